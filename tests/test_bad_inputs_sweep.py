"""Issue 39's own sweep: 100 further bad inputs, beyond the issue's list, each exit 2 with one line before any work.

Found as a tester who did not write the code would: integers in other scripts' digits or with ``_``, numbers beyond
any physical range, files nested, duplicated, oversized or not files at all, stores damaged in ways SQLite does not
see, empty or impossible paths. Every case runs through ``nlosplan.cli.main`` in this process (a watchdog fails a
case that hangs) and must give exit 2 and exactly one line naming what is wrong.

Run as a script it runs every case as its own ``python -m nlosplan`` process against the tree on ``PYTHONPATH`` and
prints the problems by kind (traceback, hang, accepted, more than one line), the figures in docs/reliability.md::

    PYTHONPATH=. python tests/test_bad_inputs_sweep.py            # this tree
    PYTHONPATH=/path/to/other/tree python tests/test_bad_inputs_sweep.py
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

PLANE = str(Path(__file__).resolve().parents[2] / "shared" / "data" / "tmf882x_distance" / "distance_data_even.json")
DEEP = "[" * 5000 + "]" * 5000
AR3, AR1, FW4 = "\u0663", "\u0661", "\uff14"   # Arabic-Indic 3 and 1, fullwidth 4


def sweep_files(d: Path) -> Path:
    """The files the cases point at, in ``d`` (returned)."""
    from nlosplan.data.store import CaptureStore
    from nlosplan.sensor_models import preset

    rng = np.random.default_rng(0)
    with CaptureStore(d / "store.sqlite") as st:
        st.put_many([(rng.poisson(40, (3, 3, 128)), dict(object=o, size=s, position=p, lights="off", repeat=r,
                                                       source="sim:fast", x=0.01 * p, y=0.3))
                     for o in ("A", "S") for s in ("4in", "8in") for p in range(4) for r in range(2)],
                    sensor=preset("tmf8828-3x3-short"))
    for name, sql in (("xstr", "UPDATE captures SET x = 'abc' WHERE id = 2"),
                      ("nometa", "ALTER TABLE captures DROP COLUMN meta"),
                      ("badmeta", "UPDATE captures SET meta = '{not json' WHERE id = 2"),
                      ("stepstr", "UPDATE captures SET meta = json_set(meta, '$.run_id', 'r', '$.step', 'abc') "
                                  "WHERE id = 2"),
                      ("badsensor", "UPDATE sensors SET config = '{\"bin_width_ps\": 1e308}'"),
                      ("textblob", "UPDATE captures SET data = 'not a histogram' WHERE id = 2"),
                      ("badshape", "UPDATE captures SET shape = '[3, 3]' WHERE id = 2")):
        shutil.copy(d / "store.sqlite", d / f"{name}.sqlite")
        db = sqlite3.connect(d / f"{name}.sqlite")
        db.execute(sql)
        db.commit()
        db.close()
    base = 'base = "tmf8828-3x3-short"\n'
    files = {
        "ambient.toml": base + "ambient_rate_hz = 1e13\n",
        "dead.toml": base + "dead_time_ps = 1e-300\npileup = true\n",
        "gains.toml": base + "zone_gains = [1e308, 1, 1, 1, 1, 1, 1, 1, 1]\n",
        "inf.json": '{"base": "tmf8828-3x3-short", "jitter_fwhm_ps": Infinity}',
        "e400.json": '{"base": "tmf8828-3x3-short", "photon_scale": 1e400}',
        "base_long.toml": 'base = "' + "x" * 5000 + '"\n',
        "key_long.toml": base + "k" * 5000 + " = 1\n",
        "float_bins.json": '{"base": "tmf8828-3x3-short", "n_bins": 64.5}',
        "bom.toml": "\ufeff" + base,
        "many.toml": "[space]\nzones = [" + ", ".join(['"3x3"'] * 100_001) + "]\n",
        "cost_huge.toml": "[cost]\nzones = 1e308\n",
        "grid_huge.toml": "[search]\ngrid_points = 1000000000\n",
        "pulse_huge.toml": "[space]\npulse_fwhm_ps = [0, 1e308]\n",
        "plan_us.csv": "x_mm,y_mm\n1_0,20\n",
        "plan_dup.json": '[{"x_mm": 1, "x_mm": 2, "y_mm": 3}]',
        "rig_speed.toml": "[telemetrix]\nmax_speed = 1e308\n",
        "deep_stats.json": '{"a": ' + DEEP + "}",
        "deep_stats.toml": "a = " + DEEP + "\n",
        "deep_fit.json": DEEP,
        "active_deep.toml": "[study]\nx = " + DEEP + "\n",
        "pos_arabic.json": json.dumps({f"frame{AR3}_tag1": [0.1, 0.3]}, ensure_ascii=False),
        "pos_dup.json": '{"frame0_tag1": [0.1, 0.3], "frame0_tag1": [0.2, 0.3]}',
    }
    for name, text in files.items():
        (d / name).write_text(text, encoding="utf-8")
    (d / "big.toml").write_text("")
    os.truncate(d / "big.toml", 70 * 2**20)   # sparse: 70 MB without the disk
    for name in ("fifo.toml", "fifo.csv"):
        os.mkfifo(d / name)
    den = d / "den" / "A_8inch_3x3_lightoff_NLOSdata" / "spad_histogram"
    den.mkdir(parents=True)
    np.save(den / "000.npy", rng.poisson(50, (2, 3, 3, 128)))
    return d


S = "{F}/store.sqlite"
RIG = ["rig", "capture", "--emulate", "--positions", "0", "--repeats", "1", "--store", "{F}/r.db"]
RUN = ["rig", "run", "--emulate", "--budget", "2", "--store", "{F}/r.db", "--out", "{F}/rr"]
BENCH = ["benchmark", "--store", S, "--small", "--models", "mlp", "--tasks", "size", "--out", "{F}/bm"]
IMPORT = ["dataset", "import-denali", "{F}/den", "--store", "{F}/i.sqlite", "--positions-json"]
OUT = "nlosplan simulate: argument"

# (id, kind, argv with {F} for the files' folder, words the one line must hold)
CASES = [
    # ---- integers: ASCII digits only, in every flag and list
    ("bins-underscore", "integers", ["simulate", "--bins", "1_000"], "argument --bins: '1_000' is not an integer"),
    ("bins-fullwidth", "integers", ["simulate", "--bins", FW4], f"argument --bins: '{FW4}' is not an integer"),
    ("seed-arabic", "integers", ["simulate", "--seed", AR1], "argument --seed:"),
    ("seed-hex", "integers", ["simulate", "--seed", "0x10"], "argument --seed: '0x10' is not an integer"),
    ("position-arabic", "integers", ["simulate", "--position", AR3], "argument --position:"),
    ("only-zones-arabic", "integers", ["simulate", "--only-zones", f"{AR1},{AR1}"], "--only-zones"),
    ("crlb-repeats-arabic", "integers", ["evaluate", "crlb", "--repeats", AR3], "argument --repeats:"),
    ("observer-draws-underscore", "integers", ["evaluate", "observer", "shape", "--draws", "1_0"],
     "argument --draws: '1_0' is not an integer"),
    ("bench-arrivals-arabic", "integers", ["bench", "histogram", "--arrivals", AR3], "argument --arrivals:"),
    ("build-positions-arabic", "integers", ["dataset", "build", "--positions", AR3, "--store", "{F}/b.sqlite"],
     "argument --positions:"),
    ("build-positions-underscore", "integers", ["dataset", "build", "--positions", "1_0", "--store", "{F}/b.sqlite"],
     "argument --positions: '1_0' is not a position"),
    ("dry-run-positions-underscore", "integers", ["rig", "dry-run", "--positions", "1_0"], "argument --positions:"),
    ("bench-refpos-underscore", "integers", ["bench", "simulate", "--reference-positions", "1_0"],
     "argument --reference-positions:"),
    ("active-budget-arabic", "integers", ["study", "active-vs-raster", "--budget", AR3], "argument --budget:"),
    ("active-seeds-underscore", "integers", ["study", "active-vs-raster", "--seeds", "0,1_0"], "argument --seeds:"),
    ("calibrate-bootstrap-underscore", "integers", ["calibrate", PLANE, "--bootstrap", "1_0"],
     "argument --bootstrap: '1_0' is not an integer"),
    ("where-repeat-underscore", "integers", BENCH + ["--where", "repeat=1_0"], "--where repeat=1_0: repeat takes"),
    ("cluster-arabic", "integers", ["design", "--quick", "--cluster", f"local:{AR3}", "--out", "{F}/d"],
     "argument --cluster:"),
    ("serve-port-fullwidth", "integers", ["serve", S, "--port", FW4 * 4], "argument --port:"),
    ("live-port-arabic", "integers", RIG + ["--live", AR3 * 4], "argument --live:"),
    # ---- numbers: finite, ASCII, within the physical range, before any work
    ("jitter-above", "numbers", ["simulate", "--jitter-ps", "10000001"], "argument --jitter-ps: 10000001 is out of"),
    ("diffuse-above", "numbers", ["simulate", "--diffuse-albedo", "1.0000001"], "argument --diffuse-albedo:"),
    ("object-albedo-negative", "numbers", ["simulate", "--object-albedo", "-0.1"],
     "argument --object-albedo: -0.1 is out of range; allowed: 0 to 1"),
    ("object-albedo-nan", "numbers", ["simulate", "--object-albedo", "nan"], "nan is not a finite number"),
    ("lobe-huge", "numbers", ["simulate", "--lobe-deg", "1e308"], "lobe_fwhm_deg=1e+308 is out of range"),
    ("wall-distance-negative", "numbers", ["simulate", "--scene", "corner", "--wall-distance", "-1"],
     "wall-distance"),
    ("wall-distance-huge", "numbers", ["simulate", "--scene", "corner", "--wall-distance", "1e308"],
     "argument --wall-distance: 1e308 is out of range; allowed: > 0 and <= 100 m"),
    ("object-size-zero", "numbers", ["simulate", "--scene", "corner", "--object-size", "0"], "object-size"),
    ("object-yaw-huge", "numbers", ["simulate", "--scene", "corner", "--object-yaw", "1e308"],
     "argument --object-yaw: 1e308 is out of range; allowed: -360 to 360 deg"),
    ("object-xy-nan", "numbers", ["simulate", "--scene", "corner", "--object-xy", "nan,0.3"], "object_xy[0]=nan"),
    ("object-xy-huge", "numbers", ["simulate", "--scene", "corner", "--object-xy", "1e308,0.3"],
     "object_xy[0]=1e+308 is out of range; allowed: -100 to 100 m"),
    ("object-xy-underscore", "numbers", ["simulate", "--scene", "corner", "--object-xy", "1_0,0.3"],
     "--object-xy '1_0,0.3' must be two numbers"),
    ("wall-distance-zero", "numbers", ["simulate", "--scene", "wall", "--distance", "0"], "argument --distance: 0"),
    ("wall-yaw-90", "numbers", ["simulate", "--scene", "wall", "--yaw", "90"], "yaw_deg=90.0 is out of range"),
    ("wall-albedo-2", "numbers", ["simulate", "--scene", "wall", "--albedo", "2"], "argument --albedo: 2 is out"),
    ("wall-samples-huge", "numbers", ["simulate", "--scene", "wall", "--samples", "100000000"],
     "argument --samples: 100000000 is out of range; allowed: 1 to 256"),
    ("observer-photons-inf", "numbers", ["evaluate", "observer", "shape", "--photon-scale", "inf"],
     "argument --photon-scale: inf is not a finite number"),
    ("bench-seconds-tiny", "numbers", ["bench", "histogram", "--seconds", "1e-300"],
     "argument --seconds: 1e-300 is out of range; allowed: 0.01 to 3600 s"),
    ("bench-rig-seconds-huge", "numbers", ["bench", "rig", "--seconds", "1e308"], "argument --seconds: 1e308 is out"),
    ("benchmark-width-huge", "numbers", BENCH + ["--width", "1e308"], "argument --width: 1e308 is out of range"),
    ("benchmark-budget-tiny", "numbers", BENCH + ["--max-seconds", "1e-300"], "argument --max-seconds: 1e-300"),
    ("benchmark-threads-huge", "numbers", BENCH + ["--threads", "100000"], "argument --threads: 100000 is out"),
    ("jitter-threads-zero", "numbers", ["study", "jitter", "--store", S, "--threads", "0"], "argument --threads: 0"),
    ("holdout-nan", "numbers", ["calibrate", PLANE, "--holdout", "nan"], "argument --holdout: nan is not a finite"),
    ("min-distance-huge", "numbers", ["bench", "real", "--min-distance", "1e308"], "argument --min-distance: 1e308"),
    ("target-rmse-negative", "numbers", RUN + ["--target-rmse", "-1"], "argument --target-rmse: -1 must be > 0"),
    ("target-rmse-huge", "numbers", RUN + ["--target-rmse", "1e308"],
     "argument --target-rmse: 1e308 is out of range; allowed: > 0 and <= 10 m"),
    ("limits-nan", "numbers", ["rig", "dry-run", "--limits", "0:320,0:nan"],
     "argument --limits: '0:320,0:nan': each value must be a finite number of mm"),
    ("limits-underscore", "numbers", ["rig", "dry-run", "--limits", "0:1_0,0:320"], "argument --limits:"),
    ("settle-negative", "numbers", ["rig", "dry-run", "--settle", "-1"], "argument --settle: -1 must be >= 0"),
    ("feed-huge", "numbers", ["rig", "dry-run", "--feed", "1e6"],
     "argument --feed: 1e6 is out of range; allowed: 1 to 100000 mm/min"),
    ("time-scale-tiny", "numbers", RIG + ["--time-scale", "0.001"], "argument --time-scale: 0.001 is out of range"),
    ("fault-slow-huge", "numbers", RIG + ["--emulate-faults", "slow=1e308"], "fault slow=1e308 is out of range"),
    ("fault-garble-fraction", "numbers", RIG + ["--emulate-faults", "garble=1.5"], "a whole number from 0 to"),
    ("work-offset-underscore", "numbers", RIG + ["--work-offset", "1_0,0"], "--work-offset '1_0,0': use auto"),
    ("jitter-levels-huge", "numbers", ["study", "jitter", "--store", S, "--jitter-ps", "0,1e308"],
     "argument --jitter-ps: 0,1e308 is out of range"),
    ("active-targets-inf", "numbers", ["study", "active-vs-raster", "--more-targets", "0.05,inf"],
     "argument --more-targets: '0.05,inf': give targets > 0 m"),
    ("requirement-huge", "numbers", ["design", "--quick", "--requirement", "loc<=1e308", "--out", "{F}/d"],
     "loc threshold 1e+308 must be > 0 and <= 10 (metres)"),
    ("requirement-zero", "numbers", ["design", "--quick", "--requirement", "loc<=0", "--out", "{F}/d"],
     "loc threshold 0.0 must be > 0"),
    ("requirement-above-one", "numbers", ["design", "--quick", "--requirement", "size>=1.5", "--out", "{F}/d"],
     "size threshold 1.5 must be in (0, 1]"),
    # ---- configuration files: capped, strict, regular files
    ("design-many-items", "files", ["design", "--quick", "--config", "{F}/many.toml", "--out", "{F}/d"],
     "space.zones holds 100001 items; at most 100000 are allowed"),
    ("design-fifo", "files", ["design", "--quick", "--config", "{F}/fifo.toml", "--out", "{F}/d"],
     "fifo.toml is a FIFO (named pipe), not a regular file"),
    ("design-70-mb", "files", ["design", "--quick", "--config", "{F}/big.toml", "--out", "{F}/d"],
     "big.toml holds 70 MB; it may hold at most 64 MB"),
    ("design-cost-huge", "files", ["design", "--quick", "--config", "{F}/cost_huge.toml", "--out", "{F}/d"],
     "[cost]: zones = 1e+308 must be a number from 0 to 1000"),
    ("design-grid-huge", "files", ["design", "--quick", "--config", "{F}/grid_huge.toml", "--out", "{F}/d"],
     "[search]: grid_points = 1000000000 must be an integer from 1 to 100"),
    ("design-pulse-huge", "files", ["design", "--quick", "--config", "{F}/pulse_huge.toml", "--out", "{F}/d"],
     "[space]: pulse_fwhm_ps = [0, 1e+308] must be [low, high]"),
    ("sensor-ambient-huge", "files", ["sensor", "show", "{F}/ambient.toml"],
     "ambient_rate_hz=1e+13 is out of range; allowed: 0 to 1e+12 Hz"),
    ("sensor-dead-time-tiny", "files", ["sensor", "show", "{F}/dead.toml"], "dead_time_ps=1e-300 is out of range"),
    ("sensor-gain-huge", "files", ["sensor", "show", "{F}/gains.toml"], "zone_gains[0]=1e+308 is out of range"),
    ("sensor-json-infinity", "files", ["sensor", "show", "{F}/inf.json"], "jitter_fwhm_ps=inf must be finite"),
    ("sensor-json-1e400", "files", ["sensor", "show", "{F}/e400.json"], "photon_scale=inf must be finite"),
    ("sensor-base-long", "files", ["sensor", "show", "{F}/base_long.toml"],
     "base = 'xxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxx'... (5000 characters) is not a sensor preset"),
    ("sensor-key-long", "files", ["sensor", "show", "{F}/key_long.toml"], "kkkkkkkkkkkkkkkkkkkkkkkkkkkkkkkkkkkkkkkk..."),
    ("sensor-float-bins", "files", ["sensor", "show", "{F}/float_bins.json"], "n_bins=64.5 must be an integer"),
    ("sensor-bom", "files", ["sensor", "show", "{F}/bom.toml"], "bom.toml is not valid TOML"),
    ("sensor-fifo", "files", ["sensor", "show", "{F}/fifo.toml"], "fifo.toml is a FIFO (named pipe)"),
    ("plan-underscore", "files", ["rig", "dry-run", "--plan", "{F}/plan_us.csv"], "line 2: expected two numbers"),
    ("plan-duplicate-key", "files", ["rig", "dry-run", "--plan", "{F}/plan_dup.json"],
     "the key 'x_mm' is given twice in one object"),
    ("plan-fifo", "files", ["rig", "dry-run", "--plan", "{F}/fifo.csv"], "fifo.csv is a FIFO (named pipe)"),
    ("plan-device", "files", ["rig", "dry-run", "--plan", "/dev/zero"], "/dev/zero is a character device"),
    ("rig-file-speed-huge", "files", ["rig", "capture", "--emulate", "--gantry-kind", "telemetrix", "--rig-file",
                                      "{F}/rig_speed.toml", "--store", "{F}/r.db"], "max_speed = 1e+308"),
    ("stats-deep-json", "files", ["calibrate", "--stats", "{F}/deep_stats.json"],
     "statistics file {F}/deep_stats.json: a is nested deeper than 32 levels"),
    ("stats-deep-toml", "files", ["calibrate", "--stats", "{F}/deep_stats.toml"], "a is nested deeper than 32"),
    ("score-deep", "files", ["calibrate", "--score", "{F}/deep_fit.json", "--sensor", "tmf8828-3x3-short"],
     "the top level is nested deeper than 32 levels"),
    ("fit-timebase-deep", "files", ["sensor", "fit-timebase", "{F}/deep_fit.json"],
     "capture file {F}/deep_fit.json: the top level is nested deeper"),
    ("active-config-deep", "files", ["study", "active-vs-raster", "--config", "{F}/active_deep.toml"],
     "study.x is nested deeper than 32 levels"),
    ("positions-arabic-frame", "files", IMPORT + ["{F}/pos_arabic.json"], "is not a frame number with [x, y, ...]"),
    ("positions-duplicate-key", "files", IMPORT + ["{F}/pos_dup.json"], "the key 'frame0_tag1' is given twice"),
    # ---- stores: what SQLite does not check, a device
    ("store-x-text", "stores", BENCH[:-2] + ["--tasks", "loc"] + ["--store", "{F}/xstr.sqlite"],
     "capture 2 of capture store {F}/xstr.sqlite is damaged: its x label 'abc' is not a number"),
    ("store-no-meta-column", "stores", ["rig", "status", "--store", "{F}/nometa.sqlite"],
     "is damaged: its captures table has no meta column"),
    ("store-meta-not-json", "stores", ["rig", "status", "--store", "{F}/badmeta.sqlite"],
     "is damaged: its metadata is not a JSON object"),
    ("store-step-text", "stores", ["rig", "status", "--store", "{F}/stepstr.sqlite"],
     "is damaged: its run id or step ('r', 'abc') is not a name and a step number"),
    ("store-sensor-out-of-range", "stores", ["dataset", "export-denali", "--store", "{F}/badsensor.sqlite", "--out",
                                             "{F}/e"], "bin_width_ps=1e+308 is out of range"),
    ("store-device", "stores", ["dataset", "info", "--store", "/dev/zero"], "/dev/zero is a character device"),
    ("store-histogram-text", "stores", ["rig", "status", "--store", "{F}/textblob.sqlite"],
     "is damaged: its histogram holds 15 bytes, 9216 expected"),
    ("store-shape-wrong", "stores", ["dataset", "export-denali", "--store", "{F}/badshape.sqlite", "--out", "{F}/e"],
     "its histogram shape '[3, 3]' is not [rows, cols, bins]"),
    # ---- paths and names
    ("out-empty", "paths", ["simulate", "--out", ""], "argument --out: give a path (it is empty)"),
    ("out-name-too-long", "paths", ["simulate", "--out", "{F}/" + "x" * 300], "a name in the path is longer than 255"),
    ("plot-device", "paths", ["simulate", "--out", "{F}/o", "--plot", "/dev/full"], "--plot /dev/full: unknown file"),
    ("export-out-device", "paths", ["dataset", "export-denali", "--store", S, "--out", "/dev/null"],
     "--out /dev/null is a file; give a folder"),
    ("store-empty", "paths", ["dataset", "build", "--store", ""], "argument --store: give a path (it is empty)"),
    ("real-empty", "paths", ["design", "--quick", "--real", "", "--out", "{F}/d"], "argument --real: give a path"),
    ("run-id-slash", "paths", RIG + ["--run", "a/b"], "argument --run: 'a/b': a run id is 1 to 200"),
    ("run-id-long", "paths", RIG + ["--run", "r" * 300], "a run id is 1 to 200 printable characters"),
]

KINDS = ("integers", "numbers", "files", "stores", "paths")


def fill(value, folder: Path):
    return [str(v).replace("{F}", str(folder)) for v in value] if isinstance(value, list) else \
        str(value).replace("{F}", str(folder))


# ----------------------------------------------------------------------------- the test
try:
    import pytest
except ImportError:  # the script needs no pytest
    pytest = None

if pytest is not None:
    @pytest.fixture(scope="module")
    def sw(tmp_path_factory):
        return sweep_files(tmp_path_factory.mktemp("sweep"))

    def test_the_sweep_holds_100_distinct_cases():
        assert len(CASES) >= 100 and len({c[0] for c in CASES}) == len(CASES)
        assert {c[1] for c in CASES} == set(KINDS)

    @pytest.mark.parametrize("name, kind, argv, words", CASES, ids=[c[0] for c in CASES])
    def test_further_bad_input_is_one_line_before_any_work(sw, capsys, name, kind, argv, words):
        from nlosplan.cli import main

        from bad_input_files import check_one_line

        def hang(signum, frame):
            raise TimeoutError(f"{name} did not end within 120 s")

        old = signal.signal(signal.SIGALRM, hang)
        signal.alarm(120)
        try:
            code = main(fill(argv, sw))
        finally:
            signal.alarm(0)
            signal.signal(signal.SIGALRM, old)
        line = check_one_line(code, capsys.readouterr().err, fill(words, sw))
        assert len(line) < 1000 and "x" * 100 not in line and "k" * 100 not in line, line   # no huge value echoed
        assert not (sw / "d").exists() and not (sw / "e").exists() and not (sw / "o").exists()


# ----------------------------------------------------------------------------- the script
#: Seconds a case may take as its own process (the command's start-up alone is 5 to 20 s on a loaded machine).
SCRIPT_TIMEOUT_S = 90


def _classify(code, err: str) -> str:
    lines = err.strip().splitlines()
    if code == "hang":
        return f"no answer within {SCRIPT_TIMEOUT_S} s (work started, or a hang)"
    if "Traceback" in err:
        return "traceback"
    if code == 0:
        return "accepted (a silent wrong answer)"
    if code != 2 or len(lines) != 1 or not lines[0].startswith("nlosplan: error: "):
        return "more than one line or another exit"
    return ""


def main_script() -> int:
    import tempfile

    folder = sweep_files(Path(tempfile.mkdtemp(prefix="sweep39-")))
    found: dict = {}
    for name, kind, argv, _ in CASES:
        t0 = time.monotonic()
        try:
            r = subprocess.run([sys.executable, "-m", "nlosplan", *fill(argv, folder)], capture_output=True, text=True,
                               timeout=SCRIPT_TIMEOUT_S, cwd=folder)
            code, err = r.returncode, r.stderr
        except subprocess.TimeoutExpired:
            code, err = "hang", ""
        problem = _classify(code, err)
        found.setdefault(kind, []).append(problem)
        print(f"{name:32s} {kind:9s} {time.monotonic() - t0:5.1f} s  {problem or 'ok'}"
              f"{'' if problem else ''}  | {(err.strip().splitlines() or [''])[-1][:110]}", flush=True)
    print("\nkind       cases  problems")
    for kind in KINDS:
        print(f"{kind:10s} {len(found.get(kind, [])):5d}  {sum(bool(p) for p in found.get(kind, [])):8d}")
    by = {}
    for probs in found.values():
        for p in probs:
            if p:
                by[p] = by.get(p, 0) + 1
    print("\n" + "\n".join(f"{v:4d}  {k}" for k, v in sorted(by.items())) or "no problems")
    shutil.rmtree(folder, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main_script())
