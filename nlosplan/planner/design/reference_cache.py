"""A cache of simulated design references by content, shared between runs of ``nlosplan design``.

A design run simulates one reference per zone layout (:func:`~nlosplan.planner.design.data.simulate_reference`,
minutes on 2 cores). Its result depends only on the reference sensor, the scene set (objects, sizes,
positions, lights, fidelity, backend, scene parameters, bound scenes) and the simulator's code, so a
second run with the same inputs -- in another output folder -- takes it from here instead of
simulating it again.

Key: SHA-256 of the JSON of the sensor's :meth:`~nlosplan.sensor_models.config.SensorConfig.to_dict`,
the :class:`~nlosplan.planner.design.data.SceneSet`'s ``to_dict`` and :func:`code_version` (a hash of
the source of the simulators, the sensor models, the DENALI scenes and the reference builder: any edit
there makes new keys). Folder: ``$NLOSPLAN_CACHE/references`` or ``~/.cache/nlosplan/references``.
Each entry is ``KEY.npz`` with ``KEY.sha256`` (the SHA-256 of the npz bytes), both written atomically
(:func:`nlosplan.files.atomic_path`); an entry whose checksum or content does not match is removed and
recomputed with a note, never trusted.
"""

from __future__ import annotations

import hashlib
import json
import shutil
from functools import lru_cache
from pathlib import Path
from typing import Callable

from nlosplan.files import atomic_path, write_text
from nlosplan.resources import cache_root

#: Source folders and files (relative to the package) whose code the references depend on.
CODE_PATHS = ("simulators", "sensor_models", "denali", "planner/design/data.py", "tasks/bounds.py", "constants.py",
              "_jax.py")


def cache_dir() -> Path:
    """``$NLOSPLAN_CACHE/references`` or ``~/.cache/nlosplan/references``."""
    return cache_root() / "references"


def code_files() -> list[Path]:
    """The source files in :data:`CODE_PATHS`: ``*.py`` and the compiled kernels' ``*.cc``, sorted by path."""
    pkg = Path(__file__).resolve().parents[2]
    out = []
    for rel in CODE_PATHS:
        p = pkg / rel
        out += sorted([*p.rglob("*.py"), *p.rglob("*.cc")]) if p.is_dir() else [p] if p.is_file() else []
    return out


@lru_cache(maxsize=1)
def code_version() -> str:
    """SHA-256 (16 hex digits) of :func:`code_files` (their paths in the package and contents)."""
    pkg = Path(__file__).resolve().parents[2]
    h = hashlib.sha256()
    for f in code_files():
        h.update(str(f.relative_to(pkg)).encode())
        h.update(f.read_bytes())
    return h.hexdigest()[:16]


def cache_key(sensor, scenes) -> str:
    """Content key of a reference: sensor dict, scene set dict and :func:`code_version`."""
    text = json.dumps({"sensor": sensor.to_dict(), "scenes": scenes.to_dict(), "code": code_version()},
                      sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:32]


def _digest(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _entry(key: str) -> tuple[Path, Path]:
    d = cache_dir()
    return d / f"{key}.npz", d / f"{key}.sha256"


def _valid(npz: Path, sha: Path, sensor) -> str | None:
    """None when the entry can be trusted, else why not."""
    import numpy as np

    try:
        if sha.read_text().strip() != _digest(npz):
            return "its checksum does not match"
        with np.load(npz, allow_pickle=False) as z:
            meta = json.loads(bytes(z["meta"]).decode())
            if "means" not in z.files:
                return "it holds no expected counts"
        if meta.get("sensor") != json.loads(json.dumps(sensor.to_dict(), default=str)):
            return "it belongs to another sensor"
    except (OSError, ValueError, KeyError, json.JSONDecodeError, UnicodeDecodeError) as exc:
        return f"it cannot be read ({type(exc).__name__})"
    return None


def restore(path, sensor, scenes, say: Callable[[str], None] = lambda text: None) -> bool:
    """Copy the cached reference of ``(sensor, scenes)`` to ``path``; False when there is none to trust.

    A damaged entry (checksum, unreadable, another sensor) is removed with a note through ``say``.
    """
    key = cache_key(sensor, scenes)
    npz, sha = _entry(key)
    if not npz.exists():
        return False
    why = _valid(npz, sha, sensor) if sha.exists() else "its checksum file is missing"
    if why is not None:
        say(f"reference cache: entry {key[:12]} is damaged ({why}); removed, simulating it again")
        for f in (npz, sha):
            f.unlink(missing_ok=True)
        return False
    with atomic_path(Path(path)) as tmp:
        shutil.copyfile(npz, tmp)
    return True


def store(path, sensor, scenes) -> Path:
    """Put the reference saved at ``path`` into the cache (atomically; the checksum last)."""
    npz, sha = _entry(cache_key(sensor, scenes))
    with atomic_path(npz) as tmp:
        shutil.copyfile(path, tmp)
    write_text(sha, _digest(npz) + "\n")
    return npz
