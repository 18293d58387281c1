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


# DENALI's firmware (tmf8828_app.cpp, serialInput): every command ends with printState's line; ``o`` after ``d``
# times out on I2C (the device is off); ``E`` downloads (" DWNL"), and the TMF8821 image refuses the 8x8 mode
CONF = b"#Conf,Period=16ms,KIter=10000 SPAD=6 Pers=0\n"


def _answers(zones="3x3"):
    return [(b"h", b"TMF8828 Arduino Driver\nUART commands\n# ... reset\nTMF8828 state=disabled\n"),
            (b"d", b"TMF8828 state=disabled\n"),
            (b"o", b"#Err,timeout 2300 reg=0x8 exp=0x0 0xFF\n#Err,mode switch to,0\nTMF882x state=disabled\n"),
            (b"E", b" DWNL\n#Err,mode switch to,1\n" + CONF + b"TMF8828 Arduino Driver\nUART commands\n"
                   b"Driver 1.14 FW 0.0.0.0. Chip 0.0 Serial 0x0\nTMF882x state=stopped\n"),
            (b"O", CONF + b"TMF882x state=stopped\n"),
            (b"z", CONF + b"Histogram is 1\nTMF882x state=stopped\n"),
            (b"m", b"TMF882x state=measure\n")]


def test_driver_start_transcript_and_frames():
    counts = np.random.default_rng(4).integers(0, 70000, size=(3, 3, 128))
    stream = "".join(ln + "\n" for ln in _stream(counts, ZoneMode.Z3X3)).encode()
    pairs = _answers()
    pairs[-1] = (b"m", b"TMF882x state=measure\n" + stream)
    ser = TranscriptSerial(pairs)
    lidar = TMF8828(ser, baudrate=115200, quiet_s=0.01, command_timeout=0.5)
    cfg = lidar.start("3x3", "short")
    assert cfg["sequence"] == "hdoEOzm" and cfg["answers"]["m"] == "TMF882x state=measure"
    ser.assert_consumed()
    # the frame that followed the "m" answer stays buffered for read_frame; a second one follows on the link
    ser.pairs.append((b"s", b"TMF882x state=stopped\n"))
    ser._out += stream
    frame = lidar.read_frame(timeout=1.0)
    np.testing.assert_array_equal(frame.counts, counts)
    lidar.stop()
    ser.assert_consumed()


def test_driver_presses_z_again_until_it_dumps_raw_and_checks_the_mode_it_measures_in():
    pairs = _answers()
    pairs[5] = (b"z", CONF + b"Histogram is 2\nTMF882x state=stopped\n")
    pairs.insert(6, (b"z", CONF + b"Histogram is 3\nTMF882x state=stopped\n"))
    pairs.insert(7, (b"z", CONF + b"Histogram is 0\nTMF882x state=stopped\n"))
    pairs.insert(8, (b"z", CONF + b"Histogram is 1\nTMF882x state=stopped\n"))
    ser = TranscriptSerial(pairs)
    TMF8828(ser, quiet_s=0.01, command_timeout=0.5).start("3x3", "short")
    ser.assert_consumed()
    # a firmware that measures in the other mode (here: 8x8 when 3x3 was asked for) is named, not parsed wrongly
    pairs = _answers()
    pairs[-1] = (b"m", b"TMF8828 state=measure\n")
    with pytest.raises(SensorError, match="after 'm' the firmware says 'TMF8828 state=measure', not 'TMF882x "
                                          "state=measure' \\(3x3 zones\\): it did not start in this mode"):
        TMF8828(TranscriptSerial(pairs), quiet_s=0.01, command_timeout=0.5).start("3x3", "short")


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
    ser._out += b"#Raw,65,0," + b",".join([b"1"] * 128) + b"\n"
    with pytest.raises(SensorError, match="no complete 3x3 frame within 0.2 s"):
        lidar.read_frame(timeout=0.2)


# ----------------------------------------------------------------- the emulator prints what the firmware prints
def _has_state(lines: list[str]) -> bool:
    """Whether a reply is complete: printState()'s ``... state=...`` line ends every command's reply."""
    return any(" state=" in ln for ln in lines)


def _say(ser, ch: bytes, wait: float = 0.15, until=_has_state, deadline: float = 20.0) -> list[str]:
    """Send ``ch``; the complete lines that arrive in at least ``wait`` seconds and until ``until(lines)`` holds.

    Reading to a condition, not for a fixed time alone, keeps the test exact on a loaded machine (a CI run with
    two workers once read nothing within 0.3 s of the emulator's start); ``deadline`` seconds bound the wait.
    """
    import time

    ser.write(ch)
    got, start = bytearray(), time.monotonic()
    while True:
        got += ser.read(1 << 16)
        lines = got.decode().split("\n")[:-1]
        waited = time.monotonic() - start
        if (waited >= wait and until(lines)) or waited >= deadline:
            return lines
        time.sleep(0.005)


