"""Telemetrix gantry: the driver against transcripts written from Telemetrix4Arduino's byte layout, the pty
emulator as a real Uno behaves (reset window, 16-bit arithmetic, 30-byte buffer, unknown commands, enable pin),
the rig file, and telling GRBL from Telemetrix without confusing either."""

import time

import pytest
import serial

from nlosplan.errors import UserError
from nlosplan.hardware import telemetrix_protocol as tp
from nlosplan.hardware.emulators import EmulatedGrbl, EmulatedTelemetrix
from nlosplan.hardware.gantry import LimitError, WrongFirmware
from nlosplan.hardware.rig import detect_gantry_kind
from nlosplan.hardware.telemetrix import TelemetrixGantry
from nlosplan.hardware.telemetrix_config import (DEFAULT_RIG_FILE, DENALI_STEPS_PER_MM, AxisConfig,
                                                 TelemetrixConfig, load_rig_file)
from nlosplan.hardware.transcript import TranscriptSerial
from nlosplan.hardware.transport import DeviceTimeout


def _eventually(check, timeout: float = 10.0) -> bool:
    """Poll ``check()`` until it holds or ``timeout`` seconds pass; its last value.

    The emulator runs in its own thread: a fixed sleep before an assertion reads nothing on a loaded machine.
    """
    end = time.monotonic() + timeout
    while not (ok := check()) and time.monotonic() < end:
        time.sleep(0.01)
    return ok

H = bytes.fromhex
# [length, type, data...]: length counts the type byte and the data (Telemetrix4Arduino get_next_command)
OPEN = [
    (H("0105"), H("0405050404")),          # GET_FIRMWARE_VERSION (5) -> FIRMWARE_REPORT 5.4.4
    (H("0111"), b""),                      # ENABLE_ALL_REPORTS (17): steppers run only while reports are on
    (H("0136"), H("02147f")),              # GET_FEATURES (54) -> FEATURES (20): 0x7f, steppers bit 0x04 set
    # motor 0 (X): SET_PIN_MODE_STEPPER (33) interface 1 (driver), step 2, dir 5, pins 3/4 unused (4, 5), enable
    (H("0821000102050405" "01"), b""),
    (H("032f0008"), b""),                  # STEPPER_SET_ENABLE_PIN (47) pin 8
    (H("053000000001"), b""),              # STEPPER_SET_3_PINS_INVERTED (48): direction 0, step 0, enable 1
    (H("0426007fff"), b""),                # STEPPER_SET_MAX_SPEED (38) 32767 = 0x7fff
    (H("0821010103060405" "01"), b""),     # motor 1 (Y): step 3, dir 6
    (H("032f0108"), b""),
    (H("053001000001"), b""),
    (H("0426017fff"), b""),
    (H("022d00"), b""),                    # STEPPER_ENABLE_OUTPUTS (45): the shared enable pin to "enabled"
    (H("022d01"), b""),
    (H("023300"), H("061100" "00000000")),  # STEPPER_GET_CURRENT_POSITION (51) -> report 17: motor 0 at 0 steps
    (H("023301"), H("061101" "00000000")),
]
QUICK_BOARD = {"boot_s": 0.3, "blink_s": 0.3}      # an emulated board that boots in 0.6 s (tests of other things)
QUICK_DRIVER = {"boot_s": 0.5, "answer_s": 1.5}     # a driver that waits out that boot


