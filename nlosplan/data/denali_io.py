"""The real DENALI folder layout: import it into a capture store, export a store to it.

Layout (DENALI's ``DataSet.from_raw_captures``)::

    <root>/<object>_<4inch|8inch>_<3x3|8x8>_<lighton|lightoff>_NLOSdata/spad_histogram/NNN.npy
    <root>/tag1_positions.json      {"frame{N}_tag1": [x, y, ...], ...} (metres)

Each ``NNN.npy`` holds the repeats of one capture, shape ``(repeats, H, W, 128)``;
``NNN`` is the capture number, the gantry position index. Object names are
DENALI's: ``halfcircle`` is the mesh ``semicircle``, ``i`` is ``I``;
``NOOBJECT`` and ``NOOBJECTMOUNT`` (the backgrounds) get class group
``"background"``.

Safety: histogram files are read with ``allow_pickle=False``; a file that
needs pickle (an object array, a ``NNN.pkl`` or ``NNN.joblib`` capture file)
may run code when loaded and is refused unless ``trust_pickle=True``.
Other files are never opened (pickle files among them are listed as
skipped in the import summary).
"""

from __future__ import annotations

import json
import re
import time
from pathlib import Path
from typing import Callable

import numpy as np

from nlosplan.constants import MAX_COUNT_24BIT
from nlosplan.errors import UserError
from nlosplan.files import save_npy, write_json
from nlosplan.schema import check_quantity, loads, parse_int, read_text
from nlosplan.sensor_models.config import SensorConfig
from nlosplan.denali import DENALI_OBJECTS, class_group
from nlosplan.data.records import capture_key, sensor_hash, zones_of

__all__ = ["BACKGROUNDS", "NoCaptureFiles", "OBJECT_ALIASES", "SOURCE", "export_denali", "import_denali", "load_positions"]


class NoCaptureFiles(UserError):
    """A folder given to :func:`import_denali` holds no capture file (nothing is stored)."""


#: ``source`` label of imported captures.
SOURCE = "real:denali"
#: DENALI's background captures (no object, or the bare mount).
BACKGROUNDS = ("NOOBJECT", "NOOBJECTMOUNT")
_FOLDER = re.compile(r"^(?P<object>.+)_(?P<size>4inch|8inch)_(?P<zones>\d+x\d+)_(?P<lights>lighton|lightoff)_NLOSdata$")
_FILE = re.compile(r"^(?P<number>\d+)\.(?P<ext>npy|pkl|joblib)$")
#: DENALI's data names of the objects whose mesh names differ.
OBJECT_ALIASES = {"halfcircle": "semicircle", "i": "I"}
_EXPORT_NAMES = {"semicircle": "halfcircle"}
_SIZES = {"4inch": "4in", "8inch": "8in"}
_LIGHTS = {"lighton": "on", "lightoff": "off"}
Progress = Callable[[int, int, str], None]


def load_positions(path=None) -> dict[int, tuple[float, float]]:
    """Capture number -> (x, y) in metres, from a ``tag1_positions.json`` (default: the packaged DENALI one).

    Keys ``frame{N}_tag1`` give capture number ``N`` (DENALI's
    ``load_capture_number_to_location_mapping``); other keys are ignored.
    """
    if path is None:
        from nlosplan.denali import positions_xy

        return {p: (float(x), float(y)) for p, (x, y) in enumerate(positions_xy())}
    where = f"positions file {path}"
    raw = loads(read_text(path, "positions file"), "json", where)  # FIFO, binary, depth, duplicate keys: one line
    if not isinstance(raw, dict):
        raise UserError(f"{where} is not a tag1_positions.json ({{'frameN_tag1': [x, y, ...]}}): it holds a "
                        f"{type(raw).__name__}")
    out = {}
    for key, value in raw.items():
        if not key.startswith("frame"):
            continue
        try:
            number = parse_int(key.split("_", 1)[0].removeprefix("frame"))
            if not isinstance(value, list) or len(value) < 2 or not all(
                    isinstance(v, (int, float)) and not isinstance(v, bool) for v in value[:2]):
                raise TypeError
            xy = (float(value[0]), float(value[1]))
        except (ValueError, TypeError, OverflowError):
            raise UserError(f"{where} is not a tag1_positions.json ({{'frameN_tag1': [x, y, ...]}}): entry "
                            f"{key[:40]!r} is not a frame number with [x, y, ...] in metres") from None
        for axis, v in zip("xy", xy):   # NaN or 1e308 would be stored as a NULL or absurd label
            check_quantity("position_m", v, f"{where}: {key[:40]} {axis}")
        out[number] = xy
    return out


