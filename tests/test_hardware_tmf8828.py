"""TMF8828 protocol and driver: the real recording, synthetic streams with faults, command transcripts."""

import numpy as np
import pytest

from nlosplan.errors import UserError
from nlosplan.hardware.tmf8828 import TMF8828, SensorError
from nlosplan.hardware.tmf8828_protocol import (
    FrameAssembler, LineError, RangeMode, ZoneMode, dump_lines, frame_dumps, obj_line, parse_hist_line, parse_obj_line,
    start_sequence, zone_map_8x8)
from nlosplan.hardware.transcript import TranscriptError, TranscriptSerial


@pytest.fixture
def recording(shared_data):
    return (shared_data / "tmf8828" / "arduino_capture_excerpt.csv").read_text().splitlines()


def _combined(lines, tag):
    """The recording script's own 24-bit combined histograms (#RCo<ch> / #CCo<ch>), in order."""
    return [(int(ln.split(",")[0][4:]), np.array(ln.split(",")[1:], np.int64)) for ln in lines if ln.startswith(tag)]


def test_recording_dumps_match_the_recordings_combined_lines(recording):
    """Every complete #Raw/#Cal dump parses to the counts the recording script combined (b0 + 256 b1 + 65536 b2)."""
    for kind, tag in (("#Raw", "#RCo"), ("#Cal", "#CCo")):
        planes, dumps = {}, []
        for ln in recording:
            if ln.startswith(kind):
                _, _, n, values = parse_hist_line(ln)
                planes[n] = values
                if n == 29:
                    dumps.append(sum(np.stack([planes[p * 10 + c] for c in range(10)]) << (8 * p) for p in range(3)))
                    planes = {}
        combined = _combined(recording, tag)
        assert len(combined) == 10 * len(dumps) and len(dumps) >= 2
        for k, (ch, counts) in enumerate(combined):
            assert ch == k % 10
            np.testing.assert_array_equal(dumps[k // 10][ch], counts)
    raw = _combined(recording, "#RCo")
    assert raw[1][1].max() > 256, "the recording exercises the mid byte plane"


def test_recording_as_4x4_gives_one_frame_equal_to_its_combined_lines(recording):
    asm = FrameAssembler("4x4")
    frames = [f for ln in recording for f in asm.feed(ln)]
    assert len(frames) == 1 and asm.stats.dropped_frames == 0 and asm.stats.garbage_lines == 0
    raw = _combined(recording, "#RCo")
    flat = frames[0].counts.reshape(16, 128)
    for zone in range(16):
        dump, ch = divmod(zone, 8)
        np.testing.assert_array_equal(flat[zone], raw[10 * dump + ch + 1][1])
    np.testing.assert_array_equal(frames[0].reference[0], raw[0][1])
    obj = frames[0].results[0]
    assert (obj.result_number, obj.temperature_c, obj.n_valid, obj.systick) == (0, 22, 2, 15030003)
    assert obj.distance_mm[5] == 2028 and obj.confidence[5] == 16
    assert asm.stats.calibration_dumps == 3 and asm.last_calibration is not None


def test_recording_in_other_modes_returns_no_frame(recording):
    """3x3 wants one dump per result: the recording's two-dump result is dropped and counted; 8x8 waits for more."""
    a3 = FrameAssembler("3x3")
    assert [f for ln in recording for f in a3.feed(ln)] == []
    assert a3.stats.dropped_frames == 1
    a8 = FrameAssembler("8x8")
    assert [f for ln in recording for f in a8.feed(ln)] == [] and a8.stats.dropped_frames == 0


def test_zone_map_8x8_is_the_fixed_pixel_permutation():
    zm = zone_map_8x8()
    assert sorted(zm.ravel().tolist()) == list(range(64))
    # DENALI/cc-hardware pixel map: dump 0 channel 1 -> pixel 57, dump 4 channel 7 -> pixel 1, dump 7 channel 8 -> 8
    assert zm[0, 0] == 56 and zm[4, 6] == 0 and zm[7, 7] == 7 and zm[3, 1] == 63


def _stream(counts, zones, first_result=0):
    lines, dumps = [], frame_dumps(counts, zones, reference=np.arange(128))
    per = zones.dumps_per_result
    for r in range(zones.results_per_frame):
        for d in dumps[r * per:(r + 1) * per]:
            lines += dump_lines(d)
        lines.append(obj_line(first_result + r))
    return lines


@pytest.mark.parametrize("zones", list(ZoneMode))
def test_frames_round_trip_with_24_bit_counts(zones):
    rng = np.random.default_rng(1)
    rows, cols = zones.shape
    counts = rng.integers(0, 2 ** 24, size=(rows, cols, 128))
    counts[0, 0, 0] = 2 ** 24 - 1
    asm = FrameAssembler(zones)
    frames = [f for ln in _stream(counts, zones) for f in asm.feed(ln + "\r\n")]
    assert len(frames) == 1
    np.testing.assert_array_equal(frames[0].counts, counts)
    assert frames[0].counts.dtype == np.int64 and len(frames[0].results) == zones.results_per_frame


def test_garbage_and_partial_lines_drop_only_their_frame():
    zones = ZoneMode.Z3X3
    rng = np.random.default_rng(2)
    frames_in = [rng.integers(0, 5000, size=(3, 3, 128)) for _ in range(5)]
    streams = [_stream(c, zones, first_result=i) for i, c in enumerate(frames_in)]
    streams[1][7] = streams[1][7][:40]                       # truncated line
    streams[2][3] = streams[2][3].replace(",", "?", 2)       # garbled line
    del streams[3][12]                                       # dropped line
    noise = ["\x00\xff garbage", "TMF8828 state=1", "#Err,65,7"]
    asm = FrameAssembler(zones)
    out = [f for ln in noise + [x for s in streams for x in s] for f in asm.feed(ln)]
    assert len(out) == 2
    np.testing.assert_array_equal(out[0].counts, frames_in[0])
    np.testing.assert_array_equal(out[1].counts, frames_in[4])
    assert asm.stats.dropped_frames == 3 and asm.stats.frames == 2
    assert asm.stats.garbage_lines == 3   # the binary noise, the cut line, the garbled line


def test_8x8_frame_waits_for_sub_capture_zero_and_drops_a_gap():
    counts = np.random.default_rng(3).integers(0, 100, size=(8, 8, 128))
    lines = _stream(counts, ZoneMode.Z8X8, first_result=4)
    asm = FrameAssembler("8x8")
    # start in the middle of a frame (sub-captures 2, 3), then one whole frame, then one with sub-capture 1 lost
    start = lines.index(obj_line(5)) + 1
    second = _stream(counts, ZoneMode.Z8X8, first_result=8)
    a, b = second.index(obj_line(8)) + 1, second.index(obj_line(9)) + 1
    out = [f for ln in lines[start:] + lines + second[:a] + second[b:] for f in asm.feed(ln)]
    assert len(out) == 1
    np.testing.assert_array_equal(out[0].counts, counts)
    assert asm.stats.dropped_frames == 1


def test_line_parsers_reject_bad_lines():
    with pytest.raises(LineError, match="fields"):
        parse_hist_line("#Raw,65,3,1,2")
    with pytest.raises(LineError, match="out of range 0..29"):
        parse_hist_line("#Raw,65,30," + ",".join(["0"] * 128))
    with pytest.raises(LineError, match="byte out of range"):
        parse_hist_line("#Raw,65,0," + ",".join(["256"] * 128))
    with pytest.raises(LineError, match="78"):
        parse_obj_line("#Obj,65,1")


def test_start_sequences_follow_denali():
    assert "".join(start_sequence(ZoneMode.Z3X3, RangeMode.SHORT)) == "hdoEOzm"
    assert "".join(start_sequence(ZoneMode.Z4X4, RangeMode.SHORT)) == "hdoEcOzm"
    assert "".join(start_sequence(ZoneMode.Z8X8, RangeMode.LONG)) == "hdezm"


def _answers(zones="3x3"):
    return [(b"h", b"help text\r\n"), (b"d", b"TMF8828 state=0\r\n"), (b"o", b"TMF882x mode\r\n"),
            (b"E", b"Download TMF882x firmware\r\n"), (b"O", b"Short range\r\n"), (b"z", b"Histogram is 1\r\n"),
            (b"m", b"Measure\r\n")]


def test_driver_start_transcript_and_frames():
    counts = np.random.default_rng(4).integers(0, 70000, size=(3, 3, 128))
    stream = "".join(ln + "\r\n" for ln in _stream(counts, ZoneMode.Z3X3)).encode()
    pairs = _answers()
    pairs[-1] = (b"m", b"Measure\r\n" + stream)
    ser = TranscriptSerial(pairs)
    lidar = TMF8828(ser, baudrate=115200, quiet_s=0.01, command_timeout=0.5)
    cfg = lidar.start("3x3", "short")
    assert cfg["sequence"] == "hdoEOzm" and cfg["answers"]["z"] == "Histogram is 1"
    ser.assert_consumed()
    # the frame that followed the "m" answer stays buffered for read_frame; a second one follows on the link
    ser.pairs.append((b"s", b"Stop\r\n"))
    ser._out += stream
    frame = lidar.read_frame(timeout=1.0)
    np.testing.assert_array_equal(frame.counts, counts)
    lidar.stop()
    ser.assert_consumed()


def test_driver_presses_a_toggle_again_until_its_state_is_right():
    pairs = _answers()
    pairs[5] = (b"z", b"Histogram is 2\r\n")
    pairs.insert(6, (b"z", b"Histogram is 3\r\n"))
    pairs.insert(7, (b"z", b"Histogram is 0\r\n"))
    pairs.insert(8, (b"z", b"Histogram is 1\r\n"))
    ser = TranscriptSerial(pairs)
    TMF8828(ser, quiet_s=0.01, command_timeout=0.5).start("3x3", "short")
    ser.assert_consumed()


def test_driver_errors_are_clear():
    with pytest.raises(UserError, match="baud rate 9600 is not a TMF8828 firmware rate"):
        TMF8828(TranscriptSerial([]), baudrate=9600)
    lidar = TMF8828(TranscriptSerial([(b"h", b"")]), quiet_s=0.01, command_timeout=0.2)
    with pytest.raises(SensorError, match="no answer to command 'h' within 0.2 s"):
        lidar.start("3x3", "short")
    with pytest.raises(SensorError, match="not measuring"):
        lidar.read_frame(timeout=0.1)
    with pytest.raises(TranscriptError, match="expects"):
        TMF8828(TranscriptSerial([(b"h", b"x\r\n")]), quiet_s=0.01).command("d")


def test_read_frame_times_out_without_a_complete_frame():
    pairs = _answers()
    ser = TranscriptSerial(pairs)
    lidar = TMF8828(ser, quiet_s=0.01, command_timeout=0.5)
    lidar.start("3x3", "short")
    ser._out += b"#Raw,65,0," + b",".join([b"1"] * 128) + b"\r\n"
    with pytest.raises(SensorError, match="no complete 3x3 frame within 0.2 s"):
        lidar.read_frame(timeout=0.2)