def test_open_and_move_follow_the_documented_byte_layout():
    move = [
        # (35.556, 10.0) mm at 101.786 steps/mm: 3619 = 0x0e23 and 1018 = 0x03fa steps; 3000 mm/min = 5089 steps/s
        (H("07220000000e2300"), b""),      # STEPPER_MOVE_TO (34): |position| 4 bytes big-endian, polarity 0
        (H("05280013e100"), b""),          # STEPPER_SET_SPEED (40) 5089 = 0x13e1, after move_to (which resets it)
        (H("022a00"), b""),                # STEPPER_RUN_SPEED_TO_POSITION (42): constant speed, DENALI's way
        (H("0722010000" "03fa00"), b""),
        (H("05280113e100"), b""),
        (H("022a01"), H("021300" "021301")),  # RUN_COMPLETE (19) for motors 0 and 1
        (H("023300"), H("061100" "00000e23")),
        (H("023301"), H("061101" "000003fa")),
    ]
    ser = TranscriptSerial(OPEN + move)
    g = TelemetrixGantry(ser, boot_s=0.2)
    t0 = time.monotonic()
    g.prepare()
    assert time.monotonic() - t0 >= 0.2             # nothing was sent while the board boots
    assert (g.firmware, g.features, g.steps) == ("5.4.4", 0x7F, (0, 0))
    pos = g.move_to(35.556, 10.0, feed_mm_min=3000)
    assert pos.raw == {"steps": [3619, 1018]} and pos.xy_mm == pytest.approx((35.556, 10.0), abs=0.5 / 101.786)
    ser.assert_consumed()
    assert b"?" not in ser.written and b"\x18" not in ser.written and g.referenced is False


def test_flipped_axis_origin_and_acceleration_change_the_bytes():
    cfg = TelemetrixConfig(x=AxisConfig(2, 5, 100.0, flip=True), acceleration=500, origin_mm=(10.0, 0.0),
                           max_speed=4000)
    assert cfg.to_steps(20.0, 5.0) == (-1000, 509) and cfg.to_mm(-1000, 509) == pytest.approx((20.0, 5.0), abs=0.01)
    assert tp.move_to(0, -1000) == H("0722000000" "03e801")          # polarity 1: negative
    assert tp.signed32(H("fffffc18")) == -1000
    ser = TranscriptSerial(OPEN[:3])
    g = TelemetrixGantry(ser, config=cfg, boot_s=0.05, limits_mm=((0.0, 320.0), (0.0, 320.0)))
    g.connect()
    ser.assert_consumed()
    assert g._speeds(60000) == (4000, 4000)          # capped at max_speed
    with pytest.raises(tp.PacketError, match="does not fit the 16-bit field"):
        tp.set_max_speed(0, 70000)


def test_reader_splits_packets_across_reads_and_refuses_length_zero():
    r = tp.PacketReader()
    assert r.feed(H("0611000000")) == [] and r.pending == 5
    assert r.feed(H("0e2302")) == [(17, H("0000000e23"))] and r.pending == 1   # motor 0, then 4 position bytes
    assert r.feed(H("13")) == [] and r.feed(H("01")) == [(19, H("01"))]
    with pytest.raises(tp.PacketError, match="length 0"):
        r.feed(H("00ff"))


def test_emulated_board_with_its_reset_window_and_the_driver_denali_defaults():
    """The board as it comes (bootloader 1.5 s, blink 2 s) and the driver as it comes (4 s, as the client waits)."""
    with EmulatedTelemetrix(time_scale=20.0) as emu:
        t0 = time.monotonic()
        g = TelemetrixGantry(emu.port)
        g.prepare()
        assert 4.0 <= time.monotonic() - t0 < 6.0 and emu.hung is None and emu.lost_bytes == 0
        assert emu.drivers_enabled(8) and g.where().xy_mm == (0.0, 0.0)
        t0 = time.monotonic()
        pos = g.move_to(35.556, 10.0, feed_mm_min=3000)
        took = (time.monotonic() - t0) * 20.0
        # 3619 steps at min(5089, 4000 AccelStepper limit) steps/s = 0.90 s, constant speed
        assert pos.raw["steps"] == [3619, 1018] and 0.85 < took < 0.90 + 1.5
        assert emu.steps() == emu.carriage_steps() == (3619, 1018)
        g.close()
        # the port reopening resets the board: steppers forgotten, counters restart where the carriage stands
        g = TelemetrixGantry(emu.port)
        g.prepare()
        assert g.where().raw["steps"] == [0, 0] and emu.carriage_steps() == (3619, 1018) and emu.resets == 2
        g.move_to(0.0, 0.0)
        assert emu.carriage_steps() == (3619, 1018)      # "the origin" is wherever the reset found the carriage
        g.close()