def _pickle_refusal(path: Path) -> UserError:
    return UserError(f"{path}: refusing to load a file that needs pickle (it may run code when loaded); "
                     "pass --trust-pickle (trust_pickle=True) only for data you trust")


def _npy_header(path: Path) -> tuple[tuple, np.dtype]:
    try:
        fmt = np.lib.format
        with open(path, "rb") as f:  # the header only: no data, no pickle
            version = fmt.read_magic(f)
            read = {(1, 0): fmt.read_array_header_1_0, (2, 0): fmt.read_array_header_2_0}.get(version)
            if read is None:
                raise ValueError(f".npy format version {version} is not supported")
            shape, _, dtype = read(f)
        return tuple(shape), dtype
    except (OSError, ValueError, EOFError) as exc:
        raise UserError(f"{path}: not a readable .npy file ({str(exc).splitlines()[0]})") from None


def _read(path: Path, ext: str, trust: bool) -> np.ndarray:
    """The array of a capture file; pickles only when trusted."""
    try:
        if ext == "npy":
            return np.asarray(np.load(path, allow_pickle=trust))
        if not trust:
            raise _pickle_refusal(path)
        if ext == "joblib":
            import joblib

            return np.asarray(joblib.load(path))
        import pickle

        with open(path, "rb") as f:
            return np.asarray(pickle.load(f))
    except UserError:
        raise
    except Exception as exc:  # corrupt files raise many kinds; name the file in one line
        first = str(exc).splitlines()[0] if str(exc) else ""
        raise UserError(f"{path}: cannot be read ({type(exc).__name__}: {first})") from None


def _as_counts(arr: np.ndarray, path: Path, shape: tuple) -> tuple[np.ndarray, str]:
    """Checked histograms (repeats, *shape) as int64 counts; UserError for anything a TMF8828 cannot count.

    Counts are whole numbers from 0 to the 24-bit register maximum; floats
    are accepted when they hold whole numbers (within float precision) in
    that range. Negative, NaN, infinite, fractional and too large values are
    refused with the file, the first bad value and its index (a float of
    1e30 would otherwise wrap to a negative int64).
    """
    if arr.ndim != 4 or arr.shape[1:] != shape or arr.shape[0] < 1:
        raise UserError(f"{path}: histogram shape {arr.shape}, expected (repeats, {', '.join(map(str, shape))})")
    if arr.dtype.kind == "O":  # a trusted pickle of Python numbers
        try:
            arr = arr.astype(np.float64)
        except (TypeError, ValueError):
            raise UserError(f"{path}: histogram values of dtype {arr.dtype} are not numbers") from None
    if arr.dtype == bool or not (np.issubdtype(arr.dtype, np.integer) or np.issubdtype(arr.dtype, np.floating)):
        raise UserError(f"{path}: histogram values of dtype {arr.dtype} are not counts (integers)")
    values = arr.astype(np.float64) if np.issubdtype(arr.dtype, np.floating) else arr
    if values.dtype == np.float64:
        if not np.isfinite(values).all():
            raise _count_error(path, values, ~np.isfinite(values), "not a finite number")
        frac = np.abs(values - np.round(values)) > 1e-6 * np.maximum(1.0, np.abs(values))
        if frac.any():
            raise _count_error(path, values, frac, "not a whole number of counts")
        values = np.round(values)
    for bad, why in ((values < 0, "negative"),
                     (values > MAX_COUNT_24BIT, f"above the sensor's 24-bit range (at most {MAX_COUNT_24BIT})")):
        if bad.any():
            raise _count_error(path, values, bad, why)
    return values.astype(np.int64), str(arr.dtype)


def _count_error(path: Path, values: np.ndarray, bad: np.ndarray, why: str) -> UserError:
    idx = tuple(int(i) for i in np.argwhere(bad)[0])
    return UserError(f"{path}: count {values[idx].item()!r} at index {list(idx)} is {why} ({int(bad.sum())} such values); "
                     "nothing was imported")


