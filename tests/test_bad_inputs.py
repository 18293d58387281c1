"""Issues 18 and 39: every bad input a user can type exits 2 with exactly one line on stderr, before any work,
and changes nothing committed.

Each case runs through the real command line (``nlosplan.cli.main`` in this process) and asserts exit code 2,
exactly one line on stderr (``nlosplan: error: ...``, with the words that say what is wrong), no traceback, and
that the stores, logs and outputs it names are byte for byte unchanged (SHA-1 before and after) and that no
product file was left behind. The cases that need the machine (a read-only medium, a full disk: root and a
tmpfs) skip with the reason elsewhere. The files are built by ``bad_input_files.make_files``. Interruptions
(kill -9, then resume) are in test_interruptions.py; signals, locked stores and standard output in
test_signals_and_locks.py; issue 39's own sweep of 100 further cases in test_bad_inputs_sweep.py.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from nlosplan.cli import main
from nlosplan.data.store import CaptureStore

from bad_input_files import DESIGN_TOMLS, check_one_line, digest, fill, make_files, mount

BIG = str(10**30)


# ----------------------------------------------------------------------------- fixtures
@pytest.fixture(scope="module")
def fx(tmp_path_factory):
    """Files of every kind a user may point a command at (built once; cases must not change them)."""
    d = make_files(tmp_path_factory.mktemp("bad"))
    yield d
    for p in d.rglob("*"):  # chmod'ed fixtures must stay removable
        if p.is_dir():
            os.chmod(p, 0o755)


@pytest.fixture(scope="module")
def readonly(fx, tmp_path_factory):
    """A read-only folder holding a copy of the store: a read-only bind mount as root, chmod otherwise."""
    src = tmp_path_factory.mktemp("rosrc")
    shutil.copy(fx / "store.sqlite", src / "store.sqlite")
    if os.geteuid() == 0:
        ro = tmp_path_factory.mktemp("ro")
        if not (mount("--bind", str(src), str(ro)) and mount("-o", "remount,ro,bind", str(ro))):
            subprocess.run(["umount", str(ro)], capture_output=True)
            pytest.skip("read-only medium: running as root, but this container may not mount (no CAP_SYS_ADMIN); "
                        "chmod does not stop root")
        yield ro
        subprocess.run(["umount", str(ro)], capture_output=True)
    else:
        os.chmod(src / "store.sqlite", 0o444)
        os.chmod(src, 0o555)
        yield src
        os.chmod(src, 0o755)


@pytest.fixture
def full_disk(tmp_path):
    """``tmpfs(size)``: a small tmpfs mounted in tmp_path (root only), or skip with the reason."""
    mounted = []

    def tmpfs(size: str = "64k") -> Path:
        if os.geteuid() != 0:
            pytest.skip("a full disk needs a small tmpfs, which only root can mount")
        mnt = tmp_path / f"full{len(mounted)}"
        mnt.mkdir()
        if not mount("-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(mnt)):
            pytest.skip("cannot mount a tmpfs here (no CAP_SYS_ADMIN in this container)")
        mounted.append(mnt)
        return mnt

    yield tmpfs
    for mnt in mounted:
        subprocess.run(["umount", str(mnt)], capture_output=True)


# ----------------------------------------------------------------------------- the cases
SIM = ["simulate", "--fidelity", "draft"]
DESIGN = ["design", "--quick", "--workers", "1"]
BUILD = ["dataset", "build", "--objects", "A", "--sizes", "8in", "--positions", "0-1", "--repeats", "1",
         "--fidelity", "draft"]
BENCH = ["benchmark", "--models", "mlp", "--tasks", "size", "--small"]
OBS = ["evaluate", "observer", "shape", "--objects", "A,S", "--positions", "0-1", "--fidelity", "draft"]
CRLB = ["evaluate", "crlb", "--objects", "A", "--positions", "0-1", "--fidelity", "draft"]
RIG = ["rig", "capture", "--emulate", "--positions", "0", "--repeats", "1"]

# (id, argv with {F} for the fixture folder, words the error line must hold, paths that must not change,
#  paths that must not exist afterwards)
CASES = [
    # ---- simulate: sensor files, flags named as typed, outputs, sizes, seeds
    ("sim-sensor-binary", SIM + ["--sensor", "{F}/bin.toml"], "is a binary file, not text", (), ()),
    ("sim-sensor-binary-json", SIM + ["--sensor", "{F}/bin.json"], "is a binary file, not text", (), ()),
    ("sim-sensor-empty", SIM + ["--sensor", "{F}/empty.toml"], "the file is empty; name the preset it refines", (), ()),
    ("sim-sensor-empty-json", SIM + ["--sensor", "{F}/empty.json"], "empty.json is empty", (), ()),
    ("sim-sensor-partial", SIM + ["--sensor", "{F}/partial.toml"], "the file misses ambient_rate_hz", (), ()),
    ("sim-sensor-typo", SIM + ["--sensor", "{F}/typo.toml"], "unknown field(s) jiter_fwhm_ps", (), ()),
    ("sim-sensor-type", SIM + ["--sensor", "{F}/wrongtype.toml"], "n_bins='many' must be an integer", (), ()),
    ("sim-sensor-list", SIM + ["--sensor", "{F}/list.json"], "must hold a JSON object", (), ()),
    ("sim-sensor-missing", SIM + ["--sensor", "{F}/missing.toml"], "missing.toml does not exist", (), ()),
    ("sim-sensor-folder", SIM + ["--sensor", "{F}/dir.toml"], "is a folder, not a file", (), ()),
    ("sim-zones-0", SIM + ["--zones", "0x3"], "argument --zones: 0x3 is out of range", (), ()),
    ("sim-zones-17", SIM + ["--zones", "17x17"], "argument --zones: 17x17 is out of range", (), ()),
    ("sim-zones-abc", SIM + ["--zones", "abc"], "argument --zones: 'abc' must look like 3x3", (), ()),
    ("sim-jitter-neg", SIM + ["--jitter-ps", "-50"], "argument --jitter-ps: -50 must be >= 0", (), ()),
    ("sim-jitter-nan", SIM + ["--jitter-ps", "nan"], "argument --jitter-ps: nan is not a finite number", (), ()),
    ("sim-bins-0", SIM + ["--bins", "0"], "argument --bins: 0 is out of range; allowed: 1 to 4096", (), ()),
    ("sim-bins-5000", SIM + ["--bins", "5000"], "argument --bins: 5000 is out of range", (), ()),
    ("sim-binwidth-inf", SIM + ["--bin-width-ps", "inf"], "argument --bin-width-ps: inf is not a finite", (), ()),
    ("sim-seed-neg", SIM + ["--seed", "-1"], "argument --seed: -1 is out of range; allowed: 0 to 4294967295", (), ()),
    ("sim-seed-huge", SIM + ["--seed", BIG], "argument --seed: 1000000000000000000000000000000 is out of range",
     (), ()),
    ("sim-repeats-huge", SIM + ["--repeats", str(10**9), "--out", "{F}/o1"], "--repeats 1000000000 needs about",
     (), ("{F}/o1",)),
    ("sim-zones-bins-repeats", SIM + ["--zones", "16x16", "--bins", "4096", "--repeats", "10000", "--out", "{F}/o2"],
     "needs about", (), ("{F}/o2",)),
    ("sim-out-inside-file", SIM + ["--out", "{F}/afile/x"], "afile is a file, not a folder", ("{F}/afile",), ()),
    ("sim-out-is-file", SIM + ["--out", "{F}/afile"], "--out {F}/afile is a file; give a folder",
     ("{F}/afile",), ()),
    ("sim-out-npy-inside-file", SIM + ["--out", "{F}/afile/x.npy"], "afile is a file, not a folder", (), ()),
    ("sim-plot-ext", SIM + ["--out", "{F}/o3", "--plot", "{F}/p.xyz"], "unknown file type '.xyz'", (), ("{F}/o3",)),
    ("sim-plot-inside-file", SIM + ["--out", "{F}/o4", "--plot", "{F}/afile/p.png"], "afile is a file", (),
     ("{F}/o4",)),
    ("sim-position", SIM + ["--position", "100"], "position", (), ()),
    ("sim-object", SIM + ["--object", "nope"], "nope", (), ()),
    ("sim-only-zones", SIM + ["--only-zones", "x"], "--only-zones 'x' must be ROW,COL pairs", (), ()),
    ("sim-wall-samples", ["simulate", "--scene", "wall", "--samples", "0"],
     "argument --samples: 0 is out of range; allowed: 1 to 256", (), ()),
    ("sim-wall-other-flag", ["simulate", "--scene", "wall", "--position", "3"], "applies only to --scene denali",
     (), ()),
    ("sim-mitsuba-explain", ["simulate", "--backend", "mitsuba", "--explain"], "--explain applies to the fast", (), ()),
    # ---- sensor
    ("sensor-show-binary", ["sensor", "show", "{F}/bin.toml"], "is a binary file", (), ()),
    ("sensor-show-empty", ["sensor", "show", "{F}/empty.toml"], "the file is empty", (), ()),
    ("sensor-show-partial", ["sensor", "show", "{F}/partial.json"], "the file misses", (), ()),
    ("sensor-show-nosuffix", ["sensor", "show", "{F}/afile"], "sensor file {F}/afile must end in .toml or .json", (),
     ()),
    ("sensor-show-unknown", ["sensor", "show", "tmf9999"], "unknown sensor preset 'tmf9999'", (), ()),
    ("sensor-fit-binary", ["sensor", "fit-timebase", "{F}/bin.json"], "capture file", (), ()),
    ("sensor-fit-list", ["sensor", "fit-timebase", "{F}/list.json"], "each entry needs dist_to_plane", (), ()),
    ("sensor-alone", ["sensor"], "nlosplan sensor: give a subcommand: list, show, fit-timebase", (), ()),
    # ---- bench
    ("bench-hist-batch0", ["bench", "histogram", "--batch", "0"], "argument --batch: 0 must be >= 1", (), ()),
    ("bench-hist-seconds-neg", ["bench", "histogram", "--seconds", "-1"], "argument --seconds: -1 must be > 0", (), ()),
    ("bench-hist-seconds-nan", ["bench", "histogram", "--seconds", "nan"], "nan is not a finite number", (), ()),
    ("bench-hist-batch-huge", ["bench", "histogram", "--batch", str(10**12)], "--batch 1000000000000 needs about",
     (), ()),
    ("bench-sim-levels", ["bench", "simulate", "--levels", "nope"], "argument --levels", (), ()),
    ("bench-sim-refpos", ["bench", "simulate", "--reference-positions", "200"], "200 out of range", (), ()),
    ("bench-sim-objects", ["bench", "simulate", "--objects", "nope"], "unknown object 'nope'", (), ()),
    ("bench-sim-sizes", ["bench", "simulate", "--sizes", "5in"], "5in not allowed", (), ()),
    ("bench-sim-sensor", ["bench", "simulate", "--sensor", "{F}/bin.toml"], "is a binary file", (), ()),
    ("bench-sim-plot", ["bench", "simulate", "--plot", "{F}/b.xyz"], "unknown file type '.xyz'", (), ()),
    ("bench-fid-plot", ["bench", "fidelity", "--plot", "{F}/f.xyz"], "unknown file type '.xyz'", (), ()),
    ("bench-crossval-objects", ["bench", "crossval", "--objects", "nope"], "unknown object 'nope'", (), ()),
    # ---- dataset build
    ("build-store-inside-file", BUILD + ["--store", "{F}/afile/s.sqlite"], "afile is a file, not a folder",
     ("{F}/afile",), ()),
    ("build-store-folder", BUILD + ["--store", "{F}/adir"], "--store {F}/adir is a folder", (), ()),
    ("build-store-not-store", BUILD + ["--store", "{F}/bin.sqlite"], "is not an nlosplan capture store",
     ("{F}/bin.sqlite",), ()),
    ("build-repeats-huge", BUILD[:-4] + ["--repeats", str(10**9), "--store", "{F}/b1.sqlite"], "needs about",
     (), ("{F}/b1.sqlite",)),
    ("build-seed-huge", BUILD + ["--seed", BIG, "--store", "{F}/b2.sqlite"], "argument --seed", (),
     ("{F}/b2.sqlite",)),
    ("build-positions", ["dataset", "build", "--positions", "100", "--store", "{F}/b3.sqlite"], "'100' is out of range",
     (), ("{F}/b3.sqlite",)),
    ("build-objects", ["dataset", "build", "--objects", "nope", "--store", "{F}/b3.sqlite"], "unknown object 'nope'",
     (), ("{F}/b3.sqlite",)),
    ("build-sensor-empty", BUILD + ["--sensor", "{F}/empty.toml", "--store", "{F}/b4.sqlite"], "the file is empty",
     (), ("{F}/b4.sqlite",)),
    # ---- dataset import-denali: counts outside the sensor's range, empty imports
    ("import-1e30", ["dataset", "import-denali", "{F}/den_big", "--store", "{F}/i1.sqlite"],
     "count 1e+30 at index [0, 0, 0, 0] is above the sensor's 24-bit range", (), ("{F}/i1.sqlite",)),
    ("import-negative", ["dataset", "import-denali", "{F}/den_neg", "--store", "{F}/i2.sqlite"], "is negative", (),
     ("{F}/i2.sqlite",)),
    ("import-fraction", ["dataset", "import-denali", "{F}/den_frac", "--store", "{F}/i3.sqlite"],
     "is not a whole number of counts", (), ("{F}/i3.sqlite",)),
    ("import-24bit", ["dataset", "import-denali", "{F}/den_over", "--store", "{F}/i4.sqlite"],
     "count 33554432 at index [0, 0, 0, 0] is above", (), ("{F}/i4.sqlite",)),
    ("import-nan", ["dataset", "import-denali", "{F}/den_nan", "--store", "{F}/i5.sqlite"], "is not a finite number",
     (), ("{F}/i5.sqlite",)),
    ("import-into-good-store", ["dataset", "import-denali", "{F}/den_big", "--store", "{F}/store.sqlite"],
     "above the sensor's 24-bit range", ("{F}/store.sqlite",), ()),
    ("import-empty", ["dataset", "import-denali", "{F}/den_empty", "--store", "{F}/i6.sqlite"],
     "no capture files to import", (), ("{F}/i6.sqlite",)),
    ("import-missing", ["dataset", "import-denali", "{F}/nothere", "--store", "{F}/i7.sqlite"],
     "does not exist or is not a folder", (), ("{F}/i7.sqlite",)),
    ("import-store-inside-file", ["dataset", "import-denali", "{F}/den_ok", "--store", "{F}/afile/i.sqlite"],
     "afile is a file", ("{F}/afile",), ()),
    ("import-positions-binary", ["dataset", "import-denali", "{F}/den_ok", "--store", "{F}/i8.sqlite",
                                 "--positions-json", "{F}/bin.json"], "bin.json is a binary file, not text", (),
     ("{F}/i8.sqlite",)),
    ("import-sensor-empty", ["dataset", "import-denali", "{F}/den_ok", "--store", "{F}/i9.sqlite", "--sensor",
                             "{F}/empty.toml"], "the file is empty", (), ("{F}/i9.sqlite",)),
    # ---- dataset export-denali and info
    ("export-out-file", ["dataset", "export-denali", "--store", "{F}/store.sqlite", "--out", "{F}/afile"],
     "--out {F}/afile is a file; give a folder", ("{F}/afile", "{F}/store.sqlite"), ()),
    ("export-out-inside-file", ["dataset", "export-denali", "--store", "{F}/store.sqlite", "--out", "{F}/afile/e"],
     "afile is a file, not a folder", ("{F}/store.sqlite",), ()),
    ("export-nothing", ["dataset", "export-denali", "--store", "{F}/store.sqlite", "--out", "{F}/e1", "--zones",
                        "5x5"], "no captures to export", ("{F}/store.sqlite",), ("{F}/e1",)),
    ("export-not-store", ["dataset", "export-denali", "--store", "{F}/bin.sqlite", "--out", "{F}/e2"],
     "is not an nlosplan capture store", ("{F}/bin.sqlite",), ("{F}/e2",)),
    ("info-missing", ["dataset", "info", "--store", "{F}/nothere.sqlite"], "does not exist", (),
     ("{F}/nothere.sqlite",)),
    ("info-not-store", ["dataset", "info", "--store", "{F}/bin.sqlite"], "is not an nlosplan capture store",
     ("{F}/bin.sqlite",), ()),
    ("info-empty-file", ["dataset", "info", "--store", "{F}/empty.json"], "is not an nlosplan capture store",
     ("{F}/empty.json",), ()),
    ("info-folder", ["dataset", "info", "--store", "{F}/adir"], "is a folder", (), ()),
    ("dataset-alone", ["dataset"], "give a subcommand: build, import-denali, export-denali, info", (), ()),
    # ---- benchmark
    ("bench-store-missing", BENCH + ["--store", "{F}/nothere.sqlite"], "does not exist", (), ("{F}/nothere.sqlite",)),
    ("bench-where-garbage", BENCH + ["--store", "{F}/store.sqlite", "--where", "garbage"], "--where 'garbage'",
     ("{F}/store.sqlite",), ()),
    ("bench-where-nothing", BENCH + ["--store", "{F}/store.sqlite", "--where", "object=nope", "--out", "{F}/bm1"],
     "no captures in", ("{F}/store.sqlite",), ("{F}/bm1",)),
    ("bench-models", BENCH[:1] + ["--store", "{F}/store.sqlite", "--models", "nope"], "unknown model(s) nope", (), ()),
    ("bench-epochs", BENCH[:1] + ["--store", "{F}/store.sqlite", "--epochs", "0"], "argument --epochs: 0 must be > 0",
     (), ()),
    ("bench-seed", BENCH + ["--store", "{F}/store.sqlite", "--seed", BIG], "argument --seed", (), ()),
    ("bench-out-file", BENCH + ["--store", "{F}/store.sqlite", "--out", "{F}/afile"], "is a file; give a folder",
     ("{F}/afile", "{F}/store.sqlite"), ()),
    # ---- evaluate
    ("crlb-repeats0", CRLB + ["--repeats", "0"], "argument --repeats: 0 is out of range; allowed: 1 to 1000000",
     (), ()),
    ("crlb-repeats-huge", CRLB + ["--repeats", BIG], "argument --repeats", (), ()),
    ("active-config-binary", ["study", "active-vs-raster", "--config", "{F}/bin.toml"], "is a binary file", (), ()),
    ("crlb-nuisance", CRLB + ["--nuisance", "none,ambient"], "--nuisance none cannot be combined", (), ()),
    ("crlb-sensor-empty", CRLB + ["--sensor", "{F}/empty.toml"], "the file is empty", (), ()),
    ("crlb-photon-neg", CRLB + ["--photon-scale", "-1"], "argument --photon-scale: -1 must be >= 0", (), ()),
    ("obs-draws-huge", OBS + ["--draws", str(10**12)], "--draws 1000000000000 needs about", (), ()),
    ("obs-seed-neg", OBS + ["--seed", "-1"], "argument --seed: -1 is out of range", (), ()),
    ("obs-seed-huge", OBS + ["--seed", BIG], "argument --seed", (), ()),
    ("obs-shape-known", OBS + ["--shape-known"], "--shape-known only applies to the size task", (), ()),
    ("obs-sensor-binary", OBS + ["--sensor", "{F}/bin.toml"], "is a binary file", (), ()),
    # ---- study jitter
    ("jitter-no-data", ["study", "jitter"], "study jitter needs data", (), ()),
    ("jitter-pickle", ["study", "jitter", "--store", "{F}/store.sqlite", "--trust-pickle"],
     "--trust-pickle only applies with --denali", (), ()),
    ("jitter-levels", ["study", "jitter", "--store", "{F}/store.sqlite", "--jitter-ps", "-5"],
     "jitter -5 ps is not allowed", (), ()),
    ("jitter-out-file", ["study", "jitter", "--store", "{F}/store.sqlite", "--out", "{F}/afile"], "is a file",
     ("{F}/afile", "{F}/store.sqlite"), ()),
    ("jitter-plot-ext", ["study", "jitter", "--store", "{F}/store.sqlite", "--out", "{F}/j1", "--plot", "{F}/j.xyz"],
     "unknown file type '.xyz'", ("{F}/store.sqlite",), ("{F}/j1",)),
    ("jitter-store-missing", ["study", "jitter", "--store", "{F}/nothere.sqlite", "--out", "{F}/j2"],
     "does not exist", (), ("{F}/nothere.sqlite",)),
    # ---- design: config files checked when read, flags that do not apply, inputs checked before the references
    ("design-config-binary", DESIGN + ["--config", "{F}/bin.toml", "--out", "{F}/d0"], "is a binary file", (),
     ("{F}/d0",)),
    ("design-config-folder", DESIGN + ["--config", "{F}/dir.toml", "--out", "{F}/d0"], "is a folder", (), ("{F}/d0",)),
    *[(f"design-toml-{k}", DESIGN + ["--config", f"{{F}}/d_{k}.toml", "--out", "{F}/d0"], word, (), ("{F}/d0",))
      for k, word in (("stride0", "[scenes]: positions_stride = 0 must be an integer from 1 to 99"),
                      ("stride_two", '[scenes]: positions_stride = "two" must be an integer'),
                      ("seeds_three", '[search]: seeds = "three" must be an integer from 1 to 20'),
                      ("bound_high", "[search.fidelity] bound = 'high' must be a table of knobs"),
                      ("cost_cheap", '[cost]: zones = "cheap" must be a number from 0 to 1000'),
                      ("threshold_abc", '[[requirements]] #1: threshold = "abc" must be a number'),
                      ("jitter_lots", '[space]: jitter_fwhm_ps = "lots" must be [low, high]'),
                      ("zones_int", "[space]: zones = 3 must be a non-empty list"),
                      ("grid_neg", "[search]: grid_points = -2 must be an integer from 1 to 100"),
                      ("repeats_float", "[scenes]: repeats = 1.5 must be an integer >= 1"),
                      ("objects_bad", '[scenes]: objects = ["nope"] must be a non-empty list'),
                      ("epochs_str", '[search.fidelity.trained]: epochs = "four" must be an integer'),
                      ("lights_dim", "[scenes]: lights = \"dim\" must be one of 'off', 'on'"),
                      ("jitter_huge", "[space]: jitter_fwhm_ps = [0, 1e+308] must be [low, high] with low <= high, "
                                      "each a number from 0 to 1e+07 ps"),
                      ("deep", "d_deep.toml: space.axes is nested deeper than 32 levels"))],
    ("design-where-no-real", DESIGN + ["--config", "{F}/tiny.toml", "--where", "lights=off", "--out", "{F}/d1"],
     "--where applies only with --real STORE", (), ("{F}/d1",)),
    ("design-capture-sensor-no-real", DESIGN + ["--capture-sensor", "tmf8828-3x3-short", "--out", "{F}/d1"],
     "--capture-sensor applies only with --real", (), ("{F}/d1",)),
    ("design-resume-nothing", DESIGN + ["--config", "{F}/tiny.toml", "--resume", "--out", "{F}/d2"],
     "--resume: there is no run to resume", (), ("{F}/d2/design_evaluations.jsonl",)),
    ("design-repair-alone", DESIGN + ["--repair", "--out", "{F}/d3"], "--repair applies only with --resume", (),
     ("{F}/d3",)),
    ("design-overwrite-resume", DESIGN + ["--overwrite", "--resume", "--out", "{F}/d3"], "exclude each other", (),
     ("{F}/d3",)),
    ("design-real-missing", DESIGN + ["--real", "{F}/nothere.sqlite", "--out", "{F}/d4"], "does not exist", (),
     ("{F}/d4", "{F}/nothere.sqlite")),
    ("design-real-not-store", DESIGN + ["--real", "{F}/bin.sqlite", "--out", "{F}/d4"],
     "is not an nlosplan capture store", ("{F}/bin.sqlite",), ("{F}/d4",)),
    ("design-real-capture-sensor", DESIGN + ["--real", "{F}/store.sqlite", "--capture-sensor", "nope", "--out",
                                             "{F}/d4"], "unknown sensor preset 'nope'", ("{F}/store.sqlite",),
     ("{F}/d4",)),
    ("design-real-where", DESIGN + ["--real", "{F}/store.sqlite", "--where", "object=nope", "--out", "{F}/d4"],
     "no captures in", ("{F}/store.sqlite",), ("{F}/d4",)),
    ("design-real-zones", DESIGN + ["--real", "{F}/store.sqlite", "--capture-sensor", "tmf8828-8x8-short", "--out",
                                    "{F}/d4"], "has no 8x8 captures (it holds 3x3 captures)", ("{F}/store.sqlite",),
     ("{F}/d4",)),
    ("design-out-file", DESIGN + ["--out", "{F}/afile"], "--out {F}/afile is a file", ("{F}/afile",), ()),
    ("design-out-inside-file", DESIGN + ["--out", "{F}/afile/d"], "afile is a file, not a folder", ("{F}/afile",), ()),
    ("design-requirement", DESIGN + ["--requirement", "speed<=3"], "must look like loc<=0.05", (), ()),
    # ---- issue 39: numbers (strict ASCII, physical ranges), files (depth, duplicates, FIFOs), damaged stores
    ("sim-binwidth-tiny", SIM + ["--bin-width-ps", "1e-300"],
     "argument --bin-width-ps: 1e-300 is out of range; allowed: 1 to 1e+06 ps", (), ()),
    ("sim-binwidth-huge", SIM + ["--bin-width-ps", "1e308"], "argument --bin-width-ps: 1e308 is out of range", (), ()),
    ("sim-jitter-huge", SIM + ["--jitter-ps", "1e308"],
     "argument --jitter-ps: 1e308 is out of range; allowed: 0 to 1e+07 ps", (), ()),
    ("sim-zones-arabic", SIM + ["--zones", "\u0663x\u0663"], "argument --zones: '\u0663x\u0663' must look like 3x3",
     (), ()),
    ("sim-repeats-underscore", SIM + ["--repeats", "1_0"],
     "argument --repeats: '1_0' is not an integer (ASCII digits only)", (), ()),
    ("sim-sensor-binwidth-huge", SIM + ["--sensor", "{F}/bw_huge.toml"],
     "bw_huge.toml: bin_width_ps=1e+308 is out of range; allowed: 1 to 1e+06 ps", (), ()),
    ("sensor-show-binwidth-huge", ["sensor", "show", "{F}/bw_huge.toml"], "bin_width_ps=1e+308 is out of range", (),
     ()),
    ("sensor-show-dup-key", ["sensor", "show", "{F}/dup.json"],
     "dup.json: the key 'n_bins' is given twice in one object", (), ()),
    ("sensor-show-deep-json", ["sensor", "show", "{F}/deep.json"],
     "sensor file {F}/deep.json: base is nested deeper than 32 levels", (), ()),
    ("sensor-show-deep-toml", ["sensor", "show", "{F}/deep.toml"],
     "sensor file {F}/deep.toml: base is nested deeper than 32 levels", (), ()),
    ("sensor-show-fifo", ["sensor", "show", "{F}/fifo.toml"], "fifo.toml is a FIFO (named pipe), not a regular file",
     (), ()),
    ("dry-run-plan-deep", ["rig", "dry-run", "--plan", "{F}/deep_plan.json"],
     "positions file {F}/deep_plan.json: the top level is nested deeper than 32 levels", (), ()),
    ("capture-rig-file-deep", ["rig", "capture", "--emulate", "--gantry-kind", "telemetrix", "--rig-file",
                               "{F}/deep_rig.toml", "--store", "{F}/r0.db"],
     "rig file {F}/deep_rig.toml: telemetrix.origin_mm is nested deeper than 32 levels", (), ("{F}/r0.db",)),
    ("dry-run-limits-huge", ["rig", "dry-run", "--limits", "0:1e308,0:320"],
     "argument --limits: 0:1e308,0:320 is out of range; allowed: -10000 to 10000 mm", (), ()),
    ("capture-run-empty", RIG + ["--run", "", "--store", "{F}/r1.db"], "argument --run: '': a run id is 1 to 200", (),
     ("{F}/r1.db",)),
    ("capture-faults-nan", RIG + ["--emulate-faults", "drop=nan", "--store", "{F}/r1.db"],
     "argument --emulate-faults: fault drop=nan is out of range", (), ("{F}/r1.db",)),
    ("capture-settle-huge", RIG + ["--settle", "1e308", "--store", "{F}/r1.db"],
     "argument --settle: 1e308 is out of range; allowed: 0 to 3600 s", (), ("{F}/r1.db",)),
    ("capture-feed-tiny", RIG + ["--feed", "1e-300", "--store", "{F}/r1.db"],
     "argument --feed: 1e-300 is out of range; allowed: 1 to 100000 mm/min", (), ("{F}/r1.db",)),
    ("capture-work-offset-huge", RIG + ["--work-offset", "1e308,0", "--store", "{F}/r1.db"],
     "--work-offset X=1e+308 is out of range; allowed: -10000 to 10000 mm", (), ("{F}/r1.db",)),
    ("capture-time-scale-huge", RIG + ["--time-scale", "1e308", "--store", "{F}/r1.db"],
     "argument --time-scale: 1e308 is out of range; allowed: 0.1 to 10000", (), ("{F}/r1.db",)),
    ("run-run-empty", ["rig", "run", "--emulate", "--run", "", "--store", "{F}/r1.db", "--out", "{F}/rr"],
     "argument --run: '': a run id is 1 to 200", (), ("{F}/r1.db", "{F}/rr")),
    ("import-positions-nan", ["dataset", "import-denali", "{F}/den_ok", "--store", "{F}/i10.sqlite",
                              "--positions-json", "{F}/pos_nan.json"],
     "positions file {F}/pos_nan.json: frame0_tag1 x=nan must be finite", (), ("{F}/i10.sqlite",)),
    ("import-positions-huge", ["dataset", "import-denali", "{F}/den_ok", "--store", "{F}/i10.sqlite",
                               "--positions-json", "{F}/pos_huge.json"],
     "frame0_tag1 x=1e+308 is out of range; allowed: -100 to 100 m", (), ("{F}/i10.sqlite",)),
    ("crlb-photon-huge", CRLB + ["--photon-scale", "1e300"],
     "argument --photon-scale: 1e300 is out of range; allowed: 0 to 1e+12", (), ()),
    ("info-fifo", ["dataset", "info", "--store", "{F}/fifo.sqlite"],
     "capture store {F}/fifo.sqlite is a FIFO (named pipe), not a regular file", (), ()),
    ("status-fifo", ["rig", "status", "--store", "{F}/fifo.sqlite"], "fifo.sqlite is a FIFO (named pipe)", (), ()),
    ("build-fifo", BUILD + ["--store", "{F}/fifo.sqlite"], "fifo.sqlite is a FIFO (named pipe)", (), ()),
    *[(f"{cmd}-no-sensors", argv + ["--store", "{F}/nosensors.sqlite"],
       "capture store {F}/nosensors.sqlite is damaged: it has no sensors table", ("{F}/nosensors.sqlite",), ())
      for cmd, argv in (("info", ["dataset", "info"]), ("status", ["rig", "status"]),
                        ("export", ["dataset", "export-denali", "--out", "{F}/e3"]))],
    ("status-blob-size", ["rig", "status", "--store", "{F}/badblob.sqlite"],
     "is damaged: its histogram holds 100 bytes, 9216 expected for shape [3, 3, 128] of <i8", ("{F}/badblob.sqlite",),
     ()),
    ("export-blob-size", ["dataset", "export-denali", "--store", "{F}/badblob.sqlite", "--out", "{F}/e4"],
     "capture 3 (A|8in|1|off|3x3|0|sim:fast|", ("{F}/badblob.sqlite",), ("{F}/e4",)),
    ("export-blob-dtype", ["dataset", "export-denali", "--store", "{F}/baddtype.sqlite", "--out", "{F}/e5"],
     "its histogram dtype '<f8' is not one of <i8, <f4", ("{F}/baddtype.sqlite",), ("{F}/e5",)),
    ("export-negative-count", ["dataset", "export-denali", "--store", "{F}/negcount.sqlite", "--out", "{F}/e6"],
     "a count of -9187201950435737472 is negative", ("{F}/negcount.sqlite",), ("{F}/e6",)),
    ("export-corrupt-page", ["dataset", "export-denali", "--store", "{F}/corrupt.sqlite", "--out", "{F}/e7"],
     "capture store {F}/corrupt.sqlite is damaged (SQLite's quick check:", ("{F}/corrupt.sqlite",), ("{F}/e7",)),
    ("serve-corrupt-page", ["serve", "{F}/corrupt.sqlite", "--port", "0"], "is damaged (SQLite's quick check:",
     ("{F}/corrupt.sqlite",), ()),
    # ---- the command itself
    ("no-command", [], "give a command: design, sensor, simulate", (), ()),
    ("bad-command", ["bogus-command"], "invalid choice: 'bogus-command'", (), ()),
    ("bad-flag", ["--bogus"], "unrecognized arguments: --bogus", (), ()),
]


def test_the_suite_is_large_enough():
    assert len(CASES) >= 80 and len({c[0] for c in CASES}) == len(CASES)


@pytest.mark.parametrize("name, argv, words, unchanged, absent", CASES, ids=[c[0] for c in CASES])
def test_bad_input_exits_2_with_one_line_and_changes_nothing(fx, capsys, name, argv, words, unchanged, absent):
    watched = {p: digest(Path(p)) for p in fill(unchanged, fx)}
    code = main(fill(argv, fx))
    _, err = capsys.readouterr()
    check_one_line(code, err, fill(words, fx))
    for p, d in watched.items():
        assert digest(Path(p)) == d, f"{p} changed"
    for p in fill(absent, fx):
        assert not Path(p).exists(), f"{p} was left behind"


# ----------------------------------------------------------------------------- cases that need a fixture each
def test_npy_out_that_is_a_folder(fx, capsys):
    (fx / "adir.npy").mkdir(exist_ok=True)
    check_one_line(main(SIM + ["--out", str(fx / "adir.npy")]), capsys.readouterr().err,
                    f"--out {fx / 'adir.npy'} is a folder; give a file path")


def _design_run(out: Path, tiny: Path, n: int = 6) -> Path:
    """A design output folder as a run of the tiny configuration leaves it (checkpoint + an evaluation log)."""
    from nlosplan.cli import build_parser
    from nlosplan.cli.design import build_config
    from nlosplan.planner.design.run import CHECKPOINT, EVALUATIONS

    cfg = build_config(build_parser().parse_args(DESIGN + ["--config", str(tiny)]))
    out.mkdir()
    (out / CHECKPOINT).write_text(json.dumps({"config_hash": cfg.hash(), "config": cfg.to_dict(), "candidates": None,
                                              "optimize_log": []}))
    rows = [{"evaluator": "bound", "task": "loc", "design": {"zones": "1x1", "bin_factor": 1, "n_bins": 128,
                                                             "jitter_fwhm_ps": float(i), "pulse_fwhm_ps": 0.0,
                                                             "photon_fraction": 1.0},
             "seed": 0, "value": 0.1, "status": "ok"} for i in range(n)]
    (out / EVALUATIONS).write_text("".join(json.dumps(r) + "\n" for r in rows))
    return out / EVALUATIONS


def test_resume_on_a_damaged_log_names_the_lines_and_changes_nothing(fx, tmp_path, capsys):
    log = _design_run(tmp_path / "d", fx / "tiny.toml")
    lines = log.read_text().splitlines()
    lines[1], lines[3] = lines[1][:20], "garbage"
    log.write_text("\n".join(lines) + "\n")
    before = digest(tmp_path / "d")
    code = main(DESIGN + ["--config", str(fx / "tiny.toml"), "--resume", "--out", str(tmp_path / "d")])
    line = check_one_line(code, capsys.readouterr().err, "line(s) 2, 4 of 6 are damaged")
    assert "--repair" in line
    assert digest(tmp_path / "d") == before


def test_a_rerun_over_a_previous_run_is_refused_without_overwrite(fx, tmp_path, capsys):
    _design_run(tmp_path / "d", fx / "tiny.toml")
    before = digest(tmp_path / "d")
    code = main(DESIGN + ["--config", str(fx / "tiny.toml"), "--out", str(tmp_path / "d")])
    line = check_one_line(code, capsys.readouterr().err, "holds a previous run (6 evaluations)")
    assert "--resume" in line and "--overwrite" in line
    assert digest(tmp_path / "d") == before


def test_resume_with_another_configuration_changes_nothing(fx, tmp_path, capsys):
    _design_run(tmp_path / "d", fx / "tiny.toml")
    before = digest(tmp_path / "d")
    code = main(DESIGN + ["--resume", "--out", str(tmp_path / "d")])  # --quick without the tiny TOML
    check_one_line(code, capsys.readouterr().err, "is from a run with another configuration")
    assert digest(tmp_path / "d") == before


@pytest.mark.parametrize("argv, words", [
    (SIM + ["--out", "{RO}/x"], "cannot write in {RO} (Read-only file system)"),
    (BUILD + ["--store", "{RO}/new.sqlite"], "cannot write in {RO}"),
    (["dataset", "build", "--objects", "A", "--sizes", "8in", "--positions", "0", "--repeats", "1", "--fidelity",
      "draft", "--store", "{RO}/store.sqlite"], "cannot write in {RO}"),
    (["dataset", "export-denali", "--store", "{F}/store.sqlite", "--out", "{RO}/e"], "cannot write in {RO}"),
    (DESIGN + ["--out", "{RO}/d"], "cannot write in {RO}"),
    (BENCH + ["--store", "{F}/store.sqlite", "--out", "{RO}/b"], "cannot write in {RO}"),
    (["rig", "run", "--emulate", "--budget", "2", "--store", "{F}/rr.sqlite", "--out", "{RO}/x"],
     "cannot write in {RO}"),
])
def test_a_read_only_target_is_refused_before_any_work(fx, readonly, capsys, argv, words):
    if os.geteuid() != 0:
        words = words.replace(" (Read-only file system)", "")
    before = digest(readonly)
    argv = [a.replace("{RO}", str(readonly)) for a in fill(argv, fx)]
    check_one_line(main(argv), capsys.readouterr().err, fill(words, fx).replace("{RO}", str(readonly)))
    assert digest(readonly) == before


@pytest.mark.parametrize("argv", [
    ["dataset", "info", "--store", "{RO}/store.sqlite", "--json"],
    ["dataset", "export-denali", "--store", "{RO}/store.sqlite", "--out", "{OUT}/e", "--json"],
    ["rig", "status", "--store", "{RO}/store.sqlite", "--json"],
])
def test_a_read_only_store_is_read_and_left_unchanged(fx, readonly, tmp_path, capsys, argv):
    before = digest(readonly)
    code = main([a.replace("{RO}", str(readonly)).replace("{OUT}", str(tmp_path)) for a in argv])
    out, err = capsys.readouterr()
    assert code == 0, err
    assert json.loads(out)
    assert digest(readonly) == before
    if argv[1] == "info":
        assert json.loads(out)["captures"] == 16


def test_design_real_captures_open_a_read_only_store(fx, readonly, capsys):
    """The check of --real before the references opens the store read-only (a read-only medium works)."""
    from nlosplan.data.load import check_captures

    assert check_captures(readonly / "store.sqlite", {"zones": "3x3"}, drop_backgrounds=True) == {"zones": "3x3"}


# ----------------------------------------------------------------------------- full disk
def test_full_disk_is_refused_before_simulating(full_disk, capsys):
    disk = full_disk("64k")
    (disk / "fill").write_bytes(b"\0" * 40_000)
    code = main(SIM + ["--repeats", "3", "--out", str(disk / "s")])
    check_one_line(code, capsys.readouterr().err, "the output needs about")
    assert not (disk / "s").exists()


def test_a_plot_on_a_full_disk_is_refused_before_simulating(full_disk, capsys):
    """The arrays fit, the figure would not: found when the path is checked, not after the simulation."""
    disk = full_disk("256k")
    code = main(SIM + ["--out", str(disk / "s"), "--plot"])
    line = check_one_line(code, capsys.readouterr().err, f"--plot {disk / 's' / 'histograms.png'}: the output needs "
                                                         "about 1.0 MB but only")
    assert "free some space or choose another place" in line
    assert not (disk / "s").exists()


def test_full_disk_while_importing_keeps_the_committed_captures(fx, full_disk, tmp_path, capsys):
    """The disk fills during the import: one line saying what is kept and how to go on; the store stays sound."""
    root = tmp_path / "data" / "A_8inch_3x3_lightoff_NLOSdata" / "spad_histogram"
    root.mkdir(parents=True)
    for i in range(40):
        np.save(root / f"{i:03d}.npy", np.random.default_rng(i).integers(0, 1 << 20, (3, 3, 3, 128)))
    store = full_disk("400k") / "s.sqlite"
    code = main(["dataset", "import-denali", str(tmp_path / "data"), "--store", str(store)])
    line = check_one_line(code, capsys.readouterr().err, "the captures committed before are kept")
    assert "rerun the same command" in line
    with CaptureStore(store, readonly=True) as st:
        assert st.integrity_check() == "ok"
        kept = st.count()
    assert 0 < kept < 120


def test_atomic_write_on_a_full_disk_leaves_the_old_file_and_no_temporary(full_disk):
    from nlosplan.files import WriteFailed, save_npy, write_text

    disk = full_disk("64k")
    old = write_text(disk / "report.md", "the old report\n")
    with pytest.raises(WriteFailed, match=r"cannot write .*report.md: No space left on device; .* free on that disk"):
        write_text(disk / "report.md", "x" * 200_000)
    assert old.read_text() == "the old report\n"
    with pytest.raises(WriteFailed, match="a.npy"):
        save_npy(disk / "a.npy", np.zeros(100_000))
    assert sorted(p.name for p in disk.iterdir()) == ["report.md"]  # no 0-byte, truncated or temporary file


def test_every_physical_range_is_documented_with_its_flags():
    """docs/reliability.md's table states each range of nlosplan.schema.QUANTITIES and the flags held to it."""
    from nlosplan.cli.common import FLAG_QUANTITIES
    from nlosplan.schema import QUANTITIES

    rows = [line for line in (Path(__file__).resolve().parents[1] / "docs" / "reliability.md").read_text().splitlines()
            if line.startswith("| ") and " | " in line]
    for name, q in QUANTITIES.items():
        row = [r for r in rows if name in r.split(" | ")[0] and f"| {q.allowed()} |" in r]
        assert row, f"{name}: {q.allowed()} is not in docs/reliability.md"
        flags = [f for f, n in FLAG_QUANTITIES.items() if n == name]
        assert all(f"`{f}`" in row[0] for f in flags), (name, flags, row[0])
