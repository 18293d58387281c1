"""The pty emulators speak the protocols: GRBL motion timing, alarms, hold; TMF8828 modes; lights."""

import math
import time

import numpy as np
import pytest

from nlosplan.errors import UserError
from nlosplan.hardware.emulators import EmulatedGrbl, EmulatedTMF8828
from nlosplan.hardware.emulators.grbl import _profile
from nlosplan.hardware.grbl import Grbl, GrblAlarm
from nlosplan.hardware.lights import EmulatedLights, FixedLights, ManualLights
from nlosplan.hardware.tmf8828 import TMF8828


def test_trapezoid_profile():
    total, t_acc, vpk = _profile(100.0, 50.0, 500.0)         # reaches 50 mm/s after 0.1 s
    assert (t_acc, vpk) == (0.1, 50.0) and total == pytest.approx(0.2 + (100 - 5) / 50)
    total, t_acc, vpk = _profile(1.0, 50.0, 500.0)           # too short: a triangle
    assert total == pytest.approx(2 * math.sqrt(1 / 500)) and vpk < 50


def test_emulated_grbl_motion_time_limits_and_hold():
    with EmulatedGrbl(time_scale=10.0, settings={110: 3000, 111: 3000, 120: 500, 121: 500}) as emu:
        g = Grbl(emu.port, poll_s=0.005)
        g.connect()
        t0 = time.monotonic()
        st = g.move_to(100.0, 0.0, feed_mm_min=3000)
        took = (time.monotonic() - t0) * 10.0                  # in emulated seconds
        expect = _profile(100.0, 50.0, 500.0)[0]
        assert st.mpos == (100.0, 0.0, 0.0) and expect * 0.95 < took < expect + 2.0   # + polling under load
        g.move_to(300.0, 0.0, feed_mm_min=3000, wait=False)
        time.sleep(0.05)                                       # 0.5 emulated s into a 4.1 s move
        g.feed_hold()
        time.sleep(0.02)
        held = g.status()
        time.sleep(0.05)
        assert held.state == "Hold" and g.status().mpos == held.mpos and 100 < held.mpos[0] < 300
        g.resume()
        assert g.wait_idle(timeout=5).mpos[0] == 300.0
        g.limits_mm = ((0, 1000), (0, 1000))                  # the driver's check off: GRBL's soft limit trips
        with pytest.raises(GrblAlarm, match="ALARM:2"):
            g.move_to(500.0, 0.0)
        g.unlock()
        assert g.status().state == "Idle"
        g.close()


def test_emulated_grbl_homing_lock():
    with EmulatedGrbl(time_scale=50.0, settings={22: 1}) as emu:
        g = Grbl(emu.port)
        g.connect()
        assert g.alarm == -1 and g.status().state == "Alarm"
        assert g.home().mpos == (0.0, 0.0, 0.0) and g.alarm is None
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