def _sensors(sensors) -> dict[str, SensorConfig]:
    from nlosplan.sensor_models import preset

    out = {"3x3": preset("denali-tmf8828-3x3"), "8x8": preset("denali-tmf8828-8x8")}  # DENALI's own unit
    for s in sensors or ():
        if not isinstance(s, SensorConfig):
            raise UserError(f"sensors must be SensorConfig objects, not {type(s).__name__}")
        out[zones_of(s)] = s
    return out


def _folder_labels(name: str) -> tuple[dict | None, str]:
    """Labels of a capture folder, or None and why it is skipped."""
    m = _FOLDER.match(name)
    if m is None:
        return None, "not <object>_<4inch|8inch>_<RxC>_<lighton|lightoff>_NLOSdata"
    obj = OBJECT_ALIASES.get(m["object"], m["object"])
    if obj in BACKGROUNDS:
        group = "background"
    elif obj in DENALI_OBJECTS:
        group = class_group(obj)
    else:
        return None, f"unknown object {m['object']!r} (not one of the 30 DENALI objects, NOOBJECT or NOOBJECTMOUNT)"
    return dict(object=obj, size=_SIZES[m["size"]], class_group=group, lights=_LIGHTS[m["lights"]],
                zones=m["zones"]), ""


def import_denali(root, store, *, positions_json=None, trust_pickle: bool = False, sensors=None,
                  source: str = SOURCE, progress: Progress | None = None) -> dict:
    """Import a DENALI data folder into a store, resumably (captures stored already are skipped).

    Every capture file is checked (layout, shape, counts in the sensor's
    range, pickle) before anything is stored: a bad file stops the import
    with one line and nothing of it lands in the store; a folder with no
    capture file at all is an error and creates no store.

    Parameters
    ----------
    root : str or Path
        The folder holding the ``*_NLOSdata`` folders.
    store : CaptureStore, str or Path
        The target store; a path is opened (and created when missing) only
        once the files passed the checks.
    positions_json : str or Path, optional
        ``tag1_positions.json`` giving (x, y) per capture number (default: the packaged DENALI one).
    trust_pickle : bool
        Allow capture files that need pickle (they may run code when loaded).
    sensors : sequence of SensorConfig, optional
        Sensors by zone mode, replacing the presets of DENALI's unit ``denali-tmf8828-3x3`` and
        ``denali-tmf8828-8x8`` (their bin width becomes the dataset's).
    source : str
        ``source`` label of the captures.
    progress : callable, optional
        ``progress(done, total, text)`` per capture file (checked, then imported: ``total`` is twice the files).

    Returns
    -------
    dict
        ``folders`` imported, ``files`` read, ``files_stored_already``,
        ``captures_added``, ``captures_skipped``, ``skipped`` (list of
        ``{"path", "reason"}`` for folders and files left out), ``seconds``.

    Raises
    ------
    UserError
        ``root`` is not a folder or holds no capture file; a capture file is
        corrupt, has the wrong shape, counts a TMF8828 cannot give (negative,
        fractional, NaN, above 24 bits), or needs pickle without
        ``trust_pickle`` (the message names the file; nothing was imported).
    """
    from nlosplan.data.store import CaptureStore

    t0 = time.perf_counter()
    root = Path(root)
    if not root.is_dir():
        raise UserError(f"DENALI data folder {root} does not exist or is not a folder")
    positions = load_positions(positions_json)
    by_zones = _sensors(sensors)
    work, skipped = _scan(root, positions, by_zones, trust_pickle)
    if not work:
        why = f"; {len(skipped)} entries skipped, e.g. {skipped[0]['path']}: {skipped[0]['reason']}" if skipped else ""
        raise NoCaptureFiles(f"no capture files to import in {root} (expected <object>_<4inch|8inch>_<3x3|8x8>_"
                        f"<lighton|lightoff>_NLOSdata/spad_histogram/NNN.npy){why}")
    owned = not isinstance(store, CaptureStore)
    if owned:
        store_path = Path(store)
        if store_path.exists():  # skip what it holds already (read-only look; created below only after the checks)
            with CaptureStore(store_path, readonly=True) as st:
                stored = st.keys(source=source)
        else:
            stored = set()
    else:
        stored = store.keys(source=source)
    todo = []
    for i, (folder, f, ext, number, lab, header) in enumerate(work):
        sensor = by_zones[lab["zones"]]
        base = dict(lab, position=number, x=positions[number][0], y=positions[number][1], source=source)
        n = header[0][0] if header is not None and len(header[0]) == 4 else 0
        if n and all(capture_key(dict(base, repeat=r), sensor_hash(sensor)) in stored for r in range(n)):
            todo.append(None)
        else:
            _as_counts(_read(f, ext, trust_pickle), f, (sensor.zones_rows, sensor.zones_cols, sensor.n_bins))
            todo.append(base)
        if progress:
            progress(i + 1, 2 * len(work), f"checked {folder.name}/{f.name}")
    if owned:
        store = CaptureStore(store_path, create=True)
    files = files_stored = added = already = 0
    try:
        for i, ((folder, f, ext, number, lab, header), base) in enumerate(zip(work, todo)):
            if base is None:
                files_stored += 1
                already += header[0][0]
            else:
                sensor = by_zones[lab["zones"]]
                counts, src_dtype = _as_counts(_read(f, ext, trust_pickle), f,
                                               (sensor.zones_rows, sensor.zones_cols, sensor.n_bins))
                meta = {"folder": folder.name, "file": f.name, "source_dtype": src_dtype}
                res = store.put_many(((counts[r], dict(base, repeat=r)) for r in range(len(counts))), sensor=sensor,
                                     meta=meta)
                files, added, already = files + 1, added + res.added, already + res.skipped
            if progress:
                progress(len(work) + i + 1, 2 * len(work), f"{folder.name}/{f.name}")
    finally:
        if owned:
            store.close()
    folders = len({w[0] for w in work})
    return {"root": str(root), "store": str(store.path), "source": source, "folders": folders, "files": files,
            "files_stored_already": files_stored, "captures_added": added, "captures_skipped": already,
            "skipped": skipped, "seconds": time.perf_counter() - t0}


