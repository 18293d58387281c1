"""Rows of the capture store: schema, keys, sensor hashes, label checks and filters.

Schema (version 1, ``PRAGMA user_version``; ``PRAGMA application_id`` marks nlosplan stores)
-----------------------------------------------------------------------------------------
``sensors``
    ``hash`` (:func:`sensor_hash`), ``name``, ``zones``, ``n_bins``,
    ``bin_width_ps`` and ``config`` (``SensorConfig.to_json()``): each distinct
    sensor once.
``captures``
    ``id``; ``key`` (unique, :func:`capture_key`); the labels ``object``,
    ``size``, ``class_group``, ``position``, ``x``, ``y`` (metres, NULL when
    unknown), ``lights``, ``zones``, ``repeat``, ``source``; ``sensor_hash``;
    ``seed`` (NULL for real captures), ``variant``, ``capture_id``;
    ``scene``, ``backend``, ``fidelity``; ``created_utc`` (ISO 8601);
    ``meta`` (free JSON); the histogram as ``dtype`` (``<i8`` counts or
    ``<f4`` expectations), ``shape`` (JSON list) and ``data`` (raw
    little-endian bytes, C order).
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass
from functools import lru_cache
from datetime import datetime, timezone
from typing import NamedTuple

import numpy as np

from nlosplan.constants import MAX_COUNT_24BIT
from nlosplan.errors import UserError, check_keys
from nlosplan.sensor_models.config import SensorConfig
from nlosplan.data.dataset import LABEL_COLUMNS

__all__ = ["APPLICATION_ID", "Added", "Capture", "FILTER_COLUMNS", "SCHEMA", "SCHEMA_VERSION", "TABLES", "capture_key",
           "capture_row", "decode_histogram", "sensor_hash", "sensor_row", "where_sql"]

#: ``PRAGMA application_id`` of nlosplan stores ("NLOS").
APPLICATION_ID = 0x4E4C4F53
#: ``PRAGMA user_version`` written by this code.
SCHEMA_VERSION = 1
#: Columns a ``where`` filter may name.
FILTER_COLUMNS = LABEL_COLUMNS + ("id", "sensor_hash", "seed", "variant", "capture_id", "scene", "backend", "fidelity")
#: Column order of an INSERT (see :func:`capture_row`).
INSERT_COLUMNS = ("key", "object", "size", "class_group", "position", "x", "y", "lights", "zones", "repeat", "source",
                  "sensor_hash", "seed", "variant", "capture_id", "scene", "backend", "fidelity", "created_utc", "meta",
                  "dtype", "shape", "data")
DTYPES = {"<i8": np.dtype("<i8"), "<f4": np.dtype("<f4")}
#: The tables every store has, with the columns this code reads.
TABLES = {"sensors": ("hash", "name", "zones", "n_bins", "bin_width_ps", "config"),
          "captures": ("id",) + INSERT_COLUMNS}
_REQUIRED = ("object", "size", "position", "lights", "repeat", "source")
_OPTIONAL = {"class_group": None, "x": None, "y": None, "zones": None, "seed": None, "variant": "", "capture_id": "",
             "scene": None, "backend": None, "fidelity": None}

SCHEMA = f"""
CREATE TABLE sensors (
    hash TEXT PRIMARY KEY, name TEXT NOT NULL, zones TEXT NOT NULL, n_bins INTEGER NOT NULL,
    bin_width_ps REAL NOT NULL, config TEXT NOT NULL
);
CREATE TABLE captures (
    id INTEGER PRIMARY KEY,
    key TEXT NOT NULL UNIQUE,
    object TEXT NOT NULL, size TEXT NOT NULL, class_group TEXT NOT NULL, position INTEGER NOT NULL,
    x REAL, y REAL, lights TEXT NOT NULL CHECK (lights IN ('on', 'off')), zones TEXT NOT NULL,
    repeat INTEGER NOT NULL, source TEXT NOT NULL,
    sensor_hash TEXT NOT NULL REFERENCES sensors(hash),
    seed INTEGER, variant TEXT NOT NULL, capture_id TEXT NOT NULL,
    scene TEXT, backend TEXT, fidelity TEXT,
    created_utc TEXT NOT NULL, meta TEXT NOT NULL,
    dtype TEXT NOT NULL CHECK (dtype IN ('<i8', '<f4')), shape TEXT NOT NULL, data BLOB NOT NULL
);
CREATE INDEX captures_scene ON captures (source, zones, lights, size, object, position);
PRAGMA application_id = {APPLICATION_ID};
PRAGMA user_version = {SCHEMA_VERSION};
"""


@lru_cache(maxsize=256)
def sensor_hash(sensor: SensorConfig) -> str:
    """16 hex digits identifying a sensor's physics (every field but ``name`` and ``notes``)."""
    fields = {k: v for k, v in sensor.to_dict().items() if k not in ("name", "notes")}
    return hashlib.sha256(json.dumps(fields, sort_keys=True).encode()).hexdigest()[:16]


