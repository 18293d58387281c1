"""GRBL 1.1 driver against command/response transcripts (every pair consumed, exact bytes), and GRBL's rules.

The transcripts use GRBL 1.1h's own answers (as the real firmware, built with grbl-sim, gives them; see
``test_grbl_firmware.py`` for the same behaviour against the firmware itself).
"""

import pytest

from nlosplan.errors import UserError
from nlosplan.hardware.gantry import WrongFirmware
from nlosplan.hardware.grbl import Grbl, GrblAlarm, GrblError, LimitError
from nlosplan.hardware.grbl_frame import FrameChanged, parse_work_offset, plan_frame
from nlosplan.hardware.grbl_homing import homing_diagnosis
from nlosplan.hardware.grbl_protocol import (machine_space, parse_build_info, parse_ngc_parameters, parse_status,
                                             setting_error)
from nlosplan.hardware.transcript import TranscriptSerial

BANNER = b"\r\nGrbl 1.1h ['$' for help]\r\n"
IDLE = b"<Idle|MPos:0.000,0.000,0.000|FS:0,0|WCO:0.000,0.000,0.000>\r\n"
VERSION = (b"$I\n", b"[VER:1.1h.20190830:]\r\n[OPT:V,15,128]\r\nok\r\n")
SETTINGS = b"$20=0\r\n$22=0\r\n$23=0\r\n$100=250.000\r\n$101=250.000\r\n$130=320.000\r\n$131=320.000\r\nok\r\n"
HOMING_SETTINGS = SETTINGS.replace(b"$20=0", b"$20=1").replace(b"$22=0", b"$22=1")
PARAMS = (b"[G54:0.000,0.000,0.000]\r\n[G55:0.000,0.000,0.000]\r\n[G92:0.000,0.000,0.000]\r\n[TLO:0.000]\r\n"
          b"[PRB:0.000,0.000,0.000:0]\r\nok\r\n")


def _connected(pairs, greeting=BANNER, status=IDLE, **kw):
    """A driver connected through a transcript: the Telemetrix query (ignored by GRBL), a status, $I."""
    ser = TranscriptSerial([(b"\x01\x05", b""), (b"?", status), VERSION] + pairs, greeting=greeting)
    g = Grbl(ser, timeout=0.5, poll_s=0.0, **kw)
    return g, ser


def test_prepare_at_default_settings_then_move_in_the_user_frame():
    pairs = [(b"$$\n", SETTINGS), (b"$#\n", PARAMS), (b"G54\n", b"ok\r\n"), (b"?", IDLE),
             (b"G90 G21 G1 X35.556 Y0.000 F3000\n", b"ok\r\n"),
             (b"?", b"<Run|MPos:10.000,0.000,0.000|FS:3000,0|Ov:100,100,100>\r\n"),
             (b"?", b"<Idle|MPos:35.556,0.000,0.000|FS:0,0>\r\n")]
    g, ser = _connected(pairs)
    g.prepare()
    assert g.banner == "Grbl 1.1h ['$' for help]" and g.connected_by == "banner" and g.alarm is None
    assert (g.build.version, g.build.build, g.build.options) == ("1.1h", "20190830", "V")
    assert g.settings[130] == 320.0 and g.frame.offset_mm == (0.0, 0.0) and g.frame.space_mm is None
    pos = g.move_to(35.5556, 0.0)
    assert pos.xy_mm == (35.556, 0.0) and pos.raw == {"mpos_mm": [35.556, 0.0, 0.0], "wco_mm": [0.0, 0.0]}
    ser.assert_consumed()


