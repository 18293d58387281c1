"""The GRBL driver against the real GRBL 1.1h firmware (grbl-sim) and the project's emulator: same scenarios.

``grbl_device`` runs each scenario twice: on the real firmware (marked ``real_firmware``; built from
``../shared/vendor`` by the session fixture) and on :func:`grbl_firmware.mirror_grbl` (the emulator set up as
grbl-sim runs: no reset when the port opens, every input pin reads active). Both must pass the same assertions;
``test_emulator_and_firmware_answer_alike`` also compares their raw answers line by line. grbl-sim runs about 3x
slower than the planned motion: moves are short and fast.
"""

import re
import time

import pytest

from nlosplan.errors import UserError
from nlosplan.hardware.grbl import Grbl, GrblAlarm, GrblError
from nlosplan.hardware.transport import DeviceTimeout

FAST = {110: 20000, 111: 20000, 120: 2000, 121: 2000}
SOFT = {22: 1, 20: 1, 130: 320, 131: 320}


def _open(dev, **kw) -> Grbl:
    return Grbl(dev.port, poll_s=0.01, **kw)


def _configure(dev, settings: dict, *, power_cycle: bool) -> None:
    g = _open(dev, limits_mm=((-1000, 1000), (-1000, 1000)), work_offset="keep")
    g.connect()
    for k, v in settings.items():   # $22 before $20: soft limits need homing enabled (error:10)
        g.set_setting(k, v)
    g.close()
    if power_cycle:
        dev.power_cycle()


def _moving(g: Grbl) -> None:
    """Wait until the move is under way (grbl-sim's pace depends on the machine's load)."""
    deadline = time.monotonic() + 10
    while not ((st := g.status()).state == "Run" and st.mpos[0] > 5.0):
        assert st.state in ("Idle", "Run") and time.monotonic() < deadline, st.raw
        time.sleep(0.01)


def test_default_settings_errors_settings_rules_and_line_ends(grbl_device):
    g = _open(grbl_device)
    g.prepare()
    # grbl-sim does not reset when the port opens (nor does the mirror): it answers a status report, no banner
    assert (g.connected_by, g.banner, g.build.version, g.build.options) == ("status", None, "1.1h", "V")
    assert (g.settings[20], g.settings[22], g.settings[100], g.settings[110], g.settings[130]) == (0, 0, 250, 500, 200)
    assert g.frame.offset_mm == (0.0, 0.0) and g.frame.space_mm is None and g.frame.step_mm == (0.004, 0.004)
    with pytest.raises(GrblError, match="error:22"):
        g.send("G1 X1")                      # no feed rate yet
    with pytest.raises(GrblError, match="error:20"):
        g.send("G5 X1")
    codes = []
    for number, value in ((20, 1), (0, 2), (100, -1), (999, 1)):
        with pytest.raises(GrblError) as err:
            g.set_setting(number, value)
        codes.append(err.value.code)
    assert codes == [10, 6, 4, 3]            # soft limits without homing; step pulse < 3 us; negative; unknown
    assert g.exchange(b"\r\n") == ["ok", "ok"] and g.exchange(b"\n") == ["ok"]   # every line end is answered
    for k, v in FAST.items():
        g.set_setting(k, v)
    pos = g.move_to(2.0, 3.0, feed_mm_min=20000)
    assert pos.xy_mm == (2.0, 3.0) and pos.raw["mpos_mm"] == [2.0, 3.0, 0.0] and pos.state == "Idle"
    g.close()


def test_power_up_lock_soft_limits_and_the_work_offset(grbl_device):
    _configure(grbl_device, {**SOFT, **FAST}, power_cycle=True)
    g = _open(grbl_device)
    with pytest.raises(UserError, match="locked in alarm .*pass --home"):
        g.prepare()
    g.close()
    g = _open(grbl_device)
    g.prepare(unlock=True)   # grbl-sim cannot home (every limit pin reads active): $X after the power-up lock
    assert g.frame.offset_mm == (-320.0, -320.0) and g.frame.space_mm == ((-320.0, 0.0), (-320.0, 0.0))
    assert g.where().xy_mm == (320.0, 320.0)          # machine (0, 0) is the user frame's far corner
    pos = g.move_to(300.0, 310.0, feed_mm_min=20000)
    assert pos.xy_mm == (300.0, 310.0) and pos.raw["mpos_mm"][:2] == [-20.0, -10.0]
    g.close()
    g = _open(grbl_device, limits_mm=((0.0, 330.0), (0.0, 320.0)))
    with pytest.raises(UserError, match=r"x 0..330 mm map to machine x -320..10 mm .*outside GRBL's machine space"):
        g.prepare()
    g.close()


