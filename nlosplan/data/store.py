"""`CaptureStore`: simulated and real captures in one SQLite file (WAL mode).

One row per capture: its labels (the :data:`~nlosplan.data.dataset.LABEL_COLUMNS`),
its metadata and its histogram as raw little-endian bytes. The rig, the
simulated-dataset builder and the DENALI importer all write here; the models
read :class:`~nlosplan.data.dataset.Dataset` objects back with :meth:`CaptureStore.load`.

Crash safety
------------
The file is in WAL mode and every capture is committed in its own
transaction, so a writer killed at any moment (SIGKILL, a crash) leaves a
consistent file: every capture whose commit returned, complete, and the
capture in flight either complete or absent.
``synchronous=FULL`` (the default) also makes every returned commit survive a
power cut or OS crash: the WAL is fsynced per commit, which the rig needs
because it moves on once a capture is stored. ``synchronous="NORMAL"`` is as
safe against process crashes and never corrupts the file, but a power cut may
undo the last commits; it suits simulated builds, which regenerate identical
captures on resume. Measured with :meth:`CaptureStore.put_many` (3x3x128
int64 captures, one transaction each, a shared 2-core VM with a virtio disk):
650-1,400 captures/s with FULL, 3,400-7,300 captures/s with NORMAL;
:meth:`CaptureStore.load` reads about 60,000 captures/s.

Keys
----
A capture's unique key joins object, size, position, lights, zones, repeat,
source, the sensor hash (:func:`sensor_hash`, the physics fields of the
sensor), the seed, the variant (a hash of a simulation's scene options and
fidelity) and the capture id, so adding the same capture twice is detected
and interrupted writers can resume (:meth:`CaptureStore.keys`).
"""

from __future__ import annotations

import json
import os
import sqlite3
from pathlib import Path
from typing import Iterable, Iterator
from urllib.parse import quote

import numpy as np
import pandas as pd

from nlosplan.constants import MAX_COUNT_24BIT
from nlosplan.errors import UserError
from nlosplan.files import WriteFailed, check_output_file
from nlosplan.schema import regular_file, shown
from nlosplan.sensor_models.config import SensorConfig
from nlosplan.data.dataset import LABEL_COLUMNS, Dataset
from nlosplan.data.writers import hold
from nlosplan.data.records import (
    APPLICATION_ID,
    FILTER_COLUMNS,
    INSERT_COLUMNS,
    SCHEMA,
    SCHEMA_VERSION,
    TABLES,
    DTYPES,
    Added,
    Capture,
    capture_key,
    capture_row,
    decode_histogram,
    describe,
    sensor_hash,
    sensor_row,
    where_sql,
)

__all__ = ["Added", "Capture", "CaptureStore", "LOCK_WAIT_S", "SCHEMA_VERSION", "capture_key", "sensor_hash"]

#: Seconds a writer waits, when it opens a store, for another process's write lock to go (an nlosplan writer holds
#: it for one capture's commit, milliseconds); a lock held longer is an error before any work.
LOCK_WAIT_S = 2.0


#: A capture's histogram as bytes whatever SQLite holds there (a damaged or edited row may hold text, which
#: sqlite3 would fail to decode): its size and values are then checked (:func:`decode_histogram`).
_DATA = "CAST(c.data AS BLOB)"


def _locked(exc: sqlite3.Error) -> bool:
    return "locked" in str(exc) or "busy" in str(exc)