def test_homing_enabled_puts_the_user_frame_into_the_negative_machine_space():
    """$22=1: GRBL's space is [-320, 0]; the driver sets G54 = (-320, -320) and checks it in a status report."""
    pairs = [(b"$$\n", HOMING_SETTINGS), (b"$#\n", PARAMS), (b"$X\n", b"[MSG:Caution: Unlocked]\r\nok\r\n"),
             (b"G10 L2 P1 X-320.000 Y-320.000\n", b"ok\r\n"), (b"G54\n", b"ok\r\n"),
             (b"$#\n", PARAMS.replace(b"G54:0.000,0.000", b"G54:-320.000,-320.000")),
             (b"?", b"<Idle|MPos:0.000,0.000,0.000|FS:0,0|WCO:-320.000,-320.000,0.000>\r\n"),
             (b"G90 G21 G1 X10.000 Y20.000 F3000\n", b"ok\r\n"),
             (b"?", b"<Idle|MPos:-310.000,-300.000,0.000|FS:0,0>\r\n")]
    g, ser = _connected(pairs, greeting=BANNER + b"[MSG:'$H'|'$X' to unlock]\r\n",
                        status=b"<Alarm|MPos:0.000,0.000,0.000|FS:0,0|Pn:XYZ|WCO:0.000,0.000,0.000>\r\n")
    g.prepare(unlock=True)
    assert g.frame.offset_mm == (-320.0, -320.0) and g.frame.space_mm == ((-320.0, 0.0), (-320.0, 0.0))
    pos = g.move_to(10, 20)   # commanded and reported in the same (user) frame; MPos kept for audit
    assert pos.xy_mm == (10.0, 20.0) and pos.raw["mpos_mm"] == [-310.0, -300.0, 0.0]
    assert g.describe()["work_offset_mm"] == [-320.0, -320.0] and g.describe()["soft_limits"] is True
    ser.assert_consumed()


def test_locked_at_connect_needs_home_or_unlock():
    g, ser = _connected([(b"$$\n", HOMING_SETTINGS), (b"$#\n", PARAMS)],
                        greeting=BANNER + b"[MSG:'$H'|'$X' to unlock]\r\n",
                        status=b"<Alarm|MPos:0.000,0.000,0.000|FS:0,0>\r\n")
    with pytest.raises(UserError, match=r"locked in alarm .*pass --home \(runs \$H\) or --unlock \(sends \$X"):
        g.prepare()
    assert g.alarm == -1 and g.blocked() == "in alarm (Alarm state)"
    ser.assert_consumed()


def test_gantry_that_was_running_answers_a_status_report_instead_of_a_banner():
    pairs = [(b"$$\n", SETTINGS), (b"$#\n", PARAMS), (b"G54\n", b"ok\r\n"), (b"?", IDLE)]
    ser = TranscriptSerial([(b"\x01\x05", b""), (b"?", IDLE), (b"?", IDLE), VERSION] + pairs)
    g = Grbl(ser, timeout=0.5, poll_s=0.0)
    g.prepare()
    assert g.banner is None and g.connected_by == "status" and g.build.version == "1.1h"
    ser.assert_consumed()


def test_telemetrix_on_a_grbl_port_is_named():
    ser = TranscriptSerial([(b"\x01\x05", b"\x04\x05\x05\x04\x04")])
    with pytest.raises(WrongFirmware, match="runs Telemetrix4Arduino 5.4.4, not GRBL: use --gantry-kind telemetrix"):
        Grbl(ser, timeout=0.5).connect(timeout=1.0)
    ser.assert_consumed()


def test_error_and_alarm_are_mapped_to_exceptions_that_say_what_grbl_needs():
    pairs = [(b"G1 X1\n", b"error:22\r\n"),
             (b"G90 G21 G1 X100.000 Y0.000 F3000\n", b"ok\r\n"),
             (b"?", b"<Run|MPos:40.000,0.000,0.000|FS:3000,0>\r\n"),
             (b"?", b"ALARM:1\r\n[MSG:Reset to continue]\r\n")]
    g, ser = _connected(pairs)
    g.connect(timeout=1.0)
    with pytest.raises(GrblError, match=r"gantry refused 'G1 X1': error:22 \(feed rate has not yet been set"):
        g.send("G1 X1")
    with pytest.raises(GrblAlarm, match=r"moving to \(100.000, 0.000\) mm: ALARM:1 \(hard limit triggered; .*"
                                        r"ignores everything, status requests and \$X included, until a soft reset"):
        g.move_to(100, 0)
    assert g.alarm == 1 and g.blocked() == "in alarm (ALARM:1)"
    ser.assert_consumed()
    assert "then unlock ($X, the position is retained)" in str(GrblAlarm(2))
    assert "locked until $H (home; recommended" in str(GrblAlarm(3))