def test_the_old_connect_fails_against_a_board_that_resets():
    """What the driver did before: the version request the moment the port opened, GRBL's '?' from 3 s on."""
    with EmulatedTelemetrix() as emu:
        ser = serial.Serial(emu.port, 115200, timeout=0)
        try:
            ser.write(tp.firmware_version())                     # lost: the bootloader owns the line
            time.sleep(3.0)
            assert ser.read(64) == b"" and emu.lost_bytes == 2
            ser.write(b"?" + tp.firmware_version())              # waits in the buffer while setup() blinks
            time.sleep(1.2)
            # loop() took '?' (63) as a packet length and the request as its command and first data byte: it waits
            # for 61 more, answers nothing and runs nothing ("no Telemetrix answer within 4 s")
            assert ser.read(64) == b"" and emu.commands == [] and emu.hung is None
            ser.write(tp.firmware_version() * 40)                # the next 80 bytes complete the "packet"
            time.sleep(0.3)
            assert emu.hung.startswith("a packet of 62 data bytes (length byte 63) overran")
            assert ser.read(64) == b""                           # hung until the next reset: nothing answers
        finally:
            ser.close()
        g = TelemetrixGantry(emu.port)                           # the next open resets it; the driver waits it out
        g.prepare()
        assert emu.hung is None and g.firmware == "5.4.4"
        g.close()


def test_firmware_arithmetic_buffer_and_command_table_as_on_the_avr():
    with EmulatedTelemetrix(time_scale=50.0, **QUICK_BOARD) as emu:
        g = TelemetrixGantry(emu.port, **QUICK_DRIVER)
        g.prepare()
        s0 = emu.steppers[0]
        # 16-bit ints: a target of 40,000 (bit 15 set) arrives as -25,536, 32,768 as -32,768; speeds above 32,767
        # arrive negative (AccelStepper keeps the magnitude of a max speed: 65,535 -> 1 step/s)
        g._write(tp.packet(tp.Cmd.STEPPER_MOVE_TO, 0, *tp.magnitude32(40000)))
        g._write(tp.packet(tp.Cmd.STEPPER_MOVE_TO, 1, *tp.magnitude32(32768)))
        g._write(tp.packet(tp.Cmd.STEPPER_SET_MAX_SPEED, 0, 0xFF, 0xFF))
        assert _eventually(lambda: (s0.target, emu.steppers[1].target, s0.max_speed) == (-25536, -32768, 1.0))
        g._write(tp.packet(tp.Cmd.STEPPER_MOVE_TO, 0, *tp.magnitude32(32767)))
        g._write(tp.packet(tp.Cmd.STEPPER_MOVE_TO, 1, *tp.magnitude32(-32767)))
        assert _eventually(lambda: (s0.target, emu.steppers[1].target) == (32767, -32767))   # within +-32,767 as sent
        # the packet builders refuse what the firmware cannot decode
        with pytest.raises(tp.PacketError, match="16-bit AVR int: -32767..32767 steps"):
            tp.move_to(0, 32768)
        with pytest.raises(tp.PacketError, match="an AVR int: 0..32767"):
            tp.set_speed(0, 40000)
        # a command id past the 58-entry table: no answer, ever, until a reset
        g._write(tp.packet(58))
        g._write(tp.get_current_position(0))
        assert _eventually(lambda: "command id 58 is past the firmware's 58-entry command table" in (emu.hung or ""))
        time.sleep(0.2)
        assert emu.queued() == 0                                 # and the position request after it goes unanswered
        g.close()
        g = TelemetrixGantry(emu.port, **QUICK_DRIVER)           # reopening resets it
        g.connect()
        # more than 30 data bytes overrun the command buffer (a GRBL '?' = a 63-byte packet)
        g._write(b"?" + bytes(63))                             # the length, a command byte, 62 data bytes
        assert _eventually(lambda: "62 data bytes (length byte 63) overran the firmware's 30-byte command buffer"
                           in (emu.hung or ""))
        g.close()