def test_soft_limit_alarm_halts_everything_until_a_soft_reset(grbl_device):
    _configure(grbl_device, {**SOFT, **FAST}, power_cycle=False)
    g = _open(grbl_device, limits_mm=((-320.0, 0.0), (-320.0, 0.0)), work_offset="keep")
    g.prepare()
    with pytest.raises(GrblAlarm, match=r"ALARM:2 \(soft limit.*until a soft reset"):
        g.send("G90 G0 X10")                 # outside [-320, 0]: GRBL refuses it by ALARM:2
    assert g.alarm == 2 and g.blocked() == "in alarm (ALARM:2)"
    with pytest.raises(DeviceTimeout, match="answers nothing after ALARM:1/2"):
        g.status(timeout=1.0)                # not even status reports...
    with pytest.raises(DeviceTimeout, match="no 'ok'"):
        g.send("$X", timeout=1.0)            # ...nor $X
    st = g.recover(unlock=True)              # soft reset, then $X
    assert st.state == "Idle" and st.mpos == (0.0, 0.0, 0.0) and g.alarm is None and g.banner.startswith("Grbl 1.1h")
    g.close()


def _moving_to_150(grbl_device):
    """A prepared gantry at fast settings, moving from 0 to x = 150 mm."""
    g = _open(grbl_device)
    g.prepare()
    for k, v in FAST.items():
        g.set_setting(k, v)
    g.move_to(150.0, 0.0, feed_mm_min=20000, wait=False)
    _moving(g)
    return g


def test_feed_hold_and_resume(grbl_device):
    g = _moving_to_150(grbl_device)
    g.feed_hold()
    deadline = time.monotonic() + 5
    while (st := g.status()).substate != "0":   # GRBL may answer a '?' sent right after '!' before holding
        assert st.state in ("Run", "Hold") and time.monotonic() < deadline
        time.sleep(0.02)
    time.sleep(0.3)
    assert g.status().mpos == st.mpos and 0 < st.mpos[0] < 150   # held, mid-move
    g.resume()
    assert g.wait_idle(timeout=20).mpos == (150.0, 0.0, 0.0)
    g.close()


def test_reset_in_motion_gives_alarm_3_and_a_lock(grbl_device):
    g = _moving_to_150(grbl_device)
    assert g.soft_reset().startswith("Grbl 1.1h")
    st = g.status()
    assert g.alarm == 3 and st.state == "Alarm" and 0 < st.mpos[0] < 150
    with pytest.raises(GrblError, match="error:9"):
        g.send("G0 X1")                      # g-code locked out in alarm
    assert g.recover(unlock=True).state == "Idle" and g.status().mpos == st.mpos   # position kept
    g.close()


def test_failed_homing_says_why(grbl_device):
    _configure(grbl_device, {22: 1, 130: 320, 131: 320}, power_cycle=False)
    g = _open(grbl_device)
    g.prepare()
    with pytest.raises(GrblAlarm, match=r"ALARM:8 .*limit pin\(s\) X, Y, Z read triggered before homing started "
                                        r"\(Pn:PXYZRHS\).*stopped after Z moved, before X or Y moved: stock GRBL homes "
                                        r"Z first"):
        g.home()
    st = g.status()
    assert st.state == "Alarm" and st.mpos == (0.0, 0.0, -1.0)   # Z pulled off 1 mm ($27), X and Y never moved
    g.close()


CONVERSATION = [b"?", b"\r\n", b"$I\n", b"$20=1\n", b"$22=1\n", b"$20=1\n", b"$0=2\n", b"$130=320\n", b"$131=320\n",
                b"$110=20000\n", b"$111=20000\n", b"$120=2000\n", b"$121=2000\n", b"G10 L2 P1 X-320 Y-320\n", b"?",
                b"G0 X310 Y310\n", "idle", b"G0 X330\n", b"?", b"$X\n", b"\x18", b"?", b"$X\n", b"$#\n", b"G5\n",
                b"$H\n", b"?", b"\x18", b"?", b"$G\n"]
UNTIL = {b"$H\n": "[MSG:'$H'|'$X' to unlock]", b"\x18": "[MSG:'$H'|'$X' to unlock]"}