def _scan(root: Path, positions: dict, by_zones: dict, trust_pickle: bool) -> tuple[list, list[dict]]:
    """The capture files of a DENALI folder (folder, file, ext, number, labels, npy header) and what is skipped."""
    skipped: list[dict] = []
    work = []
    for f in sorted(p for p in root.iterdir() if p.is_file() and p.suffix in (".pkl", ".joblib")):
        skipped.append({"path": f.name, "reason": "pickle file outside the folder layout; not opened"})
    for folder in sorted(p for p in root.iterdir() if p.is_dir()):
        lab, why = _folder_labels(folder.name)
        if lab is not None and lab["zones"] not in by_zones:
            lab, why = None, f"no sensor for {lab['zones']} zones (give one with that zone mode)"
        if lab is not None and not (folder / "spad_histogram").is_dir():
            lab, why = None, "no spad_histogram folder"
        if lab is None:
            skipped.append({"path": folder.name, "reason": why})
            continue
        for f in sorted((folder / "spad_histogram").iterdir()):
            m = _FILE.match(f.name)
            rel = f"{folder.name}/spad_histogram/{f.name}"
            if m is None or not f.is_file():
                skipped.append({"path": rel, "reason": "not a capture file NNN.npy (or NNN.pkl, NNN.joblib)"})
            elif int(m["number"]) not in positions:
                skipped.append({"path": rel, "reason": f"capture number {int(m['number'])} has no position in the "
                                                       "positions file"})
            else:
                header = _npy_header(f) if m["ext"] == "npy" else None
                if not trust_pickle and (header is None or header[1].hasobject):
                    raise _pickle_refusal(f)  # before anything is imported
                work.append((folder, f, m["ext"], int(m["number"]), lab, header))
    return work, skipped


def _write_npy(path: Path, arr: np.ndarray, overwrite: bool) -> bool:
    """Write atomically; False when an equal file is there already."""
    if path.exists():
        try:
            old = np.load(path, allow_pickle=False)
        except (OSError, ValueError, EOFError):
            old = None
        if old is not None and old.dtype == arr.dtype and np.array_equal(old, arr):
            return False
        if not overwrite:
            raise UserError(f"{path} exists with other data; pass --overwrite (overwrite=True) to replace it")
    save_npy(path, arr)
    return True