def test_bytes_during_the_blink_wait_in_a_63_byte_buffer():
    with EmulatedTelemetrix(boot_s=0.3, blink_s=0.8) as emu:
        ser = serial.Serial(emu.port, 115200, timeout=0)
        try:
            time.sleep(0.5)                                      # past the bootloader, setup() blinks
            ser.write(tp.firmware_version() * 40)                # 80 bytes: 63 fit, 17 are lost
            time.sleep(1.0)
            got = tp.PacketReader().feed(ser.read(4096))
        finally:
            ser.close()
        # 63 bytes = 31 requests and the first byte of a 32nd, which then waits for its command byte
        assert got == [(tp.Report.FIRMWARE, bytes([5, 4, 4]))] * 31 and emu.lost_bytes == 17


def test_relative_moves_as_denali_sends_them_land_where_absolute_targets_do():
    with EmulatedTelemetrix(time_scale=50.0, **QUICK_BOARD) as emu:
        g = TelemetrixGantry(emu.port, **QUICK_DRIVER)
        g.prepare()
        g.move_to(35.556, 71.111)
        here = g.where().raw["steps"]
        # DENALI (cc-hardware StepperMotorSystem.move_to): read positions, STEPPER_MOVE by the difference, the
        # speed, run_speed_to_position; to (0, 35.556) mm = (0, 3619) steps
        for motor, target in enumerate((0, 3619)):
            g._write(tp.move(motor, target - here[motor]))
            g._write(tp.set_speed(motor, 4000))
            g._write(tp.run_speed_to_position(motor))
        for motor in (0, 1):
            g._await(tp.Report.STEPPER_RUN_COMPLETE, "motion-complete", 10.0, motor=motor)
        assert g.where().raw["steps"] == [0, 3619] == list(g.targets(0.0, 35.556))
        g.close()


def test_the_shared_enable_pin_is_driven_enabled_after_prepare():
    with EmulatedTelemetrix(**QUICK_BOARD) as emu:
        g = TelemetrixGantry(emu.port, **QUICK_DRIVER)
        g.connect()
        for motor, ax in enumerate(g.config.axes()):
            g._write(tp.set_pin_mode_stepper(motor, ax.step_pin, ax.dir_pin))
            g._write(tp.set_enable_pin(motor, 8))
            g._write(tp.set_3_pins_inverted(motor, enable=True))
        # setEnablePin wrote HIGH before the inversion was set: the CNC shield's active-low drivers are off
        assert _eventually(lambda: emu.pins.get(8) == 1 and not emu.drivers_enabled(8))
        g.close()
        g = TelemetrixGantry(emu.port, **QUICK_DRIVER)
        g.prepare()
        assert emu.pins[8] == 0 and emu.drivers_enabled(8) and g.moves == 0
        g.close()


def test_limits_and_speeds_beyond_the_firmware_are_refused_before_the_port_opens(tmp_path):
    with pytest.raises(UserError, match=r"^gantry limit x = 400 mm is 40,714 steps from origin_mm 0 mm; "
                                        r"Telemetrix4Arduino decodes step targets as 16-bit AVR ints \(\+-32,767 "
                                        r"steps = x -321.9..321.9 mm"):
        TelemetrixGantry("/dev/nonexistent-port", limits_mm=((0.0, 400.0), (0.0, 320.0)))
    # an origin in the middle reaches the other way
    cfg = TelemetrixConfig(origin_mm=(200.0, 0.0))
    cfg.check_reach(((0.0, 500.0), (0.0, 320.0)))
    with pytest.raises(UserError, match="gantry limit y = -330 mm"):
        cfg.check_reach(((0.0, 500.0), (-330.0, 320.0)))
    bad = tmp_path / "fast.toml"
    bad.write_text("[telemetrix]\nmax_speed = 40000\n")
    with pytest.raises(UserError, match=r"max_speed = 40000 .* must be an integer 1..32767 steps/s: "
                                        r"Telemetrix4Arduino reads it as a 16-bit AVR int"):
        load_rig_file(bad)
    with pytest.raises(UserError, match="acceleration = 40000 .* 0..32767"):
        TelemetrixConfig(acceleration=40000)