def zones_of(sensor: SensorConfig) -> str:
    """The zone mode of a sensor, e.g. ``"3x3"``."""
    return f"{sensor.zones_rows}x{sensor.zones_cols}"


def capture_key(labels: dict, sensor: SensorConfig | str) -> str:
    """The unique key of a capture.

    Parameters
    ----------
    labels : dict
        ``object``, ``size``, ``position``, ``lights``, ``repeat``, ``source``,
        and optionally ``zones`` (default: the sensor's), ``seed``,
        ``variant``, ``capture_id``.
    sensor : SensorConfig or str
        The sensor or its :func:`sensor_hash`.

    Returns
    -------
    str
        ``object|size|position|lights|zones|repeat|source|sensor_hash|seed|variant|capture_id``
        (seed ``-`` when absent).
    """
    h = sensor if isinstance(sensor, str) else sensor_hash(sensor)
    zones = labels.get("zones") or (None if isinstance(sensor, str) else zones_of(sensor))
    seed = labels.get("seed")
    parts = [labels["object"], labels["size"], int(labels["position"]), labels["lights"], zones, int(labels["repeat"]),
             labels["source"], h, "-" if seed is None else int(seed), labels.get("variant") or "",
             labels.get("capture_id") or ""]
    return "|".join(str(p) for p in parts)


def _json_default(value):
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise UserError(f"capture metadata value {value!r} ({type(value).__name__}) cannot be written as JSON")


class Added(NamedTuple):
    """What :meth:`~nlosplan.data.store.CaptureStore.put_many` did.

    ``ids`` of every item in order (the stored capture's id for an item that
    was there already), and how many were ``added`` or ``skipped``.
    """

    ids: list
    added: int
    skipped: int


@dataclass(frozen=True)
class Capture:
    """One stored capture (see :meth:`~nlosplan.data.store.CaptureStore.iter_captures`).

    Attributes
    ----------
    id : int
    key : str
    labels : dict
        The label columns and ``sensor_hash``, ``seed``, ``variant``, ``capture_id``.
    histogram : ndarray, shape (rows, cols, bins)
        int64 counts or float32 expectations, as stored.
    meta : dict
        ``scene``, ``backend``, ``fidelity``, ``created_utc`` and the free metadata.
    """

    id: int
    key: str
    labels: dict
    histogram: np.ndarray
    meta: dict


def sensor_row(sensor: SensorConfig) -> tuple:
    """The ``sensors`` row of a sensor (hash first)."""
    if not isinstance(sensor, SensorConfig):
        raise UserError(f"sensor must be a SensorConfig (a preset or a loaded sensor file), "
                        f"not {type(sensor).__name__}")
    return (sensor_hash(sensor), sensor.name, zones_of(sensor), sensor.n_bins, sensor.bin_width_ps, sensor.to_json())


