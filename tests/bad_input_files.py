"""Files of every kind a user may point a command at, for the bad-input tests (test_bad_inputs*.py).

:func:`make_files` builds them in a folder once per test module; the cases must not change them. Also the
shared checks: :func:`check_one_line` (exit 2, one line ``nlosplan: error: ...`` with the given words, no
traceback), :func:`digest` (SHA-1 of a file or folder, to prove nothing changed) and :func:`fill`.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import sqlite3
import subprocess
from pathlib import Path

import numpy as np
import pytest

from nlosplan.data.store import CaptureStore
from nlosplan.sensor_models import preset


def digest(path: Path) -> str:
    if not path.exists():
        return "absent"
    if path.is_dir():
        h = hashlib.sha1()
        for p in sorted(path.rglob("*")):
            if p.is_file():
                h.update(str(p.relative_to(path)).encode() + p.read_bytes())
        return h.hexdigest()
    return hashlib.sha1(path.read_bytes()).hexdigest()


def mount(*args: str) -> bool:
    return subprocess.run(["mount", *args], capture_output=True).returncode == 0


#: Design TOMLs: (text replaced, replacement) in the tiny configuration.
DESIGN_TOMLS = {
    "stride0": ("positions_stride = 10", "positions_stride = 0"),
    "stride_two": ("positions_stride = 10", 'positions_stride = "two"'),
    "seeds_three": ("seeds = 1", 'seeds = "three"'),
    "bound_high": ("[search.fidelity.bound]\ndraws = 60", '[search.fidelity]\nbound = "high"'),
    "cost_cheap": ("[search]", '[cost]\nzones = "cheap"\n[search]'),
    "threshold_abc": ("[search]", '[[requirements]]\ntask = "loc"\nthreshold = "abc"\n[search]'),
    "jitter_lots": ("[space]\n", '[space]\njitter_fwhm_ps = "lots"\n'),
    "zones_int": ('zones = ["1x1", "3x3"]', "zones = 3"),
    "grid_neg": ("grid_points = 3", "grid_points = -2"),
    "repeats_float": ("repeats = 1", "repeats = 1.5"),
    "objects_bad": ('objects = ["A", "S", "circle"]', 'objects = ["nope"]'),
    "epochs_str": ("epochs = 4", 'epochs = "four"'),
    "lights_dim": ('fidelity = "draft"', 'fidelity = "draft"\nlights = "dim"'),
    "jitter_huge": ("[space]\n", "[space]\njitter_fwhm_ps = [0, 1e308]\n"),
    "deep": ("[space]\n", "[space]\naxes = " + "[" * 5000 + "]" * 5000 + "\n"),
}


def make_files(d: Path) -> Path:
    """Build the files in folder ``d`` (returned)."""
    blob = bytes(np.random.default_rng(1).integers(0, 256, 2000, dtype=np.uint8))
    for name in ("bin.toml", "bin.json", "bin.sqlite"):
        (d / name).write_bytes(blob)
    (d / "empty.toml").write_text("")
    (d / "empty.json").write_text("")
    (d / "partial.toml").write_text("n_bins = 64\n")
    (d / "partial.json").write_text('{"n_bins": 64}')
    (d / "typo.toml").write_text('base = "tmf8828-3x3-short"\njiter_fwhm_ps = 3.0\n')
    (d / "wrongtype.toml").write_text('base = "tmf8828-3x3-short"\nn_bins = "many"\n')
    (d / "list.json").write_text("[1, 2, 3]")
    (d / "afile").write_text("x")
    (d / "adir").mkdir()
    (d / "dir.toml").mkdir()
    # a small store of synthetic captures (no simulation: fast)
    sensor = preset("tmf8828-3x3-short")
    rng = np.random.default_rng(0)
    with CaptureStore(d / "store.sqlite") as st:
        st.put_many([(rng.poisson(40, (3, 3, 128)), dict(object=o, size="8in", position=p, lights="off", repeat=r,
                                                       source="sim:fast", x=0.01 * p, y=0.3))
                     for o in ("A", "S") for p in range(4) for r in range(2)], sensor=sensor)
    # DENALI folders with counts a TMF8828 cannot give
    base = rng.poisson(50, (2, 3, 3, 128))
    for name, arr in (("den_ok", base), ("den_big", np.full(base.shape, 1e30)), ("den_neg", -base),
                      ("den_frac", base + 0.5), ("den_over", np.full(base.shape, 2**25)),
                      ("den_nan", np.where(base > 60, np.nan, base.astype(float)))):
        f = d / name / "A_8inch_3x3_lightoff_NLOSdata" / "spad_histogram"
        f.mkdir(parents=True)
        for i in range(2):
            np.save(f / f"{i:03d}.npy", arr)
    (d / "den_empty" / "README_folder").mkdir(parents=True)
    # design TOMLs with wrong types (checked when the file is read)
    tiny = ('[space]\nzones = ["1x1", "3x3"]\nbin_factors = [1, 2]\naxes = ["zones", "jitter_fwhm_ps"]\n'
            "[search]\ngrid_points = 3\nrefine_steps = 1\nseeds = 1\ncandidates = 1\noptimize_evals = 4\n"
            "[search.fidelity.bound]\ndraws = 60\n[search.fidelity.trained]\nepochs = 4\nbootstrap = 50\n"
            '[scenes]\nobjects = ["A", "S", "circle"]\npositions_stride = 10\nrepeats = 1\ncrlb_objects = ["A"]\n'
            'crlb_stride = 5\nfidelity = "draft"\n')
    (d / "tiny.toml").write_text(tiny)
    for key, (old, new) in DESIGN_TOMLS.items():
        assert old in tiny, key
        (d / f"d_{key}.toml").write_text(tiny.replace(old, new, 1))
    _issue39_files(d)
    return d


def _issue39_files(d: Path) -> None:
    """Issue 39's files: numbers out of range, nesting and keys a parser chokes on, FIFOs, damaged stores."""
    (d / "bw_huge.toml").write_text('base = "tmf8828-3x3-short"\nbin_width_ps = 1e308\n')
    (d / "dup.json").write_text('{"base": "tmf8828-3x3-short", "n_bins": 64, "n_bins": 32}')
    deep = "[" * 100_000 + "]" * 100_000
    (d / "deep.json").write_text('{"base": ' + deep + "}")
    (d / "deep.toml").write_text("base = " + deep + "\n")
    (d / "deep_plan.json").write_text(deep)
    (d / "deep_rig.toml").write_text("[telemetrix]\norigin_mm = " + deep + "\n")
    (d / "pos_nan.json").write_text('{"frame0_tag1": [NaN, 0.3], "frame1_tag1": [0.1, 0.3]}')
    (d / "pos_huge.json").write_text('{"frame0_tag1": [1e308, 0.3], "frame1_tag1": [0.1, 0.3]}')
    for name in ("fifo.sqlite", "fifo.toml"):
        os.mkfifo(d / name)
    for name, sql in (("nosensors", "DROP TABLE sensors"),
                      ("badblob", "UPDATE captures SET data = substr(data, 1, 100) WHERE id = 3"),
                      ("baddtype", "UPDATE captures SET dtype = '<f8' WHERE id = 3"),
                      # the issue's -9.18e18: 0x80 bytes where counts were
                      ("negcount", "UPDATE captures SET data = X'" + "80" * 16 + "' || substr(data, 17) WHERE id = 3")):
        shutil.copy(d / "store.sqlite", d / f"{name}.sqlite")
        db = sqlite3.connect(d / f"{name}.sqlite")
        db.execute("PRAGMA foreign_keys = OFF")
        db.execute("PRAGMA ignore_check_constraints = ON")
        db.execute(sql)
        db.commit()
        db.close()
    # a corrupt page mid-file (SQLite's quick check finds it; the counts read through it were -9.18e18)
    with CaptureStore(d / "corrupt.sqlite") as st:
        rng = np.random.default_rng(2)
        st.put_many([(rng.poisson(40, (3, 3, 128)), dict(object="A", size="8in", position=p, lights="off", repeat=r,
                                                       source="sim:fast", x=0.01 * p, y=0.3))
                     for p in range(50) for r in range(3)], sensor=preset("tmf8828-3x3-short"))
    with open(d / "corrupt.sqlite", "r+b") as fh:
        fh.seek(2 * 4096)
        fh.write(bytes(np.random.default_rng(3).integers(0, 256, 4096, dtype=np.uint8)))
    with pytest.raises(Exception, match="quick check"):
        CaptureStore(d / "corrupt.sqlite", readonly=True, check=True)


def fill(value, folder: Path):
    return [str(v).replace("{F}", str(folder)) for v in value] if isinstance(value, (list, tuple)) else \
        str(value).replace("{F}", str(folder))


def check_one_line(code: int, err: str, words: str) -> str:
    lines = err.strip().splitlines()
    assert code == 2, err
    assert "Traceback" not in err, err
    assert len(lines) == 1, err
    assert lines[0].startswith("nlosplan: error: "), lines[0]
    assert words in lines[0], lines[0]
    return lines[0]
