"""Injected faults: every completed capture ends up stored exactly once."""

import pytest

from nlosplan.hardware.emulators import GantryFaults, SensorFaults
from nlosplan.hardware.executor import Executor, RunContext
from nlosplan.hardware.grbl import GrblAlarm
from nlosplan.hardware.plans import raster_plan
from nlosplan.hardware.rig import emulated_rig
from nlosplan.hardware.transport import DeviceTimeout
from nlosplan.data.store import CaptureStore

CTX = RunContext("A", "8in", source="emulated:rig", plan="faults")


def _plan():
    return raster_plan(repeats=2, settle_s=0.0, positions=range(4))


def _check_once(store, n):
    lab = store.labels()
    assert len(lab) == n and lab["capture_id"].is_unique
    assert sorted(lab["capture_id"]) == [f"run/{s:06d}" for s in range(n)]
    assert store.integrity_check() == "ok"


@pytest.mark.parametrize("faults, counter", [
    (SensorFaults(garble_every=37), "garbage_lines"),
    (SensorFaults(truncate_every=41), "garbage_lines"),
    (SensorFaults(drop_every=53), "dropped_frames"),
])
def test_garbled_truncated_and_dropped_lines(tmp_path, faults, counter):
    with emulated_rig(time_scale=50, sensor_faults=faults) as rig, CaptureStore(tmp_path / "r.db") as store:
        s = Executor(rig, store, run_id="run", context=CTX).run(_plan())
        assert s.captured == 8 and s.sensor_stats[counter] > 0 and s.sensor_stats["dropped_frames"] > 0
        _check_once(store, 8)
        # no stored histogram is a damaged frame: every zone has the simulator's first-bounce peak
        for cap in store.iter_captures():
            assert (cap.histogram.max(axis=-1) > 100).all()


def test_disconnect_and_reconnect(tmp_path):
    faults = SensorFaults(disconnect_after_frames=5, down_s=0.3)
    with emulated_rig(time_scale=50, sensor_faults=faults) as rig, CaptureStore(tmp_path / "r.db") as store:
        s = Executor(rig, store, run_id="run", context=CTX).run(_plan())
        assert s.captured == 8 and s.reconnects == 1 and s.retries == 1 and rig.sensor.reconnects == 1
        _check_once(store, 8)


def test_slow_answers(tmp_path):
    with emulated_rig(time_scale=50, sensor_faults=SensorFaults(slow_answer_s=0.1),
                      gantry_faults=GantryFaults(slow_ok_s=0.1, garble_status_every=7)) as rig, \
            CaptureStore(tmp_path / "r.db") as store:
        s = Executor(rig, store, run_id="run", context=CTX).run(_plan())
        assert s.captured == 8
        _check_once(store, 8)


def test_gantry_alarm_mid_move_then_resume_after_unlock(tmp_path):
    with emulated_rig(time_scale=50, gantry_faults=GantryFaults(alarm_on_move=3)) as rig, \
            CaptureStore(tmp_path / "r.db") as store:
        ex = Executor(rig, store, run_id="run", context=CTX)
        with pytest.raises(GrblAlarm, match=r"moving to \(0.000, 71.111\) mm: ALARM:1 \(hard limit"):
            ex.run(_plan())
        assert ex.summary.captured == 4
        assert ex.summary.finalize[-1] == "gantry in alarm (ALARM:1): not parked, last reported at (0.000, 35.556) mm"
        _check_once(store, 4)
        # GRBL after ALARM:1 answers nothing, status requests and $X included, until a soft reset
        with pytest.raises(DeviceTimeout, match="answers nothing after ALARM:1/2 until a soft reset"):
            rig.gantry.status(timeout=0.5)
        with pytest.raises(DeviceTimeout, match="no 'ok' for '\\$X'"):
            rig.gantry.send("$X", timeout=0.5)
        rig.gantry.recover(unlock=True)   # the user's decision (--unlock), never the driver's own: reset, then $X
        assert rig.gantry.blocked() is None and rig.gantry.status().state == "Idle"
        s = Executor(rig, store, run_id="run", context=CTX).run(_plan())
        assert (s.resumed, s.captured) == (4, 4)
        _check_once(store, 8)
