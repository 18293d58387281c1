"""What the rig page shows, read from a capture store (SQLite, read-only) and a ``rig run`` folder.

:class:`RigWatch` opens the store read-only (SQLite ``mode=ro``; ``immutable=1``
for a store nothing can write: an archive) and reads only the captures added
since the last poll (by id), a few metadata fields each (``json_extract``), and
the histogram of the newest capture. With a ``rig run`` output folder it also
reads the planner's checkpoint (``planner.json``: candidates, keep-out,
proposals, the loop's history of localization RMSE and calibration) and the
approval request (:mod:`nlosplan.planner.capture.approval`). It never writes.
"""

from __future__ import annotations

import json
import math
import os
import sqlite3
import time
from pathlib import Path
from urllib.parse import quote

import numpy as np

from nlosplan.data.records import APPLICATION_ID, decode_histogram
from nlosplan.errors import UserError
from nlosplan.planner.capture.approval import read_request

__all__ = ["RigWatch", "is_store", "open_readonly"]

PLANNER = "planner.json"
#: A run whose last capture is older than this (and awaits no approval) is shown as idle.
IDLE_AFTER_S = 120.0


def is_store(path) -> bool:
    """Whether ``path`` is an SQLite file with nlosplan's application id (asked of SQLite, read-only:
    a new store in WAL mode has it only in its write-ahead log until a checkpoint)."""
    p = Path(path)
    if not p.is_file():
        return False
    try:
        with open(p, "rb") as fh:
            head = fh.read(100)
    except OSError:
        return False
    if len(head) < 100 or head[:16] != b"SQLite format 3\x00":
        return False
    if int.from_bytes(head[68:72], "big") == APPLICATION_ID:
        return True
    try:
        con = sqlite3.connect(_uri(p), uri=True, timeout=5.0)
        try:
            return con.execute("PRAGMA application_id").fetchone()[0] == APPLICATION_ID
        finally:
            con.close()
    except sqlite3.Error:
        return False


def writable(path) -> bool:
    """Whether the store can be written (the file and its folder); an archived store is not."""
    p = Path(path).resolve()
    try:
        ro_medium = bool(os.statvfs(p.parent).f_flag & os.ST_RDONLY)
    except OSError:
        ro_medium = True
    return not ro_medium and os.access(p, os.W_OK) and os.access(p.parent, os.W_OK)


def open_readonly(path) -> sqlite3.Connection:
    """A read-only connection to a capture store (``immutable=1`` when nothing can write it).

    Raises
    ------
    UserError
        Not an nlosplan store, or it cannot be opened.
    """
    p = Path(path).resolve()
    if not is_store(p):
        raise UserError(f"{path} is not an nlosplan capture store")
    try:
        con = sqlite3.connect(_uri(p), uri=True, timeout=5.0, check_same_thread=False)
        con.execute("SELECT count(*) FROM captures").fetchone()
    except sqlite3.Error as exc:
        raise UserError(f"cannot read capture store {path}: {exc}") from None
    return con


def _uri(p: Path) -> str:
    p = p.resolve()
    uri = f"file:{quote(str(p))}?mode=ro"
    if not writable(p) and not p.with_name(p.name + "-shm").exists():
        uri += "&immutable=1"   # nothing can write it (an archive): SQLite need not look for writers
    return uri


def _json(text):
    if text is None:
        return None
    try:
        return json.loads(text)
    except (TypeError, json.JSONDecodeError):
        return None


