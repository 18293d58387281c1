"""The pty emulators speak the protocols: GRBL motion timing, alarms, hold; TMF8828 modes; lights."""

import math
import time

import numpy as np
import pytest

from nlosplan.errors import UserError
from nlosplan.hardware.emulators import EmulatedGrbl, EmulatedTMF8828
from nlosplan.hardware.emulators.motion import Segment, trapezoid
from nlosplan.hardware.grbl import Grbl, GrblAlarm
from nlosplan.hardware.lights import EmulatedLights, FixedLights, ManualLights
from nlosplan.hardware.tmf8828 import TMF8828


def test_trapezoid_profile_and_stop_by_deceleration():
    total, t_acc, vpk = trapezoid(100.0, 50.0, 500.0)         # reaches 50 mm/s after 0.1 s
    assert (t_acc, vpk) == (0.1, 50.0) and total == pytest.approx(0.2 + (100 - 5) / 50)
    total, t_acc, vpk = trapezoid(1.0, 50.0, 500.0)           # too short: a triangle
    assert total == pytest.approx(2 * math.sqrt(1 / 500)) and vpk < 50
    assert trapezoid(10.0, 5.0, 0.0) == (2.0, 0.0, 5.0)       # no acceleration limit: constant speed
    seg = Segment((0.0, 0.0), (100.0, 0.0), 0.0, 50.0, 500.0)
    stop = seg.stop(1.0)                                      # at 50 mm/s, 47.5 mm along: 2.5 mm to rest
    assert stop.start[0] == pytest.approx(47.5) and stop.target[0] == pytest.approx(50.0)
    assert stop.total == pytest.approx(0.1) and stop.position(1.05)[0] == pytest.approx(47.5 + 2.5 - 0.625)
    assert stop.speed(1.05) == pytest.approx(25.0) and stop.done(1.1) and not stop.done(1.09)


def test_emulated_grbl_motion_time_feed_hold_and_resume():
    settings = {110: 3000, 111: 3000, 120: 500, 121: 500, 130: 320, 131: 320}
    with EmulatedGrbl(time_scale=10.0, settings=settings) as emu:
        g = Grbl(emu.port, poll_s=0.005)
        g.prepare()
        t0 = time.monotonic()
        pos = g.move_to(100.0, 0.0, feed_mm_min=3000)
        took = (time.monotonic() - t0) * 10.0                  # in emulated seconds
        expect = trapezoid(100.0, 50.0, 500.0)[0]
        assert pos.xy_mm == (100.0, 0.0) and expect * 0.95 < took < expect + 2.0   # + polling under load
        g.move_to(300.0, 0.0, feed_mm_min=3000, wait=False)
        time.sleep(0.1)                                        # 1 emulated s into a 4.1 s move
        g.feed_hold()
        first = g.status()
        assert first.state == "Hold" and first.substate == "1"  # decelerating
        time.sleep(0.05)
        held = g.status()
        time.sleep(0.05)
        assert held.substate == "0" and g.status().mpos == held.mpos and 100 < held.mpos[0] < 300
        assert held.mpos[0] - first.mpos[0] < 50 ** 2 / (2 * 500) + 1e-3   # stopped within the braking distance
        g.resume()
        assert g.wait_idle(timeout=5).mpos[0] == 300.0
        g.close()


def test_emulated_grbl_homing_with_and_without_a_z_switch():
    with EmulatedGrbl(time_scale=50.0, settings={22: 1, 20: 1, 130: 320, 131: 320}) as emu:
        g = Grbl(emu.port)
        g.prepare(home=True)   # the power-up lock is cleared by homing: MPos = -pull-off on every axis
        assert g.status().mpos == (-1.0, -1.0, -1.0) and g.alarm is None
        assert g.where().xy_mm == (319.0, 319.0)   # G54 = (-320, -320)
        g.close()
    with EmulatedGrbl(time_scale=500.0, settings={22: 1}, switches="XY") as emu:
        g = Grbl(emu.port)
        with pytest.raises(GrblAlarm, match=r"ALARM:9 .*stopped after Z moved, before X or Y moved: stock GRBL homes "
                                            r"Z first"):
            g.prepare(home=True)
        assert g.status().state == "Alarm" and g.banner.startswith("Grbl 1.1h")   # it reset itself
        g.close()


@pytest.mark.parametrize("zones, shape", [("3x3", (3, 3, 128)), ("4x4", (4, 4, 128)), ("8x8", (8, 8, 128))])
def test_emulated_tmf8828_modes(zones, shape):
    means = {"3x3": 10.0, "4x4": 20.0, "8x8": 30.0}

    def expected(z, r):
        n = int(z[0])
        assert r == "long"
        return np.full((n, n, 128), means[z]), 260.0

    with EmulatedTMF8828(expected, frame_period_s=0.01, seed=3) as emu:
        lidar = TMF8828(emu.port, quiet_s=0.05)
        cfg = lidar.start(zones, "long")
        frame = lidar.read_frame(fresh=True)
        assert frame.counts.shape == shape and abs(frame.counts.mean() - means[zones]) < 1.0
        assert cfg["sequence"] == {"3x3": "hdoEzm", "4x4": "hdoEczm", "8x8": "hdezm"}[zones]
        lidar.close()


def test_lights():
    asked = []
    m = ManualLights(ask=asked.append)
    m.set(True)
    m.set(True)
    assert asked == ["Switch the room lights ON and press Enter: "] and m.state is True
    with pytest.raises(UserError, match="fixed off"):
        FixedLights(False).set(True)
    e = EmulatedLights()
    e.set(True)
    e.set(False)
    assert e.changes == 2 and e.state is False


def test_a_sensor_port_with_text_but_no_histograms_is_named():
    from rig_ports import ChattyPort

    from nlosplan.hardware.tmf8828 import SensorGarbage

    with ChattyPort() as port:
        lidar = TMF8828(port.port, quiet_s=0.05)
        lidar.garbage_s = 1.0
        lidar.start("3x3", "short")          # every command is answered (with text)
        t0 = time.monotonic()
        with pytest.raises(SensorGarbage, match=r"lines in 1.\d s, none of them histogram data \(e.g. "
                                                r"'temperature,21.5"):
            lidar.read_frame(timeout=10.0, fresh=True)
        assert time.monotonic() - t0 < 2.0
        lidar.close()
