"""The executor on the pty emulators: raster captures, metadata, resume, dry run, finalize, pause."""

import threading

import numpy as np
import pytest

from nlosplan.errors import UserError
from nlosplan.hardware.commands import Capture, Checkpoint, Move, SetLights
from nlosplan.hardware.executor import Executor, RunContext, dry_run
from nlosplan.denali.geometry import grid_mm, label_xy, object_pose_mm
from nlosplan.hardware.plans import ask_tell_plan, finalize_wrapper, positions_plan, raster_plan, read_positions
from nlosplan.hardware.rig import emulated_rig
from nlosplan.denali import object_pose, positions_xy
from nlosplan.data.store import CaptureStore

CTX = RunContext("A", "8in", source="emulated:rig", plan="test")


def test_ten_position_raster_with_three_repeats_lands_thirty_captures(tmp_path):
    with emulated_rig(time_scale=50) as rig, CaptureStore(tmp_path / "r.db") as store:
        summary = Executor(rig, store, run_id="r1", context=CTX).run(
            raster_plan(repeats=3, settle_s=0.0, positions=range(10)))
        assert (summary.captured, summary.resumed, summary.moves, summary.completed) == (30, 0, 10, True)
        # no frame waited for in vain: the emulated sensor never stalls to recompile at a new position
        assert (summary.retries, summary.reconnects) == (0, 0)
        assert summary.finalize == ["sensor stopped", "gantry parked at (0, 0) mm"]
        lab = store.labels()
        assert len(lab) == 30 and lab["capture_id"].is_unique
        assert lab["position"].tolist() == [p for p in range(10) for _ in range(3)]
        assert lab["repeat"].tolist() == [0, 1, 2] * 10
        np.testing.assert_allclose(lab[["x", "y"]].to_numpy()[::3], positions_xy()[:10])
        caps = list(store.iter_captures())
        for c in caps:
            m = c.meta
            assert m["run_id"] == "r1" and m["commanded_mm"] == pytest.approx(list(grid_mm(c.labels["position"])))
            # reported in the same (user) frame as commanded, on GRBL's step grid (250 steps/mm: 0.004 mm)
            step = m["gantry"]["step_mm"][0]
            assert step == pytest.approx(0.004) and m["reported_mm"] == pytest.approx(m["commanded_mm"], abs=step)
            assert m["gantry_raw"]["mpos_mm"][:2] == pytest.approx(m["reported_mm"], abs=1e-9)   # work offset 0
            # DENALI's sequence; a toggle may be pressed again after a reconnect to a firmware that kept its state
            assert "".join(dict.fromkeys(m["sensor"]["sequence"])) == "hdoEOzm" and m["sensor"]["zones"] == "3x3"
            assert m["gantry"]["banner"].startswith("Grbl 1.1h") and m["lights"] == "off"
            assert m["t_capture_start_utc"] <= m["t_capture_end_utc"]
            assert c.histogram.shape == (3, 3, 128) and c.histogram.dtype == np.int64
        # rerun: everything comes from the store, nothing moves or is stored twice
        again = Executor(rig, store, run_id="r1", context=CTX).run(
            raster_plan(repeats=3, settle_s=0.0, positions=range(10)))
        assert (again.captured, again.resumed, again.moves, store.count()) == (0, 30, 0, 30)


def test_emulated_histograms_follow_the_gantry_to_any_position(tmp_path):
    """Off-grid positions work; the stored counts are Poisson draws of the simulator at that position."""
    from nlosplan.simulators.presets.denali import scene_at
    from nlosplan.sensor_models import preset
    from nlosplan.simulators import expected_histogram
    from nlosplan.simulators.presets.scene_model import scene_model, scene_options

    points = [(17.5, 203.25), (250.0, 40.0)]
    with emulated_rig(time_scale=50) as rig, CaptureStore(tmp_path / "r.db") as store:
        Executor(rig, store, run_id="off", context=CTX).run(positions_plan(points, repeats=8, settle_s=0.0))
        sensor = preset("denali-tmf8828-3x3")  # the emulator's model: DENALI's unit and its fitted scene
        opts = scene_options(scene_model(sensor))
        assert opts["mount"] and not opts["mount_in_background"]
        for k, (x, y) in enumerate(points):
            ds = store.load(position=-1, capture_id=[f"off/{k * 8 + r:06d}" for r in range(8)])
            mean = expected_histogram(scene_at("A", "8in", x, y, **opts), sensor, fidelity="draft")
            got = ds.histograms.mean(axis=0)
            # late bins hold the object's three-bounce light: compare where the expectation has counts
            z = (mean.sum(axis=(0, 1)) / mean.sum()).argmax()
            assert got[..., z].sum() == pytest.approx(mean[..., z].sum(), rel=0.02)
            assert ds.labels["x"].iloc[0] == pytest.approx(label_xy(x, y)[0])
    # the pose between grid points is continuous and exact at them
    np.testing.assert_allclose(object_pose_mm(*grid_mm(37)), object_pose(37), atol=1e-12)


def test_dry_run_lists_moves_and_finds_problems():
    rep = dry_run(raster_plan(repeats=3, settle_s=0.5), feed_mm_min=3000, accel_mm_s2=500)
    assert len(rep.moves) == 100 and rep.captures == 300 and not rep.problems
    assert rep.travel_mm == pytest.approx(99 * 320 / 9)   # a snake raster steps one pitch at a time
    rep = dry_run(positions_plan([(10, 10), (400, 10)], repeats=1), view=lambda x, y: "in view" if x == 10 else None)
    assert rep.problems == ["move 1: in view", "move 2 to (400.0, 10.0) mm is outside the limits x 0..320, "
                                                "y 0..320 mm"]