def export_denali(store, root, *, overwrite: bool = False, progress: Progress | None = None, **where) -> dict:
    """Write captures in the DENALI folder layout, with a ``tag1_positions.json``.

    Parameters
    ----------
    store : CaptureStore
    root : str or Path
        Output folder (created).
    overwrite : bool
        Replace files that hold other data (equal files are left alone).
    progress : callable, optional
        ``progress(done, total, text)`` per scene file.
    **where
        Capture filter (as :meth:`CaptureStore.load`); negative repeats
        (means, expectations) are never exported.

    Returns
    -------
    dict
        ``folders``, ``files_written``, ``files_unchanged``, ``captures``, ``positions`` and ``root``.

    Raises
    ------
    UserError
        Nothing matches; two captures would share a file slot (filter by
        ``source``, ``sensor_hash`` or ``seed``); a scene's repeats are not
        0..R-1; a capture lacks x, y; labels the layout cannot name; a
        damaged capture (checked before anything is written).
    """
    labels = store.labels(**where)
    labels = labels[labels["repeat"] >= 0]
    if labels.empty:
        raise UserError(f"no captures to export match {where or 'no filter'}")
    scene_cols = ["object", "size", "zones", "lights", "position"]
    dup = labels.duplicated(scene_cols + ["repeat"], keep=False)
    if dup.any():
        row = labels[dup].iloc[0]
        raise UserError(f"several captures of {row['object']}_{row['size']} {row['zones']} lights {row['lights']} "
                        f"position {row['position']} repeat {row['repeat']} (sources, sensors or seeds differ); "
                        "filter by source, sensor_hash or seed")
    if labels[["x", "y"]].isna().any().any():
        raise UserError("some captures have no x, y label; the DENALI layout needs a position for each")
    bad = sorted(set(labels["object"]) - set(DENALI_OBJECTS) - set(BACKGROUNDS)) + sorted(
        set(labels["size"]) - set(_SIZES.values()))
    if bad:
        raise UserError(f"the DENALI layout cannot name {', '.join(map(repr, bad))}")
    pos = labels.groupby("position")[["x", "y"]].nunique()
    if (pos > 1).any().any():
        raise UserError(f"positions {sorted(pos.index[(pos > 1).any(axis=1)])} have several (x, y) labels")
    for _ in store.iter_captures(**where):   # every histogram checked before the first file: a damaged one is one
        pass                                 # line naming it, and nothing is written
    root = Path(root)
    root.mkdir(parents=True, exist_ok=True)
    inv_sizes, inv_lights = {v: k for k, v in _SIZES.items()}, {v: k for k, v in _LIGHTS.items()}
    scenes = list(labels.groupby(scene_cols, sort=True))
    written = unchanged = 0
    folders = set()
    for i, ((obj, size, zones, lights, p), rows) in enumerate(scenes):
        rows = rows.sort_values("repeat")
        if list(rows["repeat"]) != list(range(len(rows))):
            raise UserError(f"{obj}_{size} {zones} lights {lights} position {p}: repeats {list(rows['repeat'])} "
                            "are not 0..R-1")
        ids = [int(v) for v in rows["id"]]
        by_id = {c.id: c.histogram for c in store.iter_captures(id=ids)}
        ordered = [by_id[k] for k in ids]
        dtype = np.int64 if all(h.dtype == np.int64 for h in ordered) else np.float32
        folder = root / f"{_EXPORT_NAMES.get(obj, obj)}_{inv_sizes[size]}_{zones}_{inv_lights[lights]}_NLOSdata"
        (folder / "spad_histogram").mkdir(parents=True, exist_ok=True)
        folders.add(folder.name)
        if _write_npy(folder / "spad_histogram" / f"{int(p):03d}.npy", np.stack(ordered).astype(dtype), overwrite):
            written += 1
        else:
            unchanged += 1
        if progress:
            progress(i + 1, len(scenes), folder.name)
    first = labels.groupby("position")[["x", "y"]].first()
    positions = {f"frame{int(p)}_tag1": [float(r.x), float(r.y)] for p, r in first.iterrows()}
    pos_path = root / "tag1_positions.json"
    if pos_path.exists():
        old = {f"frame{k}_tag1": list(v) for k, v in load_positions(pos_path).items()}
        clash = [k for k in positions if k in old and old[k] != positions[k]]
        if clash and not overwrite:
            raise UserError(f"{pos_path} gives other positions for {', '.join(clash[:3])}; pass --overwrite to replace")
        positions = {**old, **positions}
    write_json(pos_path, dict(sorted(positions.items(), key=lambda kv: int(kv[0][5:].split("_")[0]))), indent=1)
    return {"root": str(root), "folders": len(folders), "files_written": written, "files_unchanged": unchanged,
            "captures": int(len(labels)), "positions": len(first)}