def test_work_offset_changed_during_a_run_is_refused():
    pairs = [(b"$$\n", SETTINGS), (b"$#\n", PARAMS), (b"G54\n", b"ok\r\n"), (b"?", IDLE),
             (b"?", b"<Idle|MPos:5.000,5.000,0.000|FS:0,0|WCO:5.000,0.000,0.000>\r\n")]
    g, ser = _connected(pairs)
    g.prepare()
    with pytest.raises(FrameChanged, match=r"work offset is \(5, 0\) mm but nlosplan set \(0, 0\) mm"):
        g.where()
    ser.assert_consumed()


def test_soft_limits_of_the_driver_are_checked_before_sending():
    g, ser = _connected([])
    g.connect(timeout=1.0)
    with pytest.raises(LimitError, match=r"\(320.100, 0.000\) mm is outside the limits x 0..320, y 0..320 mm; "
                                         "nothing was sent"):
        g.move_to(320.1, 0.0)
    ser.assert_consumed()
    assert isinstance(LimitError("x"), UserError)


def test_character_counting_sends_ahead_within_grbls_128_byte_buffer():
    """Five 24-byte lines (120 bytes) go out before any ok; the sixth waits for the first ok."""
    lines = [f"G1 X{i}.000 Y{i}.000 F3000" for i in range(6)]
    answers = [b"", b"", b"", b"", b"ok\r\n", b"ok\r\n" * 5]   # send-and-wait would time out on line 1
    ser = TranscriptSerial([(f"{ln}\n".encode(), a) for ln, a in zip(lines, answers)])
    g = Grbl(ser, timeout=0.3)
    assert g.stream(lines) == 6
    ser.assert_consumed()
    with pytest.raises(Exception, match="no 'ok'"):
        Grbl(TranscriptSerial([(b"G1 X1 F1\n", b"")]), timeout=0.2).send("G1 X1 F1")


def test_real_time_bytes_and_soft_reset():
    pairs = [(b"!", b""), (b"~", b""), (b"\x18", BANNER), (b"?", IDLE)]
    g, ser = _connected(pairs)
    g.connect(timeout=1.0)
    g.feed_hold()
    g.resume()
    assert g.soft_reset(timeout=1.0).startswith("Grbl 1.1h")
    ser.assert_consumed()


def test_status_reports_of_the_real_firmware():
    st = parse_status("<Hold:1|WPos:10.000,5.000,0.000|Bf:15,128|FS:0,0|Pn:PXYZRHS|WCO:1.000,2.000,0.000>")
    assert (st.state, st.substate, st.pins) == ("Hold", "1", "PXYZRHS")
    assert st.wpos == (10.0, 5.0, 0.0) and st.mpos == (11.0, 7.0, 0.0) and st.wco == (1.0, 2.0, 0.0)
    st = parse_status("<Run|MPos:-51.840,-50.168,0.000|FS:27832,0|Pn:PXYZRHS|Ov:100,100,100>", (-320, -320, 0))
    assert st.wco is None and st.wpos == pytest.approx((268.16, 269.832, 0.0)) and st.feed == 27832
    with pytest.raises(ValueError, match="not a GRBL status report"):
        parse_status("ok")
    info = parse_build_info(["[VER:1.1h.20190830:]", "[OPT:VZ,15,128]"])
    assert (info.version, info.build, info.force_origin, info.rx_buffer) == ("1.1h", "20190830", True, 128)
    params = parse_ngc_parameters(["[G54:-320.000,-320.000,0.000]", "[TLO:0.000]", "[PRB:0.000,0.000,0.000:0]"])
    assert params["G54"] == (-320.0, -320.0, 0.0) and params["TLO"] == (0.0,) and params["PRB"] == (0.0, 0.0, 0.0)


