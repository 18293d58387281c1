"""One writer of a kind per capture store: a second identical ``dataset build`` stops at once, naming the first.

The holder is a row of the store's table ``writers`` (created when first needed): what it writes, its process id,
host and process start time (to tell it from a later process of the same id), and since when. A process that has
died (kill -9, a crash) or runs on another host does not count; its row is replaced. Other writers are not
affected: SQLite orders every capture's commit.
"""

from __future__ import annotations

import os
import socket
import sqlite3
from contextlib import contextmanager
from datetime import datetime, timezone
from pathlib import Path
from typing import Iterator

from nlosplan.errors import UserError

__all__ = ["hold"]


@contextmanager
def hold(db: sqlite3.Connection, path, what: str) -> Iterator[None]:
    """Hold the store of connection ``db`` (autocommit) for one writer of ``what`` while the block runs.

    Raises
    ------
    UserError
        Another live process on this host holds ``what`` (one line naming it and since when).
    """
    me = (os.getpid(), socket.gethostname(), _process_start(os.getpid()))
    db.execute("BEGIN IMMEDIATE")
    try:
        db.execute("CREATE TABLE IF NOT EXISTS writers (what TEXT PRIMARY KEY, pid INTEGER NOT NULL, "
                   "host TEXT NOT NULL, process_start TEXT, since_utc TEXT NOT NULL)")
        row = db.execute("SELECT pid, host, process_start, since_utc FROM writers WHERE what = ?", (what,)).fetchone()
        if row is not None and row[0] != me[0] and _alive(*row[:3]):
            raise UserError(f"capture store {path}: another {what.split(' #')[0]} (process {row[0]}, since "
                            f"{str(row[3])[:19]} UTC) is writing the same captures into it; wait for it to end, then "
                            "rerun: what it stored is skipped")
        db.execute("INSERT OR REPLACE INTO writers VALUES (?, ?, ?, ?, ?)",
                   (what, *me, datetime.now(timezone.utc).isoformat(timespec="seconds")))
        db.execute("COMMIT")
    except BaseException:
        if db.in_transaction:
            db.execute("ROLLBACK")
        raise
    try:
        yield
    finally:
        try:
            db.execute("DELETE FROM writers WHERE what = ? AND pid = ?", (what, me[0]))
        except sqlite3.Error:
            pass   # a full disk or a lock at the very end: the next writer finds this process gone


def _process_start(pid: int) -> str | None:
    """When process ``pid`` started (clock ticks since boot, from /proc), to tell it from a later one of that id."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[19]
    except (OSError, IndexError):
        return None


def _alive(pid: int, host: str, start: str | None) -> bool:
    """Whether the process that wrote a ``writers`` row still runs (on this host; another host's cannot be told)."""
    if host != socket.gethostname():
        return False
    try:
        os.kill(int(pid), 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        pass   # another user's process: it runs
    now = _process_start(int(pid))
    return start is None or now is None or now == start