class CaptureStore:
    """Captures with labels and metadata in an SQLite file (created when missing).

    Parameters
    ----------
    path : str or Path
        The store file; parent folders are created.
    create : bool
        Create a new store when ``path`` does not exist (else a UserError).
    synchronous : {"FULL", "NORMAL"}
        SQLite durability per commit (see the module notes): FULL survives
        power cuts, NORMAL only process crashes (and is ~20x faster).
    timeout : float
        Seconds to wait for another writer's lock.
    readonly : bool
        Open an existing store for reading only (SQLite ``mode=ro``;
        ``immutable=1`` on a read-only medium): what commands that only read
        use, so an archived or shared store, a read-only file or folder can be
        read and is never changed.
    check : bool
        Run SQLite's ``PRAGMA quick_check`` when opening (:meth:`quick_check`):
        what export and serving do, so a damaged file is refused before it is read.

    Raises
    ------
    UserError
        The file is not an nlosplan store (a FIFO, a device, another SQLite
        file), misses one of its tables, is newer than this code, cannot be
        opened, is locked by another writer (a store opened for writing:
        found within :data:`LOCK_WAIT_S`, before any work), or is damaged
        (with ``check``).

    Notes
    -----
    Every histogram read is checked (:func:`~nlosplan.data.records.decode_histogram`):
    its size against its dtype and shape, finite values, counts from 0 to the
    24-bit maximum (for a sensor that saturates); a damaged capture is one line
    naming it, never a wrong number.

    Examples
    --------
    >>> with CaptureStore("captures.sqlite") as store:  # doctest: +SKIP
    ...     store.put(counts, dict(object="A", size="8in", position=19, lights="off", repeat=0,
    ...                            source="real:rig"), sensor=preset("tmf8828-3x3-short"))
    ...     ds = store.load(lights="off")
    """

    def __init__(self, path, *, create: bool = True, synchronous: str = "FULL", timeout: float = 30.0,
                 readonly: bool = False, check: bool = False):
        self.path = Path(path)
        self.readonly = bool(readonly)
        self.timeout = float(timeout)
        if str(synchronous).upper() not in ("FULL", "NORMAL"):
            raise UserError(f"synchronous={synchronous!r} is not allowed; allowed: FULL, NORMAL")
        if self.path.is_dir():
            raise UserError(f"capture store {self.path} is a folder; give a file path such as "
                            f"{self.path / 'captures.sqlite'}")
        if not self.path.exists():
            if not create or readonly:
                raise UserError(f"capture store {self.path} does not exist")
            self._check_creatable()
        else:
            regular_file(self.path, "capture store")   # a FIFO or a device: refused before it is opened (no hang)
            if not readonly and not os.access(self.path, os.W_OK):
                raise UserError(f"capture store {self.path} is read-only; it can be read but not written to")
        self._sensors: dict[str, SensorConfig] = {}
        self._max_counts: dict[str, int | None] = {}
        # a writer finds another writer's lock within LOCK_WAIT_S (before any work), then waits up to timeout
        wait = self.timeout if readonly else min(self.timeout, LOCK_WAIT_S)
        try:
            if readonly:
                self._db = sqlite3.connect(self._readonly_uri(), uri=True, timeout=wait, isolation_level=None)
            else:
                self._db = sqlite3.connect(str(self.path), timeout=wait, isolation_level=None)
        except sqlite3.Error as exc:
            raise UserError(f"cannot open capture store {self.path}: {exc}") from None
        try:
            self._open(str(synchronous).upper())
            if not readonly:
                self._db.execute("BEGIN IMMEDIATE")   # the write lock is free (or freed within LOCK_WAIT_S)
                self._db.execute("ROLLBACK")
            self._db.execute(f"PRAGMA busy_timeout = {int(1000 * self.timeout)}")
            if check:
                self.quick_check()
        except sqlite3.OperationalError as exc:  # locked, no permission, disk I/O
            self._db.close()
            if _locked(exc):
                raise UserError(f"capture store {self.path} is locked by another process (it holds a write "
                                f"transaction and did not let go within {wait:g} s); wait for it to finish or give "
                                "another --store") from None
            raise UserError(f"cannot open capture store {self.path}: {exc}") from None
        except sqlite3.DatabaseError as exc:  # "file is not a database", "database disk image is malformed"
            self._db.close()
            raise UserError(f"{self.path} is not an nlosplan capture store, or it is damaged ({exc})") from None
        except UserError:
            self._db.close()
            raise

    def _check_creatable(self) -> None:
        """Before a new store is created: its folder must be a writable folder (one line otherwise)."""
        check_output_file(self.path, "capture store")
        self.path.parent.mkdir(parents=True, exist_ok=True)

    def _readonly_uri(self) -> str:
        """SQLite URI opening the file read-only; ``immutable=1`` where nothing can write it (read-only medium).

        On a writable medium ``mode=ro`` (other writers may go on; SQLite may
        add its empty ``-shm``/``-wal`` side files). Where the file or its
        folder cannot be written (a read-only mount, an archive) SQLite
        cannot create those side files, so the file is opened immutable:
        possible only when no un-checkpointed write-ahead log lies beside it.
        """
        folder = self.path.resolve().parent
        ro_medium = bool(os.statvfs(folder).f_flag & os.ST_RDONLY)
        frozen = ro_medium or not os.access(folder, os.W_OK) or not os.access(self.path, os.W_OK)
        wal = self.path.with_name(self.path.name + "-wal")
        shm = self.path.with_name(self.path.name + "-shm")
        uri = f"file:{quote(str(self.path.resolve()))}?mode=ro"
        if not frozen or shm.exists():
            return uri
        if wal.exists() and wal.stat().st_size > 0:
            raise UserError(f"capture store {self.path} is on a read-only medium with writes still in its "
                            f"write-ahead log {wal.name}; open it once where it can be written to merge them")
        return uri + "&immutable=1"

    def _open(self, synchronous: str) -> None:
        db = self._db
        app = db.execute("PRAGMA application_id").fetchone()[0]
        version = db.execute("PRAGMA user_version").fetchone()[0]
        n_tables = db.execute("SELECT count(*) FROM sqlite_master").fetchone()[0]
        if app != APPLICATION_ID and (app != 0 or n_tables or self.readonly):
            raise UserError(f"{self.path} is not an nlosplan capture store"
                            + ("" if app == 0 and not n_tables else " (an SQLite file of something else)")
                            + ("" if self.readonly else "; choose another path"))
        if app == APPLICATION_ID and version > SCHEMA_VERSION:
            raise UserError(f"capture store {self.path} has schema version {version}, newer than this nlosplan "
                            f"({SCHEMA_VERSION}); upgrade nlosplan")
        if app == APPLICATION_ID:
            tables = {r[0] for r in db.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
            missing = [t for t in TABLES if t not in tables]
            if missing:
                raise UserError(f"capture store {self.path} is damaged: it has no {' and no '.join(missing)} "
                                f"table{'s' if len(missing) > 1 else ''}")
            for table, want in TABLES.items():
                have = {r[1] for r in db.execute(f"PRAGMA table_info({table})")}
                gone = [c for c in want if c not in have]
                if gone:
                    raise UserError(f"capture store {self.path} is damaged: its {table} table has no "
                                    f"{', '.join(gone)} column{'s' if len(gone) > 1 else ''}")
        if self.readonly:
            return
        if db.execute("PRAGMA journal_mode=WAL").fetchone()[0].lower() != "wal":
            raise UserError(f"capture store {self.path}: the file system does not support SQLite WAL mode")
        db.execute(f"PRAGMA synchronous={synchronous}")
        db.execute("PRAGMA foreign_keys=ON")
        if app == 0:
            db.execute("BEGIN IMMEDIATE")
            try:
                if db.execute("PRAGMA application_id").fetchone()[0] == 0:  # not created meanwhile by another process
                    for statement in SCHEMA.split(";"):
                        if statement.strip():
                            db.execute(statement)
                db.execute("COMMIT")
            except BaseException:
                db.execute("ROLLBACK")
                raise

    # ------------------------------------------------------------ lifecycle
    def close(self) -> None:
        """Close the file (idempotent)."""
        if self._db is not None:
            self._db.close()
            self._db = None

    def __enter__(self) -> "CaptureStore":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _conn(self) -> sqlite3.Connection:
        if self._db is None:
            raise UserError(f"capture store {self.path} is closed")
        return self._db

    def integrity_check(self) -> str:
        """SQLite's ``PRAGMA integrity_check`` result (``"ok"`` for a sound file)."""
        return "; ".join(r[0] for r in self._conn().execute("PRAGMA integrity_check"))

    def quick_check(self) -> None:
        """SQLite's ``PRAGMA quick_check`` (every page and record, in one pass over the file); UserError when it
        finds damage, so nothing is read from a damaged store.

        It reads the whole file: 0.14 to 0.28 s for a 100 MB store (11,000 3x3 captures) on this 2-core machine,
        shared (``PRAGMA integrity_check``: 0.19 to 0.39 s).
        """
        try:
            found = [r[0] for r in self._conn().execute("PRAGMA quick_check(3)")]
        except sqlite3.DatabaseError as exc:
            found = [str(exc)]
        if found != ["ok"]:
            first = " ".join("; ".join(found).split())[:160]   # one line, whatever SQLite says
            raise UserError(f"capture store {self.path} is damaged (SQLite's quick check: {first}); nothing was "
                            f"read from it: recover what it holds with 'sqlite3 {self.path} .recover' into a new file")

    def _max_count(self, hash_: str) -> int | None:
        """The largest count a capture of this sensor can hold (None: a sensor that does not saturate)."""
        if hash_ not in self._max_counts:
            self._max_counts[hash_] = MAX_COUNT_24BIT if self.sensor(hash_).saturation else None
        return self._max_counts[hash_]

    def _what(self, cid, key=None) -> str:
        return f"capture {cid}{f' ({str(key)[:120]})' if key else ''} of capture store {self.path}"

    # ------------------------------------------------------------ one writer of a kind
    def writer(self, what: str):
        """Hold the store for one writer of ``what`` (e.g. one dataset build) while the block runs (a context
        manager: :func:`nlosplan.data.writers.hold`): the same ``what`` from another live process is one line."""
        if self.readonly:
            raise UserError(f"capture store {self.path} was opened read-only")
        return hold(self._conn(), self.path, what)

    # ------------------------------------------------------------ writing
    _INSERT = (f"INSERT INTO captures ({', '.join(INSERT_COLUMNS)}) VALUES ({', '.join('?' * len(INSERT_COLUMNS))}) "
               "ON CONFLICT (key) DO NOTHING")

    def _insert(self, row: tuple, sensor_row: tuple) -> tuple[int, bool]:
        db = self._conn()
        if self.readonly:
            raise UserError(f"capture store {self.path} was opened read-only")
        try:
            db.execute("BEGIN IMMEDIATE")
            try:
                db.execute("INSERT OR IGNORE INTO sensors VALUES (?, ?, ?, ?, ?, ?)", sensor_row)
                cur = db.execute(self._INSERT, row)
                new = cur.rowcount == 1
                rid = cur.lastrowid if new else db.execute("SELECT id FROM captures WHERE key = ?",
                                                           (row[0],)).fetchone()[0]
                db.execute("COMMIT")
            except BaseException:
                if db.in_transaction:
                    db.execute("ROLLBACK")
                raise
        except sqlite3.OperationalError as exc:
            if "full" in str(exc) or "disk I/O" in str(exc) or "readonly" in str(exc):
                raise WriteFailed(f"capture store {self.path}: {exc}; the captures committed before are kept") from None
            if _locked(exc):
                raise WriteFailed(f"capture store {self.path} is locked by another process (waited "
                                  f"{self.timeout:g} s); the captures committed before are kept") from None
            raise
        return int(rid), new

    def put(self, hist, labels: dict, *, sensor: SensorConfig, meta: dict | None = None, exists: str = "error") -> int:
        """Store one capture in its own transaction.

        Parameters
        ----------
        hist : array, shape (rows, cols, bins)
            Integer counts (stored as int64) or float expectations (stored as float32).
        labels : dict
            ``object``, ``size``, ``position``, ``lights`` ("on"/"off"), ``repeat``,
            ``source``; optional ``class_group`` (derived for DENALI objects),
            ``x``, ``y`` (metres), ``zones`` (must equal the sensor's), ``seed``,
            ``variant``, ``capture_id``, ``scene``, ``backend``, ``fidelity``.
        sensor : SensorConfig
            The sensor that made it (stored once per distinct sensor).
        meta : dict, optional
            Free JSON metadata (e.g. commanded and reported gantry position).
        exists : {"error", "skip"}
            What to do when a capture with the same key is stored already.

        Returns
        -------
        int
            The capture's id (the stored one's with ``exists="skip"``).
        """
        return self.put_many([(hist, labels)], sensor=sensor, meta=meta, exists=exists).ids[0]

    def put_many(self, items: Iterable, *, sensor: SensorConfig, meta: dict | None = None,
                 exists: str = "skip") -> Added:
        """Store captures, each in its own transaction (an interrupted call keeps every finished one).

        Committing each capture costs one fsync with ``synchronous="FULL"``
        (650-1,400 captures/s here) and none with NORMAL (3,400-7,300/s).

        Parameters
        ----------
        items : iterable of (hist, labels) or (hist, labels, meta)
            As :meth:`put`; a per-item ``meta`` updates the shared ``meta``.
        sensor, exists
            As :meth:`put` (``exists`` defaults to "skip" here).

        Returns
        -------
        Added
            ``ids`` of every item in order, and how many were ``added`` or ``skipped``.
        """
        if exists not in ("error", "skip"):
            raise UserError(f"exists={exists!r} is not allowed; allowed: 'error', 'skip'")
        srow = sensor_row(sensor)
        ids, added = [], 0
        for item in items:
            hist, labels, extra = (*item, None) if len(item) == 2 else item
            m = {**(meta or {}), **(extra or {})}
            rid, new = self._insert(capture_row(hist, labels, sensor, m), srow)
            if not new and exists == "error":
                raise UserError(f"capture {capture_key(labels, sensor)} is stored already (id {rid})")
            ids.append(rid)
            added += new
        return Added(ids, added, len(ids) - added)

    # ------------------------------------------------------------ reading
    def has(self, key: str) -> bool:
        """Whether a capture with this key (:func:`capture_key`) is stored."""
        return self._conn().execute("SELECT 1 FROM captures WHERE key = ?", (key,)).fetchone() is not None

    def keys(self, **where) -> set[str]:
        """Keys of the stored captures matching ``where`` (to skip them when resuming)."""
        sql, vals = where_sql(where)
        return {r[0] for r in self._conn().execute(f"SELECT c.key FROM captures c{sql}", vals)}

    def count(self, **where) -> int:
        """Number of captures whose columns equal the given values (lists allowed)."""
        sql, vals = where_sql(where)
        return int(self._conn().execute(f"SELECT count(*) FROM captures c{sql}", vals).fetchone()[0])

    def sensor(self, hash_: str) -> SensorConfig:
        """The stored sensor with this :func:`sensor_hash`."""
        if hash_ not in self._sensors:
            row = self._conn().execute("SELECT config FROM sensors WHERE hash = ?", (hash_,)).fetchone()
            if row is None:
                raise UserError(f"no sensor {hash_!r} in capture store {self.path}")
            self._sensors[hash_] = SensorConfig.from_json(row[0])
        return self._sensors[hash_]

    def sensors(self) -> pd.DataFrame:
        """Stored sensors: hash, name, zones, n_bins, bin_width_ps and their number of captures."""
        q = ("SELECT s.hash, s.name, s.zones, s.n_bins, s.bin_width_ps, count(c.id) AS captures FROM sensors s "
             "LEFT JOIN captures c ON c.sensor_hash = s.hash GROUP BY s.hash ORDER BY s.name, s.hash")
        return pd.read_sql_query(q, self._conn())

    _LABELS = ", ".join(f"c.{c}" for c in LABEL_COLUMNS + ("id", "sensor_hash", "seed", "variant", "capture_id"))

    def labels(self, **where) -> pd.DataFrame:
        """Label table (no histograms) of the matching captures, ordered by id.

        Columns: :data:`LABEL_COLUMNS`, ``id``, ``sensor_hash``, ``seed``
        (nullable integer), ``variant``, ``capture_id``; x, y are NaN when unknown.
        """
        sql, vals = where_sql(where)
        df = pd.read_sql_query(f"SELECT {self._LABELS} FROM captures c{sql} ORDER BY c.id", self._conn(), params=vals)
        for col in ("x", "y", "position", "repeat"):   # numbers, or a damaged store said in one line
            if df[col].dtype != object:
                continue
            bad = df[col].map(lambda v: isinstance(v, (str, bytes)) or (col in ("position", "repeat") and v is None))
            if bad.any():
                row = df[bad].iloc[0]
                raise UserError(f"{self._what(row['id'])} is damaged: its {col} label {shown(row[col])} is not a "
                                "number")
        df["x"], df["y"] = df["x"].astype(float), df["y"].astype(float)
        df["seed"] = df["seed"].astype("Int64")
        return df

    def load(self, **where) -> Dataset:
        """The matching captures as a :class:`Dataset` (histograms stacked as float32, ordered by id).

        Counts up to the 24-bit register maximum are exact in float32.

        Raises
        ------
        UserError
            No capture matches, or the matches differ in histogram shape or bin width
            (filter by ``zones`` or ``sensor_hash``).
        """
        db = self._conn()
        sql, vals = where_sql(where)
        db.execute("BEGIN")  # one snapshot for the three queries while writers go on
        try:
            labels = self.labels(**where)
            if labels.empty:
                raise UserError(f"no captures in {self.path} match {describe(where)}")
            q = f"SELECT DISTINCT c.shape, s.bin_width_ps FROM captures c JOIN sensors s ON s.hash = c.sensor_hash{sql}"
            kinds = db.execute(q, vals).fetchall()
            if len(kinds) > 1:
                shown = "; ".join(f"shape {json.loads(s)} at {b:g} ps" for s, b in kinds)
                raise UserError(f"captures matching {describe(where)} mix histogram shapes or bin widths ({shown}); "
                                "filter by zones= or sensor_hash=")
            shape, bin_width = tuple(json.loads(kinds[0][0])), float(kinds[0][1])
            out = np.empty((len(labels),) + shape, np.float32)
            rows = db.execute(f"SELECT c.id, c.key, c.sensor_hash, c.dtype, c.shape, {_DATA} FROM captures c{sql} "
                              "ORDER BY c.id", vals)
            counts = np.zeros(len(labels), bool)   # rows of integer counts (the others: float expectations)
            sizes = {d: int(np.prod(shape)) * DTYPES[d].itemsize for d in DTYPES}
            for i, (cid, key, h, dtype, shp, data) in enumerate(rows):
                if sizes.get(dtype) != (len(data) if isinstance(data, bytes) else None) or i == 0:
                    decode_histogram(dtype, shp, data, what=lambda: self._what(cid, key), max_count=None)
                out[i] = np.frombuffer(data, DTYPES[dtype]).reshape(shape)
                counts[i] = dtype == "<i8"
            self._check_loaded(out, counts, labels)
        finally:
            db.execute("COMMIT")
        return Dataset(out, labels, bin_width)

    def _check_loaded(self, out: np.ndarray, counts: np.ndarray, labels: pd.DataFrame) -> None:
        """Every loaded histogram finite, counts from 0 to their sensor's maximum (a damaged one: one line)."""
        flat = out.reshape(len(out), -1)
        cap = np.array([self._max_count(h) or np.inf for h in labels["sensor_hash"]], np.float64)
        bad = ~np.isfinite(flat).all(axis=1) | (counts & ((flat.min(axis=1) < 0) | (flat.max(axis=1) > cap)))
        if bad.any():
            i = int(np.argmax(bad))
            cid = int(labels["id"].iloc[i])
            dtype, shape, data, key, h = self._conn().execute(
                f"SELECT c.dtype, c.shape, {_DATA}, c.key, c.sensor_hash FROM captures c WHERE c.id = ?",
                (cid,)).fetchone()
            decode_histogram(dtype, shape, data, what=self._what(cid, key), max_count=self._max_count(h))
            raise UserError(f"{self._what(cid, key)} is damaged: its histogram holds values no sensor gives")

    def iter_captures(self, **where) -> Iterator[Capture]:
        """The matching captures one at a time, ordered by id (histograms in their stored dtype)."""
        sql, vals = where_sql(where)
        q = (f"SELECT {self._LABELS}, c.key, c.scene, c.backend, c.fidelity, c.created_utc, c.meta, c.dtype, c.shape, "
             f"{_DATA} FROM captures c{sql} ORDER BY c.id")
        names = list(LABEL_COLUMNS) + ["id", "sensor_hash", "seed", "variant", "capture_id"]
        for row in self._conn().execute(q, vals):
            lab = dict(zip(names, row[: len(names)]))
            key, scene, backend, fidelity, created, meta, dtype, shape, data = row[len(names):]
            lab["x"], lab["y"] = (float("nan") if v is None else v for v in (lab["x"], lab["y"]))
            hist = decode_histogram(dtype, shape, data, what=lambda: self._what(lab["id"], key),
                                    max_count=self._max_count(lab["sensor_hash"]))
            try:
                extra = json.loads(meta)
            except (TypeError, ValueError):
                extra = None
            if not isinstance(extra, dict):
                raise UserError(f"{self._what(lab['id'], key)} is damaged: its metadata is not a JSON object")
            info = {"scene": scene, "backend": backend, "fidelity": fidelity, "created_utc": created, **extra}
            yield Capture(id=lab.pop("id"), key=key, labels=lab, histogram=hist, meta=info)

    def summary(self, by: tuple[str, ...] = ("source", "zones", "lights", "size")) -> pd.DataFrame:
        """Captures counted by the ``by`` columns: objects, positions, repeats per scene and captures."""
        bad = [c for c in by if c not in FILTER_COLUMNS]
        if bad:
            raise UserError(f"cannot group captures by {', '.join(bad)}; allowed: {', '.join(FILTER_COLUMNS)}")
        cols = ", ".join(by)
        q = (f"SELECT {cols}, count(DISTINCT object) AS objects, count(DISTINCT position) AS positions, "
             f"max(repeat) + 1 AS repeats, count(*) AS captures FROM captures GROUP BY {cols} ORDER BY {cols}")
        return pd.read_sql_query(q, self._conn())