class RigWatch:
    """The state of a rig run: its captures in the store and, optionally, its planner folder.

    Parameters
    ----------
    store : str or Path
        The capture store.
    planner_dir : str or Path, optional
        The ``rig run`` output folder (``planner.json``, ``approval.json``).
    run_id : str, optional
        The run to show (default: the run of the newest capture, followed as new runs start).
    min_interval_s : float
        :meth:`refresh` reads at most this often.
    """

    _COLS = ("id", "created_utc", "run_id", "step", "repeat", "commanded", "reported", "faults", "assembler",
             "plan_total")
    _QUERY = ("SELECT id, created_utc, json_extract(meta, '$.run_id'), json_extract(meta, '$.step'), "
              "json_extract(meta, '$.repeat'), json_extract(meta, '$.commanded_mm'), "
              "json_extract(meta, '$.reported_mm'), json_extract(meta, '$.run_faults'), "
              "json_extract(meta, '$.frame.assembler'), json_extract(meta, '$.plan_total') "
              "FROM captures WHERE id > ? ORDER BY id")

    def __init__(self, store, *, planner_dir=None, run_id: str | None = None, min_interval_s: float = 1.0):
        self.store = Path(store)
        self._db = None            # opened once the store exists (a run started with --live creates it)
        self.writable = False
        self.error: str | None = None
        self._connect()
        self.planner_dir = None if planner_dir is None else Path(planner_dir)
        self.fixed_run = run_id
        self.min_interval_s = float(min_interval_s)
        self.version = 0
        self.runs: dict[str, list[dict]] = {}
        self.total = 0
        self.run_meta: dict[str, dict] = {}
        self.last_hist: dict | None = None
        self.planner: dict | None = None
        self.approval: dict | None = None
        self._max_id = 0
        self._last_read = -math.inf
        self._planner_stat = None
        self._approval_stat = None

    def _connect(self) -> bool:
        if self._db is None and is_store(self.store):
            self._db = open_readonly(self.store)
            self.writable = writable(self.store)
        return self._db is not None

    @property
    def opened(self) -> bool:
        """Whether the store exists and is open."""
        return self._db is not None

    def close(self) -> None:
        if self._db is not None:
            self._db.close()
            self._db = None

    # ------------------------------------------------------------------ reading
    def refresh(self, force: bool = False) -> bool:
        """Read what changed since the last call (at most every ``min_interval_s``); True if anything did."""
        now = time.monotonic()
        if not force and now - self._last_read < self.min_interval_s:
            return False
        self._last_read = now
        changed = self._read_captures()
        changed = self._read_planner() or changed
        if changed:
            self.version += 1
        return changed

    def _read_captures(self) -> bool:
        if not self._connect():
            return False
        try:
            rows = self._db.execute(self._QUERY, (self._max_id,)).fetchall()
            self.total = int(self._db.execute("SELECT count(*) FROM captures").fetchone()[0])
        except sqlite3.Error as exc:  # e.g. a checkpoint of the WAL in progress: read again next time
            self.error = str(exc)
            return False
        for row in rows:
            rec = dict(zip(self._COLS, row))
            self._max_id = max(self._max_id, rec["id"])
            if rec["run_id"] is None or rec["step"] is None:
                continue
            for k in ("commanded", "reported", "faults", "assembler"):
                rec[k] = _json(rec[k])
            self.runs.setdefault(rec["run_id"], []).append(rec)
        if rows:
            run = self.run_id
            if run in self.runs and (self.last_hist is None or self.last_hist["id"] != self.runs[run][-1]["id"]):
                self._read_hist(self.runs[run][-1]["id"])
        return bool(rows)

    def _read_hist(self, cid: int) -> None:
        row = self._db.execute("SELECT dtype, shape, CAST(data AS BLOB), capture_id, zones FROM captures WHERE id = ?",
                               (cid,)).fetchone()
        if row is None:
            return
        dtype, shape, data, capture_id, zones = row
        try:   # a damaged capture is said on the page, never a 500 on every load
            hist = decode_histogram(dtype, shape, data, what=f"capture {cid}", max_count=None).astype(np.float64)
        except UserError as exc:
            self.error = str(exc)
            return
        self.last_hist = {"id": cid, "capture_id": capture_id, "zones": zones, "counts": hist}

    def _read_planner(self) -> bool:
        if self.planner_dir is None:
            return False
        changed = False
        path = self.planner_dir / PLANNER
        try:
            st = path.stat()
            key = (st.st_size, st.st_mtime_ns, st.st_ino)
        except OSError:
            key = None
        if key != self._planner_stat:
            try:
                self.planner = None if key is None else json.loads(path.read_text(encoding="utf-8"))
                self._planner_stat = key
                changed = True
            except (OSError, json.JSONDecodeError):
                pass  # being replaced: read again next time
        try:
            st = (self.planner_dir / "approval.json").stat()
            akey = (st.st_size, st.st_mtime_ns, st.st_ino)
        except OSError:
            akey = None
        if akey != self._approval_stat:
            self._approval_stat = akey
            self.approval = read_request(self.planner_dir)
            changed = True
        return changed

    # ------------------------------------------------------------------ derived
    @property
    def run_id(self) -> str | None:
        """The run shown: the one asked for, else the run of the newest capture."""
        if self.fixed_run is not None:
            return self.fixed_run
        if not self.runs:
            return None
        return max(self.runs, key=lambda r: self.runs[r][-1]["id"])

    def meta(self) -> dict:
        """The first stored capture's metadata of the shown run (plan, plan spec, gantry, sensor)."""
        run = self.run_id
        if run is None or run not in self.runs:
            return {}
        if run not in self.run_meta:
            first = self.runs[run][0]["id"]
            row = self._db.execute("SELECT meta, object, size, zones, source, lights FROM captures WHERE id = ?",
                                   (first,)).fetchone()
            meta = _json(row[0]) or {}
            meta.update(dict(zip(("object", "size", "zones", "source", "lights"), row[1:])))
            spec = self._db.execute(
                "SELECT json_extract(meta, '$.plan_spec') FROM captures WHERE capture_id LIKE ? AND "
                "json_extract(meta, '$.plan_spec') IS NOT NULL LIMIT 1", (f"{run}/%",)).fetchone()
            meta["plan_spec"] = _json(spec[0]) if spec else meta.get("plan_spec")
            self.run_meta[run] = meta
        return self.run_meta[run]

    def limits_mm(self):
        """Gantry limits ((x0, x1), (y0, y1)) mm, as the gantry driver reported them (None if unknown)."""
        lim = (self.meta().get("gantry") or {}).get("limits_mm")
        return None if not lim else tuple(tuple(float(v) for v in ax) for ax in lim)

    def counts(self) -> dict:
        """Captures stored, planned and left, positions, repeats of the shown run (planned None: unknown)."""
        caps = self.runs.get(self.run_id or "", [])
        meta = self.meta()
        spec = meta.get("plan_spec") or {}
        steps = {int(c["step"]) for c in caps}
        positions = {tuple(round(v, 3) for v in c["commanded"]) for c in caps if c["commanded"]}
        repeats = max((int(c["repeat"]) for c in caps if c["repeat"] is not None), default=-1) + 1
        planned, unit = None, "captures"
        total = next((c["plan_total"] for c in reversed(caps) if c["plan_total"]), None)
        if total:
            planned = int(total)
        elif spec.get("kind") in ("raster", "positions"):
            from nlosplan.hardware.status import plan_from_spec, plan_steps

            planned = len(plan_steps(plan_from_spec(spec)))
        elif spec.get("kind") == "planner" and spec.get("budget"):
            planned, unit = int(spec["budget"]), "positions"
        done = len(positions) if unit == "positions" else len(steps)
        return {"captures": len(steps), "positions": len(positions), "repeats": repeats, "planned": planned,
                "planned_unit": unit, "left": None if planned is None else max(planned - done, 0),
                "first_utc": caps[0]["created_utc"] if caps else None,
                "last_utc": caps[-1]["created_utc"] if caps else None}

    def faults(self) -> dict:
        """Frames dropped, dumps dropped, garbage lines (the sensor link's counters), frame retries and
        sensor reconnects (the executor's), as of the newest capture; planner failures with reasons."""
        caps = self.runs.get(self.run_id or "", [])
        last = caps[-1] if caps else {}
        asm = last.get("assembler") or {}
        run_faults = last.get("faults") or {}
        fails = (self.planner or {}).get("failures") or []
        return {"dropped_frames": asm.get("dropped_frames"), "dropped_dumps": asm.get("dropped_dumps"),
                "garbage_lines": asm.get("garbage_lines"), "retries": run_faults.get("retries"),
                "reconnects": run_faults.get("reconnects"), "failed_captures": len(fails), "failures": fails}

    def captured_positions(self) -> list[dict]:
        """Distinct commanded positions of the shown run: x_mm, y_mm, captures there, first step."""
        out: dict = {}
        for c in self.runs.get(self.run_id or "", []):
            if not c["commanded"]:
                continue
            k = tuple(round(v, 3) for v in c["commanded"])
            e = out.setdefault(k, {"x_mm": k[0], "y_mm": k[1], "captures": 0, "step": int(c["step"])})
            e["captures"] += 1
        return list(out.values())

    def current_position(self):
        """The gantry's last reported position (x_mm, y_mm) in the plan's frame, or None."""
        caps = self.runs.get(self.run_id or "", [])
        for c in reversed(caps):
            if c["reported"]:
                return tuple(float(v) for v in c["reported"])
        return None

    def pending(self) -> list[dict]:
        """The planner's pending proposals (the next batch), in route order."""
        props = (self.planner or {}).get("proposals") or []
        return sorted((p for p in props if p.get("status") == "pending"), key=lambda p: p.get("batch_order", 0))

    def awaiting(self) -> dict | None:
        """The approval request, when a batch awaits an answer (of the shown run)."""
        a = self.approval
        return a if a and a.get("status") == "pending" else None

    def seconds_since_last(self) -> float | None:
        caps = self.runs.get(self.run_id or "", [])
        if not caps:
            return None
        from datetime import datetime

        try:
            t = datetime.fromisoformat(caps[-1]["created_utc"]).timestamp()
        except (TypeError, ValueError):
            return None
        return max(0.0, time.time() - t)

    def summary(self) -> list[dict]:
        """Captures of the store by source, zones and lights (what a store without rig runs shows)."""
        if self._db is None:
            return []
        rows = self._db.execute("SELECT source, zones, lights, count(DISTINCT object), count(*) FROM captures "
                                "GROUP BY source, zones, lights ORDER BY source, zones, lights").fetchall()
        return [dict(zip(("source", "zones", "lights", "objects", "captures"), r)) for r in rows]