def test_a_target_beyond_the_steps_is_refused_and_nothing_is_sent():
    ser = TranscriptSerial(OPEN)
    g = TelemetrixGantry(ser, boot_s=0.05, limits_mm=((0.0, 320.0), (0.0, 320.0)))
    g.prepare()
    g.limits_mm = ((0.0, 400.0), (0.0, 320.0))       # as if the limits had not been checked
    with pytest.raises(LimitError, match=r"is 33,589 steps on x; Telemetrix4Arduino decodes step targets as 16-bit "
                                         r"AVR ints \(\+-32,767 steps\); nothing was sent"):
        g.move_to(330.0, 0.0)
    ser.assert_consumed()


def test_rig_file_defaults_are_denali_and_bad_values_are_one_line(tmp_path):
    cfg = load_rig_file(DEFAULT_RIG_FILE)
    assert cfg.x == TelemetrixConfig().x and cfg.y == TelemetrixConfig().y and cfg.max_speed == 32767
    assert (cfg.enable_pin, cfg.enable_inverted, cfg.acceleration, cfg.origin_mm) == (8, True, 0, (0.0, 0.0))
    assert cfg.x.steps_per_mm == DENALI_STEPS_PER_MM == pytest.approx(101.7857, abs=1e-4)   # 2850 steps / 28 mm
    assert cfg.reach_mm()[0] == pytest.approx((-321.92, 321.92), abs=0.01)
    bad = tmp_path / "bad.toml"
    for text, message in [
        ("[telemetrix.x]\nsteps_per_mm = 0\n", "telemetrix x.steps_per_mm = 0 in .*bad.toml must be > 0"),
        ("[telemetrix.y]\nsteps_per_mm = -101.8\n", "y.steps_per_mm = -101.8 .* must be > 0"),
        ("[telemetrix]\nmax_speed = 70000\n", "max_speed = 70000 .* 1..32767"),
        ("[telemetrix]\nspeed = 3\n", r"unknown key\(s\) speed in \[telemetrix\]"),
        ("[grbl]\nx = 1\n", r"unknown table\(s\) grbl"),
        ("[telemetrix\n", "is not valid TOML"),
    ]:
        bad.write_text(text)
        with pytest.raises(UserError, match=message):
            load_rig_file(bad)
    with pytest.raises(UserError, match="does not exist"):
        load_rig_file(tmp_path / "none.toml")


def test_auto_tells_grbl_from_telemetrix_without_sending_grbl_bytes_to_telemetrix():
    with EmulatedTelemetrix() as tmx, EmulatedGrbl() as grbl:
        t0 = time.monotonic()
        assert detect_gantry_kind(grbl.port) == "grbl" and time.monotonic() - t0 < 1.0   # its banner, at once
        assert detect_gantry_kind(tmx.port) == "telemetrix"
        assert tmx.hung is None and tmx.lost_bytes == 0
        assert {k for k, _ in tmx.commands} == {tp.Cmd.GET_FIRMWARE_VERSION}              # nothing else reached it
        with pytest.raises(WrongFirmware, match=r"runs GRBL \((Grbl 1.1h|<Idle).*\), not Telemetrix4Arduino: use "
                                                r"--gantry-kind grbl"):
            TelemetrixGantry(grbl.port, **QUICK_DRIVER).prepare()
        with pytest.raises(UserError, match="--home and --unlock are GRBL's"):
            TelemetrixGantry(tmx.port).prepare(home=True)
    from nlosplan.hardware.grbl import Grbl

    # the GRBL driver (the user said GRBL) names a Telemetrix board that keeps running across the open ...
    with EmulatedTelemetrix(reset_on_open=False) as tmx:
        with pytest.raises(WrongFirmware, match="runs Telemetrix4Arduino 5.4.4, not GRBL"):
            Grbl(tmx.port).prepare()
    # ... and says where to look when one resets (its request was lost, and GRBL's '?' hangs it)
    with EmulatedTelemetrix(**QUICK_BOARD) as tmx:
        with pytest.raises(DeviceTimeout, match="a Telemetrix4Arduino board that reset as the port opened answers "
                                                "no GRBL request: --gantry-kind telemetrix or auto"):
            Grbl(tmx.port).prepare()