def test_emulator_answers_o_and_O_with_the_firmwares_own_lines():
    """From DENALI's tmf8828_app.cpp: ``o`` toggles modeIsTmf8828 and calls setMode(), which prints only when the
    switch fails; ``O`` toggles isLongRangeMode and, when stopped, applies it and prints configure()'s line;
    printState() ends every command."""
    import serial

    from nlosplan.hardware.emulators import EmulatedTMF8828

    # the help screen 0.3 s after the port opens: pyserial empties the input buffer once it has opened the port, so
    # a screen sent at once was lost whenever the emulator saw the opening first (a loaded machine)
    with EmulatedTMF8828(lambda z, r: (np.zeros((int(z[0]), int(z[0]), 128)), 100.0), boot_s=0.3) as emu:
        ser = serial.Serial(emu.port, 115200, timeout=0)
        try:
            boot = _say(ser, b"", 0.5, until=lambda ls: "# ... reset" in ls)
            assert boot[0] == "TMF8828 Arduino Driver" and boot[-1] == "# ... reset"   # setupFn's help screen
            assert _say(ser, b"d") == ["TMF8828 state=disabled"]
            # the device is off: the mode switch's register check times out (driver log level ERROR at start-up)
            assert _say(ser, b"o") == ["#Err,timeout 2300 reg=0x8 exp=0x0 0xFF", "#Err,mode switch to,0",
                                       "TMF882x state=disabled"]
            assert _say(ser, b"O") == ["TMF882x state=disabled"]       # toggled, not applied: not stopped
            e = _say(ser, b"e", 0.3)
            assert e[:2] == [" DWNL", "#Conf,Period=132ms,KIter=10 SPAD=15 Pers=0"] and e[-1] == "TMF8828 state=stopped"
            assert (emu.zones, emu.short_range) == (ZoneMode.Z8X8, False)   # the download reset mode and range
            assert _say(ser, b"O") == ["#Conf,Period=132ms,KIter=10 SPAD=15 Pers=0", "TMF8828 state=stopped"]
            assert emu.short_range
            assert _say(ser, b"o") == ["TMF882x state=stopped"]        # the TMF8828 image switches silently
            assert _say(ser, b"o") == ["TMF8828 state=stopped"]
            assert _say(ser, b"E") == ["Driver 1.14 FW 0.0.0.0. Chip 0.0 Serial 0x0", "TMF8828 state=stopped"]
            assert _say(ser, b"z") == ["#Conf,Period=132ms,KIter=10 SPAD=15 Pers=0", "Histogram is 1",
                                       "TMF8828 state=stopped"]
            assert _say(ser, b"k") == ["#Err,Cmd k", "TMF8828 state=stopped"]
            assert _say(ser, b"m", 0.05)[0] == "TMF8828 state=measure"
        finally:
            ser.close()


def _one_whole_result(lines: list[str]) -> bool:
    """Whether ``lines`` hold a result from its first #Cal dump to its #Obj line."""
    starts = [i for i, ln in enumerate(lines) if ln.startswith("#Cal,65,0,")]
    return bool(starts) and any(ln.startswith("#Obj") for ln in lines[starts[0]:])


def test_emulator_prints_a_result_as_the_recording_does(recording):
    """The recording (a two-dump result, dump mode 3): the result's #Cal dumps, then its #Raw dumps, then #Obj."""
    import serial

    from nlosplan.hardware.emulators import EmulatedTMF8828

    def kinds(lines):
        out = []
        for ln in lines:
            k = ln.split(",")[0]
            if k in ("#Cal", "#Raw", "#Obj") and (not out or out[-1][0] != k):
                out.append([k, 0])
            if k in ("#Cal", "#Raw", "#Obj"):
                out[-1][1] += 1
        return out

    first_obj = next(i for i, ln in enumerate(recording) if ln.startswith("#Obj"))
    assert kinds(recording[:first_obj + 1]) == [["#Cal", 60], ["#Raw", 60], ["#Obj", 1]]
    with EmulatedTMF8828(lambda z, r: (np.full((4, 4, 128), 5.0), 100.0), frame_period_s=0.2) as emu:
        ser = serial.Serial(emu.port, 115200, timeout=0)
        try:
            for ch in b"doEczzz":              # 4x4 (two dumps per result), dump mode 3 (calibration and raw)
                _say(ser, bytes([ch]), 0.05)
            assert emu.dump_mode == 3 and emu.zones is ZoneMode.Z4X4
            lines = _say(ser, b"m", 0.5, until=_one_whole_result)
        finally:
            ser.close()
    start = next(i for i, ln in enumerate(lines) if ln.startswith("#Cal,65,0,"))
    end = next(i for i, ln in enumerate(lines) if i > start and ln.startswith("#Obj"))
    assert kinds(lines[start:end + 1]) == [["#Cal", 60], ["#Raw", 60], ["#Obj", 1]]