def _check_labels(labels: dict, sensor: SensorConfig) -> dict:
    check_keys(labels, _REQUIRED + tuple(_OPTIONAL), "capture label(s)")
    missing = [k for k in _REQUIRED if labels.get(k) is None]
    if missing:
        raise UserError(f"capture labels miss {', '.join(missing)}")
    lab = {**_OPTIONAL, **labels}
    if lab["lights"] not in ("on", "off"):
        raise UserError(f"lights={lab['lights']!r} is not allowed; allowed: 'on', 'off'")
    if lab["zones"] not in (None, zones_of(sensor)):
        raise UserError(f"capture zones {lab['zones']!r} differ from the sensor's {zones_of(sensor)}")
    lab["zones"] = zones_of(sensor)
    if lab["class_group"] is None:
        from nlosplan.denali import DENALI_OBJECTS, class_group

        if lab["object"] not in DENALI_OBJECTS:
            raise UserError(f"give class_group for object {lab['object']!r} (not a DENALI object)")
        lab["class_group"] = class_group(lab["object"])
    return lab


def _histogram_bytes(hist, sensor: SensorConfig) -> tuple[str, list, bytes]:
    a = np.asarray(hist)
    expected = (sensor.zones_rows, sensor.zones_cols, sensor.n_bins)
    if a.shape != expected:
        raise UserError(f"histogram shape {a.shape} does not match the sensor {sensor.name!r} {expected}")
    if np.issubdtype(a.dtype, np.integer):
        dtype = "<i8"
        top = MAX_COUNT_24BIT if sensor.saturation else None   # what reading it back accepts
        if a.size and (a.min() < 0 or (top is not None and a.max() > top)):
            bad = a.min() if a.min() < 0 else a.max()
            raise UserError(f"histogram count {int(bad)} is outside 0 to {top if top is not None else 'any'}"
                            + (" (the sensor saturates at 24 bits)" if top is not None else ""))
    elif np.issubdtype(a.dtype, np.floating):
        dtype = "<f4"
        if not np.all(np.isfinite(a)):
            raise UserError("histogram has NaN or infinite values")
    else:
        raise UserError(f"histogram dtype {a.dtype} is not allowed; allowed: integers (counts) or floats")
    return dtype, list(a.shape), np.ascontiguousarray(a, dtype=DTYPES[dtype]).tobytes()


def capture_row(hist, labels: dict, sensor: SensorConfig, meta: dict | None) -> tuple:
    """The ``captures`` row (in :data:`INSERT_COLUMNS` order) of one capture, checked.

    Raises
    ------
    UserError
        Unknown or missing labels, lights not on/off, zones or histogram shape
        unlike the sensor's, non-finite values, counts below 0 or above the
        24-bit maximum (of a sensor that saturates), metadata that is not JSON.
    """
    lab = _check_labels(labels, sensor)
    dtype, shape, data = _histogram_bytes(hist, sensor)
    xy = [None if v is None or not math.isfinite(float(v)) else float(v) for v in (lab["x"], lab["y"])]
    h = sensor_hash(sensor)
    now = datetime.now(timezone.utc).isoformat(timespec="microseconds")
    meta_json = json.dumps(meta or {}, sort_keys=True, default=_json_default)
    return (capture_key(lab, h), str(lab["object"]), str(lab["size"]), str(lab["class_group"]), int(lab["position"]),
            *xy, lab["lights"], lab["zones"], int(lab["repeat"]), str(lab["source"]), h,
            None if lab["seed"] is None else int(lab["seed"]), str(lab["variant"]), str(lab["capture_id"]),
            lab["scene"], lab["backend"], lab["fidelity"], now, meta_json, dtype, json.dumps(shape), data)


@lru_cache(maxsize=64)
def _dims(shape) -> tuple | None:
    """A stored ``shape`` (JSON text) as (rows, cols, bins), or None when it is not one."""
    try:
        dims = json.loads(shape) if isinstance(shape, (str, bytes)) else None
    except ValueError:
        return None
    ok = isinstance(dims, list) and len(dims) == 3 and all(
        isinstance(d, int) and not isinstance(d, bool) and 0 < d <= 4096 for d in dims)
    return tuple(dims) if ok else None


