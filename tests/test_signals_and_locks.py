"""Issue 39: interrupts, standard output, locked and damaged stores.

- SIGTERM and Ctrl-C finalize a rig run (sensor stopped, gantry parked) and the command exits 143 / 130, never 0,
  also when the interrupt comes while Python shuts down; repeated Ctrl-C cannot cut finalize short.
- Standard output on a full device is one line and a non-zero exit.
- A store another process holds is found before any work; one dataset build of the same captures at a time.
- Every histogram read is checked (size, dtype, finite, counts within 24 bits): a damaged one is one line naming it.
"""

from __future__ import annotations

import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from nlosplan.cli import main
from nlosplan.cli.common import Terminated, sigterm_interrupts
from nlosplan.data.records import decode_histogram
from nlosplan.data.store import LOCK_WAIT_S, CaptureStore
from nlosplan.errors import UserError
from nlosplan.hardware.executor import Executor, RunContext
from nlosplan.hardware.plans import raster_plan
from nlosplan.hardware.rig import emulated_rig
from nlosplan.sensor_models import SensorConfig

from bad_input_files import check_one_line, digest, make_files

ROOT = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}
CTX = RunContext("A", "8in", source="emulated:rig", plan="signals")
BUILD = ["dataset", "build", "--sensor", "tmf8828-3x3-short", "--objects", "A", "--sizes", "8in", "--positions", "0-1",
         "--repeats", "1", "--fidelity", "draft", "--batch", "2"]


@pytest.fixture(scope="module")
def fx(tmp_path_factory):
    return make_files(tmp_path_factory.mktemp("sig"))


# ----------------------------------------------------------------------------- interrupts
def test_main_exits_130_on_ctrl_c_and_143_on_sigterm(monkeypatch, capsys):
    import nlosplan.cli.sensor as sensor_cli

    def ctrl_c(args):
        raise KeyboardInterrupt

    def sigterm(args):
        with sigterm_interrupts():
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(5)   # the handler raises before this ends
        raise AssertionError("SIGTERM did not interrupt")

    monkeypatch.setattr(sensor_cli, "_cmd_sensor_list", ctrl_c)
    assert main(["sensor", "list"]) == 130
    assert capsys.readouterr().err == "nlosplan: interrupted\n"
    monkeypatch.setattr(sensor_cli, "_cmd_sensor_list", sigterm)
    before = signal.getsignal(signal.SIGTERM)
    assert main(["sensor", "list"]) == 143
    assert capsys.readouterr().err == "nlosplan: terminated (SIGTERM)\n"
    assert signal.getsignal(signal.SIGTERM) is before   # the handler is the block's only


def _run(rig, store, on_capture=None):
    return Executor(rig, store, run_id="run", context=CTX, on_capture=on_capture)


def test_sigterm_finalizes_a_rig_run_like_ctrl_c(tmp_path):
    """SIGTERM mid-run: the capture in hand is stored, the sensor stopped, the gantry parked, then Terminated."""
    def term(result):
        os.kill(os.getpid(), signal.SIGTERM)

    with emulated_rig(time_scale=50) as rig, CaptureStore(tmp_path / "r.db") as store:
        ex = _run(rig, store, term)
        with sigterm_interrupts(), pytest.raises(Terminated):
            ex.run(raster_plan(repeats=2, settle_s=0.0, positions=range(4)))
        assert ex.summary.finalize == ["sensor stopped", "gantry parked at (0, 0) mm"]
        assert ex.summary.captured == 1 and store.count() == 1
        assert not rig.sensor.measuring


@pytest.fixture
def ctrl_c():
    """Ctrl-C raises KeyboardInterrupt in this process while the test runs (as at a terminal)."""
    old = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, old)


def test_repeated_ctrl_c_cannot_cut_finalize_short(tmp_path, monkeypatch, ctrl_c):
    """Ctrl-C ends the run; two more while the sensor is being stopped wait: the gantry still parks."""
    def pressed(result):
        raise KeyboardInterrupt

    with emulated_rig(time_scale=50) as rig, CaptureStore(tmp_path / "r.db") as store:
        stop = rig.sensor.stop

        def stop_pressed_twice():   # in finalize; not again when the rig closes
            monkeypatch.setattr(rig.sensor, "stop", stop)
            signal.raise_signal(signal.SIGINT)
            signal.raise_signal(signal.SIGINT)
            stop()

        monkeypatch.setattr(rig.sensor, "stop", stop_pressed_twice)
        ex = _run(rig, store, pressed)
        with pytest.raises(KeyboardInterrupt):
            ex.run(raster_plan(repeats=1, settle_s=0.0, positions=range(4)))
        assert ex.summary.finalize == ["sensor stopped", "gantry parked at (0, 0) mm"]
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_ctrl_c_during_finalize_of_a_finished_run_still_interrupts(tmp_path, monkeypatch, ctrl_c):
    with emulated_rig(time_scale=50) as rig, CaptureStore(tmp_path / "r.db") as store:
        stop = rig.sensor.stop

        def stop_pressed():
            monkeypatch.setattr(rig.sensor, "stop", stop)
            signal.raise_signal(signal.SIGINT)
            stop()

        monkeypatch.setattr(rig.sensor, "stop", stop_pressed)
        ex = _run(rig, store)
        with pytest.raises(KeyboardInterrupt):
            ex.run(raster_plan(repeats=1, settle_s=0.0, positions=[0]))
        assert ex.summary.completed and ex.summary.captured == 1
        assert ex.summary.finalize == ["sensor stopped", "gantry parked at (0, 0) mm"]