def test_finalize_runs_on_errors_and_plan_cleanup_runs_first(tmp_path):
    events = []

    def plan():
        yield Move(0.0, 0.0)
        yield Capture(repeat=0)
        yield Move(35.0, 0.0)
        raise RuntimeError("planner crashed")

    def cleanup():
        events.append("cleanup")
        yield Checkpoint()

    with emulated_rig(time_scale=50) as rig, CaptureStore(tmp_path / "r.db") as store:
        ex = Executor(rig, store, run_id="f", context=CTX)
        with pytest.raises(RuntimeError, match="planner crashed"):
            ex.run(finalize_wrapper(plan(), cleanup))
        assert events == ["cleanup"] and ex.summary.captured == 1
        assert ex.summary.finalize == ["sensor stopped", "gantry parked at (0, 0) mm"]
        assert not rig.sensor.measuring and rig.gantry.status().mpos[:2] == (0.0, 0.0)
        with pytest.raises(UserError, match="outside the limits"):
            Executor(rig, store, run_id="g", context=CTX).run(positions_plan([(500.0, 0.0)], repeats=1))
        with pytest.raises(UserError, match="before any Move"):
            Executor(rig, store, run_id="h", context=CTX).run(x for x in [Capture()])
        with pytest.raises(UserError, match="holds another capture under this id"):
            Executor(rig, store, run_id="f", context=CTX).run(positions_plan([(5.0, 5.0)], repeats=1))


def test_pause_at_checkpoint_and_lights_and_ask_tell(tmp_path):
    told = []
    queue = [[(0.0, 0.0), (35.0, 0.0)], [(70.0, 35.0)], []]

    def plan():
        yield SetLights(True)
        yield from ask_tell_plan(lambda n: queue.pop(0), told.extend, batch=2, repeats=2, settle_s=0.0)

    with emulated_rig(time_scale=50) as rig:
        gate = threading.Event()
        holder = {}

        def run():   # SQLite connections belong to their thread: the store is opened where it is used
            with CaptureStore(tmp_path / "r.db") as st:
                holder["ex"] = ex = Executor(rig, st, run_id="p", context=CTX, pause_when=lambda: not gate.is_set())
                ex.run(plan())

        t = threading.Thread(target=run)
        t.start()
        for _ in range(300):   # the first lights-on frame compiles the simulator's ambient term
            if holder.get("ex") and holder["ex"].summary.checkpoints:
                break
            t.join(timeout=0.1)
        ex = holder["ex"]
        t.join(timeout=0.5)
        assert t.is_alive() and ex.summary.captured == 2   # waiting at the first checkpoint
        gate.set()
        t.join(timeout=30)
        assert not t.is_alive() and ex.summary.captured == 6 and ex.summary.checkpoints == 3
        assert [p for p, _ in told] == [(0.0, 0.0), (35.0, 0.0), (70.0, 35.0)]
        assert all(len(rs) == 2 and rs[0].histogram.shape == (3, 3, 128) for _, rs in told)
        with CaptureStore(tmp_path / "r.db") as store:
            assert set(store.labels()["lights"]) == {"on"} and rig.lights.state is True


def test_read_positions_formats_and_errors(tmp_path):
    (tmp_path / "p.csv").write_text("x_mm,y_mm\n# a comment\n1.5,2\n3 4\n")
    assert read_positions(tmp_path / "p.csv") == [(1.5, 2.0), (3.0, 4.0)]
    (tmp_path / "p.json").write_text('[[1, 2], {"x_mm": 5, "y_mm": 6}]')
    assert read_positions(tmp_path / "p.json") == [(1.0, 2.0), (5.0, 6.0)]
    (tmp_path / "bad.csv").write_text("1,2\n3,x\n")
    with pytest.raises(UserError, match=r"bad.csv line 2: expected two numbers x_mm, y_mm"):
        read_positions(tmp_path / "bad.csv")
    with pytest.raises(UserError, match="does not exist"):
        read_positions(tmp_path / "none.csv")


def test_planner_sees_reported_positions_in_its_own_frame_under_a_work_offset(tmp_path):
    """Homing and soft limits on: GRBL's space is [-320, 0], G54 = (-320, -320). What the executor hands the
    ask/tell planner (and stores) is the user-frame position, not the machine position (-320 mm away)."""
    told = []
    queue = [[(17.5, 203.25), (250.0, 40.0)], []]
    settings = {22: 1, 20: 1}
    with emulated_rig(time_scale=50, gantry_settings=settings, unlock=True) as rig, \
            CaptureStore(tmp_path / "r.db") as store:
        assert rig.gantry.frame.offset_mm == (-320.0, -320.0) and rig.gantry.frame.soft_limits
        Executor(rig, store, run_id="wo", context=CTX).run(
            ask_tell_plan(lambda n: queue.pop(0), told.extend, batch=2, repeats=1, settle_s=0.0))
        for (x, y), results in told:
            assert results[0].reported_mm == pytest.approx((x, y), abs=0.004)
        for cap in store.iter_captures():
            mx, my, _ = cap.meta["gantry_raw"]["mpos_mm"]
            assert (mx, my) == pytest.approx((cap.meta["reported_mm"][0] - 320, cap.meta["reported_mm"][1] - 320))
