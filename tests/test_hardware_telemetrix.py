"""Telemetrix gantry: the driver against transcripts written from Telemetrix4Arduino's byte layout, the pty
emulator, the rig file, and telling GRBL from Telemetrix."""

import time

import pytest

from nlosplan.errors import UserError
from nlosplan.hardware import telemetrix_protocol as tp
from nlosplan.hardware.emulators import EmulatedGrbl, EmulatedTelemetrix
from nlosplan.hardware.gantry import WrongFirmware
from nlosplan.hardware.rig import detect_gantry_kind
from nlosplan.hardware.telemetrix import TelemetrixGantry
from nlosplan.hardware.telemetrix_config import (DEFAULT_RIG_FILE, DENALI_STEPS_PER_MM, AxisConfig,
                                                 TelemetrixConfig, load_rig_file)
from nlosplan.hardware.transcript import TranscriptSerial

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
    (H("023300"), H("061100" "00000000")),  # STEPPER_GET_CURRENT_POSITION (51) -> report 17: motor 0 at 0 steps
    (H("023301"), H("061101" "00000000")),
]


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
    g = TelemetrixGantry(ser, boot_s=0.5)
    g.prepare()
    assert (g.firmware, g.features, g.steps) == ("5.4.4", 0x7F, (0, 0))
    pos = g.move_to(35.556, 10.0, feed_mm_min=3000)
    assert pos.raw == {"steps": [3619, 1018]} and pos.xy_mm == pytest.approx((35.556, 10.0), abs=0.5 / 101.786)
    ser.assert_consumed()


def test_flipped_axis_origin_and_acceleration_change_the_bytes():
    cfg = TelemetrixConfig(x=AxisConfig(2, 5, 100.0, flip=True), acceleration=500, origin_mm=(10.0, 0.0),
                           max_speed=4000)
    assert cfg.to_steps(20.0, 5.0) == (-1000, 509) and cfg.to_mm(-1000, 509) == pytest.approx((20.0, 5.0), abs=0.01)
    assert tp.move_to(0, -1000) == H("0722000000" "03e801")          # polarity 1: negative
    assert tp.signed32(H("fffffc18")) == -1000
    ser = TranscriptSerial(OPEN[:3])
    g = TelemetrixGantry(ser, config=cfg, boot_s=0.5)
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


def test_emulated_board_with_the_driver_denali_defaults():
    with EmulatedTelemetrix(time_scale=20.0) as emu:
        g = TelemetrixGantry(emu.port, boot_s=1.0)
        g.prepare()
        assert g.where().xy_mm == (0.0, 0.0)
        t0 = time.monotonic()
        pos = g.move_to(35.556, 10.0, feed_mm_min=3000)
        took = (time.monotonic() - t0) * 20.0
        # 3619 steps at min(5089, 4000 AccelStepper limit) steps/s = 0.90 s, constant speed
        assert pos.raw["steps"] == [3619, 1018] and 0.85 < took < 0.90 + 1.5
        assert emu.steps() == (3619, 1018) and g.move_to(0.0, 0.0).raw["steps"] == [0, 0]
        g.close()
        # the port reopening resets the board: steppers forgotten, the origin is where the carriage is now
        g = TelemetrixGantry(emu.port, boot_s=1.0)
        g.prepare()
        assert g.where().raw["steps"] == [0, 0]
        g.close()


def test_emulated_board_follows_accelstepper_and_the_firmware_framing():
    with EmulatedTelemetrix(time_scale=50.0) as emu:
        g = TelemetrixGantry(emu.port, boot_s=1.0)
        g.connect()
        g._write(tp.set_pin_mode_stepper(0, 2, 5))
        g._write(tp.set_speed(0, 3000))            # clamped to the max speed, 1 step/s until it is set
        g._write(tp.set_max_speed(0, 4000))
        time.sleep(0.05)
        assert emu.steppers[0].speed == 1.0 and emu.steppers[0].max_speed == 4000.0
        g._write(b"?")                              # a GRBL status request: a 63-byte packet to this firmware
        g._write(tp.get_current_position(0))
        time.sleep(0.1)
        assert emu.queued() == 0 and len(emu._rx) == 4   # still waiting for the rest of the "packet"
        g.close()


def test_rig_file_defaults_are_denali_and_bad_values_are_one_line(tmp_path):
    cfg = load_rig_file(DEFAULT_RIG_FILE)
    assert cfg.x == TelemetrixConfig().x and cfg.y == TelemetrixConfig().y and cfg.max_speed == 32767
    assert (cfg.enable_pin, cfg.enable_inverted, cfg.acceleration, cfg.origin_mm) == (8, True, 0, (0.0, 0.0))
    assert cfg.x.steps_per_mm == DENALI_STEPS_PER_MM == pytest.approx(101.7857, abs=1e-4)   # 2850 steps / 28 mm
    bad = tmp_path / "bad.toml"
    for text, message in [
        ("[telemetrix.x]\nsteps_per_mm = 0\n", "telemetrix x.steps_per_mm = 0 in .*bad.toml must be > 0"),
        ("[telemetrix.y]\nsteps_per_mm = -101.8\n", "y.steps_per_mm = -101.8 .* must be > 0"),
        ("[telemetrix]\nmax_speed = 70000\n", "max_speed = 70000 .* 1..65535"),
        ("[telemetrix]\nspeed = 3\n", r"unknown key\(s\) speed in \[telemetrix\]"),
        ("[grbl]\nx = 1\n", r"unknown table\(s\) grbl"),
        ("[telemetrix\n", "is not valid TOML"),
    ]:
        bad.write_text(text)
        with pytest.raises(UserError, match=message):
            load_rig_file(bad)
    with pytest.raises(UserError, match="does not exist"):
        load_rig_file(tmp_path / "none.toml")


def test_auto_tells_grbl_from_telemetrix_and_each_driver_names_the_other():
    with EmulatedTelemetrix() as tmx, EmulatedGrbl() as grbl:
        assert detect_gantry_kind(tmx.port) == "telemetrix" and detect_gantry_kind(grbl.port) == "grbl"
        with pytest.raises(WrongFirmware, match=r"runs GRBL \((Grbl 1.1h|<Idle).*\), not Telemetrix4Arduino: use --gantry-kind grbl"):
            TelemetrixGantry(grbl.port, boot_s=0.5).prepare()
        from nlosplan.hardware.grbl import Grbl

        with pytest.raises(WrongFirmware, match="runs Telemetrix4Arduino 5.4.4, not GRBL"):
            Grbl(tmx.port).prepare()
        with pytest.raises(UserError, match="--home and --unlock are GRBL's"):
            TelemetrixGantry(tmx.port).prepare(home=True)