@pytest.mark.slow
def test_sigterm_ends_rig_capture_with_143_and_one_line(tmp_path):
    """Through the command line: SIGTERM after the first capture; the last line says what finalize did."""
    store = tmp_path / "s.db"
    p = subprocess.Popen([sys.executable, "-m", "nlosplan", "rig", "capture", "--emulate", "--positions", "0-9",
                          "--repeats", "2", "--settle", "0.3", "--store", str(store)], env=ENV,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 240
        while time.monotonic() < deadline and p.poll() is None:
            time.sleep(0.3)
            try:
                with CaptureStore(store, readonly=True) as st:
                    if st.count() >= 1:
                        break
            except UserError:
                pass
        p.send_signal(signal.SIGTERM)
        _, err = p.communicate(timeout=120)
    finally:
        p.kill()
    assert p.returncode == 143, err
    last = err.strip().splitlines()[-1]
    assert last.startswith("nlosplan: terminated (SIGTERM): run raster-A-8in-off-3x3-"), last
    assert "finalize: sensor stopped; gantry parked at (0, 0) mm; rerun the same command to resume" in last


def test_an_interrupt_while_python_shuts_down_exits_130_not_0():
    """Ctrl-C after the work, during the interpreter's exit (an atexit hook here): 130, never 0."""
    code = ("import atexit, os, signal, time\n"
            "signal.signal(signal.SIGINT, signal.default_int_handler)\n"   # as at a terminal (a runner may ignore it)
            "from nlosplan.cli import main\n"
            "atexit.register(lambda: (os.kill(os.getpid(), signal.SIGINT), time.sleep(5)))\n"
            "raise SystemExit(main())\n")
    r = subprocess.run([sys.executable, "-c", code, "sensor", "list"], env=ENV, capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 130, r.stderr
    assert "tmf8828-3x3-short" in r.stdout   # the output was written first
    assert "Traceback" not in r.stderr


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="needs /dev/full")
def test_standard_output_on_a_full_device_is_one_line():
    with open("/dev/full", "w") as full:
        r = subprocess.run([sys.executable, "-m", "nlosplan", "sensor", "list"], env=ENV, stdout=full,
                           stderr=subprocess.PIPE, text=True, timeout=120)
    assert r.returncode == 2
    assert r.stderr == ("nlosplan: error: cannot write to standard output (No space left on device); files the "
                        "command wrote are kept\n")


# ----------------------------------------------------------------------------- locked stores
def test_a_store_another_process_holds_is_refused_before_any_work(fx, tmp_path, capsys):
    path = tmp_path / "s.sqlite"
    path.write_bytes((fx / "store.sqlite").read_bytes())
    holder = sqlite3.connect(path, isolation_level=None)
    holder.execute("BEGIN IMMEDIATE")
    before = digest(path)
    try:
        for argv in (BUILD, ["rig", "capture", "--emulate", "--positions", "0", "--repeats", "1"]):
            t0 = time.monotonic()
            code = main(argv + ["--store", str(path)])
            check_one_line(code, capsys.readouterr().err, f"capture store {path} is locked by another process (it "
                                                          f"holds a write transaction and did not let go within "
                                                          f"{LOCK_WAIT_S:g} s)")
            assert time.monotonic() - t0 < 60   # not the 30 s wait of every write, then a traceback
    finally:
        holder.execute("ROLLBACK")
        holder.close()
    assert digest(path) == before


HOLD = ("import sys, time\n"
        "from nlosplan.data.store import CaptureStore\n"
        "with CaptureStore(sys.argv[1]) as st, st.writer(sys.argv[2]):\n"
        "    print('held', flush=True)\n"
        "    time.sleep(300)\n")


def test_one_dataset_build_of_the_same_captures_at_a_time(tmp_path, capsys, monkeypatch):
    """A second identical build stops at once, naming the first; a build killed with -9 does not hold the store."""
    path = tmp_path / "s.sqlite"

    def tell(self, what):
        raise UserError(what)

    monkeypatch.setattr(CaptureStore, "writer", tell)   # which lease the build takes
    assert main(BUILD + ["--store", str(path)]) == 2
    what = capsys.readouterr().err.strip().removeprefix("nlosplan: error: ")
    assert what.startswith("dataset build #")
    monkeypatch.undo()
    holder = subprocess.Popen([sys.executable, "-c", HOLD, str(path), what], env=ENV, stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        t0 = time.monotonic()
        code = main(BUILD + ["--store", str(path)])
        line = check_one_line(code, capsys.readouterr().err, f"capture store {path}: another dataset build (process "
                                                             f"{holder.pid}, since ")
        assert "is writing the same captures into it; wait for it to end, then rerun" in line
        assert time.monotonic() - t0 < 60
    finally:
        holder.kill()
        holder.wait()
    with CaptureStore(path) as st:
        assert st.count() == 0
        with st.writer(what):   # the killed holder's row no longer counts
            pass


# ----------------------------------------------------------------------------- what is read is checked
def test_a_damaged_capture_is_one_line_naming_it_wherever_it_is_read(fx):
    with CaptureStore(fx / "negcount.sqlite", readonly=True) as st:
        for read in (st.load, lambda: list(st.iter_captures())):
            with pytest.raises(UserError, match=r"capture 3 \(A\|8in\|1\|off\|3x3\|0\|sim:fast\|.*\) of capture store "
                                                r".*negcount.sqlite is damaged: a count of -9187201950435737472 is "
                                                r"negative"):
                read()
        assert len(st.load(id=[1, 2, 4]).labels) == 3   # the other captures read as before


@pytest.mark.parametrize("dtype, shape, data, words", [
    ("<f8", "[3, 3, 128]", bytes(9216), "dtype '<f8' is not one of <i8, <f4"),
    ("<i8", "[3, 3]", bytes(9216), "shape '[3, 3]' is not [rows, cols, bins]"),
    ("<i8", "not json", bytes(9216), "shape 'not json' is not [rows, cols, bins]"),
    ("<i8", "[3, 3, 128]", bytes(9208), "holds 9208 bytes, 9216 expected for shape [3, 3, 128] of <i8"),
    ("<i8", "[3, 3, 128]", "text", "its histogram is a str, not bytes"),
    ("<f4", "[1, 1, 2]", np.array([1.0, np.nan], "<f4").tobytes(), "holds NaN or infinite values"),
    ("<i8", "[1, 1, 2]", np.array([0, 2**24], "<i8").tobytes(), "a count of 16777216 is above 16777215, the 24-bit"),
    ("<i8", "[1, 1, 2]", np.array([-1, 0], "<i8").tobytes(), "a count of -1 is negative"),
])
def test_decode_histogram_refuses_what_no_sensor_gives(dtype, shape, data, words):
    with pytest.raises(UserError, match=f"^capture 7 is damaged: its histogram .*|^capture 7 is damaged: a count"):
        decode_histogram(dtype, shape, data, what="capture 7")
    with pytest.raises(UserError) as err:
        decode_histogram(dtype, shape, data, what=lambda: "capture 7")
    assert words in str(err.value) and "\n" not in str(err.value)


def test_counts_above_24_bits_are_kept_for_a_sensor_that_does_not_saturate(tmp_path):
    free = SensorConfig(name="no-saturation", saturation=False)
    big = np.full((3, 3, 128), 2**30, np.int64)
    with CaptureStore(tmp_path / "s.sqlite") as st:
        st.put(big, dict(object="A", size="8in", position=0, lights="off", repeat=0, source="sim:fast"), sensor=free)
        assert float(st.load().histograms.max()) == 2.0**30
    assert decode_histogram("<i8", "[3, 3, 128]", big.tobytes(), what="c", max_count=None).max() == 2**30


def test_a_corrupt_page_is_found_by_the_quick_check_and_a_sound_store_passes(fx):
    with pytest.raises(UserError, match=r"corrupt.sqlite is damaged \(SQLite's quick check: .*\); nothing was read "
                                        r"from it: recover what it holds with 'sqlite3 .*corrupt.sqlite \.recover'"):
        CaptureStore(fx / "corrupt.sqlite", readonly=True, check=True)
    with CaptureStore(fx / "store.sqlite", readonly=True, check=True) as st:
        assert st.count() == 16


def test_the_live_page_says_a_damaged_capture_instead_of_failing(tmp_path):
    """The rig page reads the newest capture of the run: a damaged one is its error line, not a 500 per load."""
    from nlosplan.reports.live.rig_watch import RigWatch

    path = tmp_path / "s.sqlite"
    with CaptureStore(path) as st:
        for step in range(2):
            st.put(np.full((3, 3, 128), 7), dict(object="A", size="8in", position=step, lights="off", repeat=0,
                                                 source="emulated:rig", capture_id=f"r/{step:06d}"),
                   sensor=SensorConfig(name="s"), meta={"run_id": "r", "step": step})
    db = sqlite3.connect(path)
    db.execute("UPDATE captures SET data = substr(data, 1, 100) WHERE id = 2")
    db.commit()
    db.close()
    watch = RigWatch(path, min_interval_s=0)
    try:
        assert watch.refresh(force=True)
        assert watch.last_hist is None and len(watch.runs["r"]) == 2
        assert watch.error.startswith("capture 2 is damaged: its histogram holds 100 bytes, 9216 expected")
    finally:
        watch.close()