def test_machine_space_and_settings_validation_follow_the_firmware():
    s = {130: 320.0, 131: 300.0, 132: 50.0, 23: 0, 22: 0}
    assert machine_space(s) == ((-320.0, 0.0), (-300.0, 0.0), (-50.0, 0.0))
    # only HOMING_FORCE_SET_ORIGIN with a negative homing direction gives a positive space
    assert machine_space({**s, 23: 1}) == ((-320.0, 0.0), (-300.0, 0.0), (-50.0, 0.0))
    assert machine_space({**s, 23: 1}, force_origin=True)[:2] == ((0.0, 320.0), (-300.0, 0.0))
    assert setting_error(s, 20, 1) == 10 and setting_error({22: 1}, 20, 1) is None
    assert (setting_error(s, 0, 2), setting_error(s, 100, -1), setting_error(s, 999, 1)) == (6, 4, 3)
    assert setting_error(s, 32, 1, variable_spindle=False) == 17


def test_work_frame_choices_and_limits_outside_the_machine_space():
    homing = {20: 1, 22: 1, 100: 250, 101: 250, 130: 320, 131: 320}
    assert plan_frame("auto", ((0, 320), (0, 320)), homing).offset_mm == (-320, -320)
    assert plan_frame("auto", ((0, 320), (0, 320)), {22: 0}).offset_mm == (0.0, 0.0)
    assert plan_frame("keep", ((0, 320), (0, 320)), {22: 0}, active_wco=(1.5, 2.5)).offset_mm == (1.5, 2.5)
    assert plan_frame((-330, -320), ((10, 320), (0, 320)), homing).offset_mm == (-330, -320)
    with pytest.raises(UserError, match=r"gantry limits x 0..330 mm map to machine x -320..10 mm .* outside GRBL's "
                                        r"machine space x -320..0 mm \(\$130=320, homing on, soft limits on\): "
                                        r"raise \$130 or narrow --limits"):
        plan_frame("auto", ((0, 330), (0, 320)), homing)
    with pytest.raises(UserError, match=r"limits y 0..320 mm map to machine y -310..10 mm .*use --work-offset auto"):
        plan_frame((-320, -310), ((0, 320), (0, 320)), homing)
    assert parse_work_offset("-320,-320") == (-320.0, -320.0) and parse_work_offset("KEEP") == "keep"
    with pytest.raises(UserError, match="use auto, keep, or X,Y"):
        parse_work_offset("origin")


def test_homing_diagnosis_names_z_first_and_stuck_pins():
    before = parse_status("<Alarm|MPos:-295.040,-300.000,0.000|FS:0,0|Pn:PXYZRHS>")
    after = parse_status("<Alarm|MPos:-295.040,-300.000,-1.000|FS:0,0|Pn:PXYZRHS>")
    text = homing_diagnosis(8, before, after)
    assert "limit pin(s) X, Y, Z read triggered before homing started" in text and "$5=1" in text
    assert "stopped after Z moved, before X or Y moved: stock GRBL homes Z first (HOMING_CYCLE_0" in text
    no_z = homing_diagnosis(9, parse_status("<Alarm|MPos:0,0,0|FS:0,0>"), parse_status("<Alarm|MPos:0,0,300|FS:0,0>"))
    assert "Pn" not in no_z and "needs a Z limit switch or GRBL rebuilt with HOMING_CYCLE_0" in no_z
    xy = homing_diagnosis(9, parse_status("<Alarm|MPos:0,0,0|FS:0,0>"), parse_status("<Alarm|MPos:9,0,-1|FS:0,0>"))
    assert "could not find the limit switch" in xy and "Z first" not in xy


def test_bad_settings_are_one_line_errors():
    with pytest.raises(UserError, match="limits"):
        Grbl(TranscriptSerial([]), limits_mm=((5, 1), (0, 1)))
    with pytest.raises(UserError, match="feed rate"):
        Grbl(TranscriptSerial([]), feed_mm_min=0)
    with pytest.raises(UserError, match="work offset"):
        Grbl(TranscriptSerial([]), work_offset="middle")