# ----------------------------------------------------------------- 8x8: the sub-capture order against cc-hardware
# cc-hardware's TMF8828 driver (NikhilBehari/denali capture/pkgs/drivers/cc_hardware/drivers/spads/tmf8828.py),
# facts restated: in 8x8 (SPAD map 15) it reads only #Raw lines, takes the next 8 complete dumps in arrival order as
# sub-captures 0..7 (channels 1..8 each, sub-packet index checked only until the first gap), ignores #Obj and its
# result number, and places sub-capture k, channel c at pixel CC_PIXELS[10 k + c] (1..64, row-major from 1).
CC_PIXELS = {1: 57, 2: 61, 3: 41, 4: 45, 5: 25, 6: 29, 7: 9, 8: 13, 11: 58, 12: 62, 13: 42, 14: 46, 15: 26, 16: 30,
             17: 10, 18: 14, 21: 59, 22: 63, 23: 43, 24: 47, 25: 27, 26: 31, 27: 11, 28: 15, 31: 60, 32: 64, 33: 44,
             34: 48, 35: 28, 36: 32, 37: 12, 38: 16, 41: 49, 42: 53, 43: 33, 44: 37, 45: 17, 46: 21, 47: 1, 48: 5,
             51: 50, 52: 54, 53: 34, 54: 38, 55: 18, 56: 22, 57: 2, 58: 6, 61: 51, 62: 55, 63: 35, 64: 39, 65: 19,
             66: 23, 67: 3, 68: 7, 71: 52, 72: 56, 73: 36, 74: 40, 75: 20, 76: 24, 77: 4, 78: 8}


def cc_hardware_8x8(lines):
    """One 8x8 capture as cc-hardware assembles it from a stream of firmware lines: (8, 8, 128) counts."""
    subs, current, last, bad = {}, 0, -1, False
    for line in lines:
        if not line.startswith("#Raw"):
            continue
        row = line.split(",")
        idx = int(row[2])
        if idx != last + 1 and not bad:
            bad = True
            continue
        last = idx
        base, channel = divmod(idx, 10)
        sub = subs.setdefault(current, np.zeros((9, 128), np.int64))
        if not 0 <= channel <= 8:
            continue
        sub[channel] += np.array(row[3:], np.int64) << (8 * base)
        if base == 2 and channel == 8:
            current += 1
            if current == 8:
                combined = np.vstack([subs[k][1:9] for k in range(8)])
                out = np.zeros((8, 8, 128), np.int64)
                for i, key in enumerate(CC_PIXELS):
                    out[divmod(CC_PIXELS[key] - 1, 8)] = combined[i]
                return out
    return None


def _tagged_8x8_stream(first_result=0, results=8):
    """Firmware lines of 8x8 results (two dumps each, then #Obj); channel c of dump d of result r holds
    1000 * (2 * (r % 4) + d) + c in every bin: the dump's place in its frame, readable from any capture."""
    lines = []
    for r in range(first_result, first_result + results):
        for d in range(2):
            ch = np.zeros((10, 128), np.int64)
            ch[1:9] = (1000 * (2 * (r % 4) + d) + np.arange(1, 9))[:, None]
            lines += dump_lines(ch)
        lines.append(obj_line(r))
    return lines


def test_8x8_sub_capture_order_matches_cc_hardware_when_its_capture_starts_at_sub_capture_0():
    stream = _tagged_8x8_stream()
    asm = FrameAssembler("8x8")
    frames = [f for ln in stream for f in asm.feed(ln)]
    assert len(frames) == 2
    ours = frames[0].counts
    theirs = cc_hardware_8x8(stream)
    np.testing.assert_array_equal(ours, theirs)            # same pixel for every (dump, channel)
    assert sorted((ours[..., 0].ravel() // 1000).tolist()) == sorted(list(range(8)) * 8)
    # nlosplan waits for result_number % 4 == 0; cc-hardware takes whatever dump comes first. A capture that starts
    # one result late (its accumulate() began mid-frame) puts every dump two sub-captures off: the same 64 zones,
    # permuted, and nothing in the data says so
    late = stream[2 * 30 + 1:]
    resynced = FrameAssembler("8x8")
    np.testing.assert_array_equal([f for ln in late for f in resynced.feed(ln)][0].counts, ours)
    shifted = cc_hardware_8x8(late)
    assert not np.array_equal(shifted, ours)
    zm = zone_map_8x8()
    for s in range(8):
        for c in range(8):
            r, q = divmod(int(zm[s, c]), 8)
            assert shifted[r, q, 0] == 1000 * ((s + 2) % 8) + c + 1