def decode_histogram(dtype, shape, data, *, what, max_count: int | None = MAX_COUNT_24BIT) -> np.ndarray:
    """A stored histogram as an array, checked: what a damaged or edited store holds is never passed on.

    Parameters
    ----------
    dtype, shape, data
        The row's ``dtype`` (``<i8`` or ``<f4``), ``shape`` (JSON list) and ``data`` (bytes).
    what : str or callable
        Names the capture in the message, e.g. ``"capture 12 (A|8in|...) of s.sqlite"`` (a callable returning
        it is called only when the capture is damaged).
    max_count : int, optional
        Largest count (default the 24-bit register's; None: no upper bound, a sensor that does not saturate).

    Returns
    -------
    ndarray, shape (rows, cols, bins)
        Read-only view of ``data`` in native byte order (int64 counts or float32 expectations).

    Raises
    ------
    UserError
        An unknown dtype, a shape that is not a list of three positive integers, a blob whose size does not
        match them, a NaN or infinite value, counts below 0 or above ``max_count`` (one line naming the capture).
    """
    def damaged(reason: str) -> UserError:
        name = what() if callable(what) else what
        return UserError(f"{name} is damaged: {reason}; the store may be corrupt (SQLite's 'PRAGMA integrity_check' "
                         "says where)")

    if dtype not in DTYPES:
        raise damaged(f"its histogram dtype {str(dtype)[:20]!r} is not one of {', '.join(DTYPES)}")
    dims = _dims(shape)
    if dims is None:
        raise damaged(f"its histogram shape {str(shape)[:40]!r} is not [rows, cols, bins]")
    if not isinstance(data, (bytes, bytearray, memoryview)):
        raise damaged(f"its histogram is a {type(data).__name__}, not bytes")
    want = dims[0] * dims[1] * dims[2] * DTYPES[dtype].itemsize
    if len(data) != want:
        raise damaged(f"its histogram holds {len(data)} bytes, {want} expected for shape {list(dims)} of {dtype}")
    hist = np.frombuffer(data, DTYPES[dtype]).reshape(dims)
    if dtype == "<f4":
        if not np.isfinite(hist).all():
            raise damaged("its histogram holds NaN or infinite values")
    elif hist.size:
        lo, hi = hist.min(), hist.max()
        if lo < 0:
            raise damaged(f"a count of {int(lo)} is negative")
        if max_count is not None and hi > max_count:
            raise damaged(f"a count of {int(hi)} is above {max_count}"
                          + (", the 24-bit register's maximum" if max_count == MAX_COUNT_24BIT else ""))
    return hist if DTYPES[dtype].isnative else hist.astype(DTYPES[dtype].newbyteorder("="))


def where_sql(where: dict) -> tuple[str, list]:
    """`` WHERE ...`` over the alias ``c`` (columns from :data:`FILTER_COLUMNS`) and its bound values.

    A value may be a list (any of them matches); an empty list matches nothing.
    """
    clauses, values = [], []
    for col, value in where.items():
        if col not in FILTER_COLUMNS:
            raise UserError(f"cannot filter captures by {col!r}; allowed: {', '.join(FILTER_COLUMNS)}")
        allowed = list(value) if isinstance(value, (list, tuple, set, range)) else [value]
        allowed = [v.item() if isinstance(v, np.generic) else v for v in allowed]
        clauses.append(f"c.{col} IN ({', '.join('?' * len(allowed))})" if allowed else "0")
        values += allowed
    return (" WHERE " + " AND ".join(clauses)) if clauses else "", values


def describe(where: dict) -> str:
    """A filter as ``col=value, ...`` for messages."""
    return ", ".join(f"{k}={v!r}" for k, v in where.items()) or "no filter"