def _converse(link, step) -> list[str]:
    """Send one step and read its answer: until a marker line (GRBL resetting itself takes a while in grbl-sim
    under load), until quiet, or ("idle") poll status reports until Idle and keep none of them."""
    if step == "idle":
        deadline = time.monotonic() + 30
        while not any(ln.startswith("<Idle") for ln in link.exchange(b"?", quiet_s=0.1, timeout=1.0)):
            assert time.monotonic() < deadline, "no Idle within 30 s"
        return []
    marker = UNTIL.get(step)
    if marker is None:
        return link.exchange(step, quiet_s=0.25, timeout=1.5)
    lines = link.exchange(step, quiet_s=0.3, timeout=2.0)
    deadline = time.monotonic() + 15
    while marker not in lines:
        assert time.monotonic() < deadline, f"no {marker!r} after {step!r}: {lines}"
        lines += link.exchange(b"", quiet_s=0.3, timeout=1.0)
    return lines


def _normalised(lines):
    """Status reports in motion carry timing-dependent numbers; everything else must match exactly."""
    return [re.sub(r"MPos:[-0-9.,]+\|FS:\d+", "MPos:#|FS:#", ln) if ln.startswith(("<Run", "<Hold")) else ln
            for ln in lines]


@pytest.mark.real_firmware
def test_emulator_and_firmware_answer_alike(grbl_sim_exe, tmp_path):
    from grbl_firmware import GrblFirmware, mirror_grbl

    answers = {}
    for name, dev in (("real", GrblFirmware(grbl_sim_exe, tmp_path / "eeprom")), ("emulated", mirror_grbl())):
        with dev:
            link = _open(dev)
            lines = []
            for step in CONVERSATION:
                lines += _converse(link, step)
            link.close()
            answers[name] = _normalised(lines)
    for i, (a, b) in enumerate(zip(answers["real"], answers["emulated"])):
        assert a == b, f"line {i}: real {a!r}, emulated {b!r}; real {answers['real']}, emulated {answers['emulated']}"
    assert len(answers["real"]) == len(answers["emulated"])
    assert "ALARM:2" in answers["real"] and "ALARM:8" in answers["real"] and answers["real"].count("error:10") == 1


@pytest.mark.parametrize("setup", ["defaults", "soft-limits"])
def test_rig_capture_on_the_gantry_stores_commanded_and_reported_in_one_frame(grbl_device, tmp_path, capsys, setup):
    """``rig capture`` with the real gantry (firmware or mirror) and an emulated sensor; with soft limits on,
    the gantry powers up locked (--unlock) and the user frame sits at G54 = (-320, -320) in the negative space."""
    import json

    from nlosplan.cli import main
    from nlosplan.data.store import CaptureStore

    soft = setup == "soft-limits"
    _configure(grbl_device, {**SOFT, **FAST} if soft else FAST, power_cycle=soft)
    store = tmp_path / "cap.db"
    argv = ["rig", "capture", "--emulate", "lidar", "--gantry", grbl_device.port, "--positions", "90,91",
            "--repeats", "1", "--settle", "0", "--feed", "20000", "--store", str(store), "--json"]
    code = main(argv + (["--unlock"] if soft else []))
    out, err = capsys.readouterr()
    assert code == 0, err
    data = json.loads(out)
    assert (data["captured"], data["moves"], data["finalize"]) == (2, 2, ["sensor stopped", "gantry parked at (0, 0) mm"])
    wco = [-320.0, -320.0] if soft else [0.0, 0.0]
    with CaptureStore(store, create=False) as st:
        caps = list(st.iter_captures())
    # DENALI's order: 90 and 91 share the last x column, y runs back down it
    assert [c.meta["commanded_mm"] for c in caps] == [[320.0, 320.0], [320.0, pytest.approx(284.444, abs=1e-3)]]
    for c in caps:
        m = c.meta
        step = m["gantry"]["step_mm"][0]
        assert step == 0.004 and m["gantry"]["work_offset_mm"] == wco and m["gantry"]["soft_limits"] is soft
        assert m["reported_mm"] == pytest.approx(m["commanded_mm"], abs=step)           # same (user) frame
        assert m["gantry_raw"]["mpos_mm"][:2] == pytest.approx([r + o for r, o in zip(m["reported_mm"], wco)])
        assert m["gantry"]["version"] == "1.1h" and m["emulated"] == ["lidar"] and m["gantry_state"] == "Idle"
    g = _open(grbl_device, work_offset="keep")
    g.prepare()
    assert g.where().raw["mpos_mm"][:2] == wco      # parked at user (0, 0)
    g.close()
