"""GRBL 1.1 driver against command/response transcripts (every pair consumed, exact bytes)."""

import pytest

from nlosplan.errors import UserError
from nlosplan.hardware.grbl import Grbl, GrblAlarm, GrblError, LimitError
from nlosplan.hardware.grbl_protocol import parse_status
from nlosplan.hardware.transcript import TranscriptSerial

BANNER = b"\r\nGrbl 1.1h ['$' for help]\r\n"
IDLE = b"<Idle|MPos:0.000,0.000,0.000|FS:0,0>\r\n"


def _connected(pairs, banner=BANNER, status=IDLE):
    ser = TranscriptSerial([(b"\r\n\r\n", banner), (b"?", status)] + pairs)
    g = Grbl(ser, timeout=0.5, poll_s=0.0)
    g.connect(timeout=1.0)
    return g, ser


def test_connect_settings_and_move_wait_for_idle():
    pairs = [
        (b"$$\n", b"$110=6000\r\n$130=320.000\r\n$22=0\r\nok\r\n"),
        (b"G90 G21 G1 X35.556 Y0.000 F3000\n", b"ok\r\n"),
        (b"?", b"<Run|MPos:10.000,0.000,0.000|FS:3000,0>\r\n"),
        (b"?", b"<Run|MPos:30.000,0.000,0.000|FS:3000,0>\r\n"),
        (b"?", b"<Idle|MPos:35.556,0.000,0.000|FS:0,0>\r\n"),
    ]
    g, ser = _connected(pairs)
    assert g.banner == "Grbl 1.1h ['$' for help]" and g.alarm is None
    assert g.settings() == {110: 6000.0, 130: 320.0, 22: 0.0}
    st = g.move_to(35.5556, 0.0)
    assert st.state == "Idle" and st.mpos == (35.556, 0.0, 0.0)
    ser.assert_consumed()


def test_soft_limits_are_checked_before_sending():
    g, ser = _connected([])
    with pytest.raises(LimitError, match=r"\(320.100, 0.000\) mm is outside the limits x 0..320, y 0..320 mm; "
                                         "nothing was sent"):
        g.move_to(320.1, 0.0)
    ser.assert_consumed()
    assert isinstance(LimitError("x"), UserError)


def test_error_and_alarm_are_mapped_to_exceptions():
    pairs = [(b"G1 X1\n", b"error:22\r\n"),
             (b"G90 G21 G1 X100.000 Y0.000 F3000\n", b"ok\r\n"),
             (b"?", b"<Run|MPos:40.000,0.000,0.000|FS:3000,0>\r\n"),
             (b"?", b"ALARM:1\r\n[MSG:Reset to continue]\r\n")]
    g, ser = _connected(pairs)
    with pytest.raises(GrblError, match=r"gantry refused 'G1 X1': error:22 \(feed rate has not yet been set"):
        g.send("G1 X1")
    with pytest.raises(GrblAlarm, match=r"moving to \(100.000, 0.000\) mm: ALARM:1 \(hard limit"):
        g.move_to(100, 0)
    assert g.alarm == 1
    ser.assert_consumed()


def test_locked_at_connect_then_unlock_only_when_asked():
    pairs = [(b"$X\n", b"[MSG:Caution: Unlocked]\r\nok\r\n")]
    g, ser = _connected(pairs, banner=BANNER + b"[MSG:'$H'|'$X' to unlock]\r\n",
                        status=b"<Alarm|MPos:0.000,0.000,0.000|FS:0,0>\r\n")
    assert g.alarm == -1
    g.unlock()
    assert g.alarm is None
    ser.assert_consumed()


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
    g.feed_hold()
    g.resume()
    assert g.soft_reset(timeout=1.0).startswith("Grbl 1.1h")
    ser.assert_consumed()


def test_status_parsing_with_work_offsets():
    st = parse_status("<Hold:0|WPos:10.000,5.000,0.000|Bf:15,128|FS:0,0|WCO:1.000,2.000,0.000>")
    assert st.state == "Hold" and st.wpos == (10.0, 5.0, 0.0) and st.mpos == (11.0, 7.0, 0.0)
    with pytest.raises(ValueError, match="not a GRBL status report"):
        parse_status("ok")


def test_bad_settings_are_one_line_errors():
    with pytest.raises(UserError, match="limits"):
        Grbl(TranscriptSerial([]), limits_mm=((5, 1), (0, 1)))
    with pytest.raises(UserError, match="feed rate"):
        Grbl(TranscriptSerial([]), feed_mm_min=0)
