"""Telemetrix gantry driver: two steppers on an Arduino CNC shield running Telemetrix4Arduino (DENALI's rig).

A thin protocol class of our own over the injected transport
(:mod:`~nlosplan.hardware.telemetrix_protocol` has the byte layout), not the
``telemetrix`` client: that client opens the port itself by name
(``serial.Serial``: no open serial object, no pyserial URL, so no transcript
tests), prints to stdout, runs two threads that poll with 1 us sleeps, and
upstream (1.46) refuses a stepper max speed above 1000 steps/s, while DENALI
sets 32767 -- DENALI installs the fork AaronYoung5/telemetrix, which drops
that check (its ``capture/pkgs/drivers/pyproject.toml``).

Connecting, as the real client does: opening the port resets the board, and
for about 1-2 s its bootloader loses whatever arrives. The client sends
nothing for ``arduino_wait = 4`` s (DENALI keeps 4); this driver waits the
same ``boot_s`` before its first firmware-version request, then repeats it
every 0.5 s until the board answers (bytes sent while the sketch still
blinks wait in its receive buffer). It never sends GRBL's bytes (``?``,
0x18): Telemetrix4Arduino would take ``?`` as a 63-byte packet and hang.

Set-up, as DENALI's cc-hardware does: one step/dir stepper per axis (the
rig file's pins, the shield's enable pin, enable inverted), the max speed;
then, unlike a bare set-up, both drivers are enabled (``STEPPER_ENABLE_OUTPUTS``:
``set_enable_pin`` drove the shared enable pin to "disabled" before the
inversion was set; DENALI's start-up zero move enables them the same way).

Moving: DENALI's ``StepperMotorSystem.move_to`` reads both positions, sends
the difference as a relative ``STEPPER_MOVE`` (cm to steps, truncated), the
speed and ``run_speed_to_position``. This driver sends the absolute target in
steps (``STEPPER_MOVE_TO``) instead: the same steps from the same origin, but
no round trip through centimetres and no read before each move, and a
command that arrives twice cannot move twice. Then the speed (``set_speed``,
after ``move_to``, which recomputes it) and ``run_speed_to_position``
(constant speed) -- or, with an acceleration in the rig file,
``set_acceleration`` and ``run`` -- for both axes; it waits for both
motion-complete reports and reads both positions back. Every target and
speed is checked against the firmware's 16-bit arithmetic first (+-32,767
steps, 32,767 steps/s): beyond, the board would drive somewhere else.
Positions count in steps from the board's last reset; the rig file's
``origin_mm`` is the user-frame position of that point.
"""

from __future__ import annotations

import math
import time

from nlosplan.errors import UserError
from nlosplan.hardware import telemetrix_protocol as tp
from nlosplan.hardware.gantry import BOOT_WAIT_S, GantryPosition, WrongFirmware, check_box, probe_firmware
from nlosplan.hardware.telemetrix_config import TelemetrixConfig
from nlosplan.hardware.transport import ConnectionLost, DeviceTimeout, close_serial, open_serial

__all__ = ["TelemetrixError", "TelemetrixGantry"]


class TelemetrixError(RuntimeError):
    """The Telemetrix board did not do what it was asked (no report, out-of-step stream, missed target)."""


class TelemetrixGantry:
    """An XY gantry of two steppers on Telemetrix4Arduino.

    Parameters
    ----------
    port : str or serial object
    config : TelemetrixConfig, optional
        Pins, steps per mm, speed, acceleration, flips, origin (default: DENALI's).
    limits_mm : ((xmin, xmax), (ymin, ymax))
        Limits in the user frame, checked before every move (mm).
    feed_mm_min : float
        Move speed (mm/min), converted to steps/s per axis and capped at the rig file's ``max_speed``.
    timeout : float
        Seconds to wait for an answer to a request.
    boot_s : float
        Seconds to send nothing after opening the port (the board resets; the telemetrix client's 4 s).
    answer_s : float
        Seconds after ``boot_s`` to keep asking for the firmware version (the sketch blinks 2 s after its reset).
    move_timeout : float
        Most seconds one move may take.

    Raises
    ------
    UserError
        Limits or speeds the firmware cannot represent (before the port is opened).
    """

    kind = "telemetrix"
    #: Positions count from where the carriage stood when the port opened (no switches, no homing).
    referenced = False

    def __init__(self, port, *, config: TelemetrixConfig | None = None, limits_mm=((0.0, 320.0), (0.0, 320.0)),
                 feed_mm_min: float = 3000.0, timeout: float = 2.0, boot_s: float = BOOT_WAIT_S,
                 answer_s: float = 3.0, move_timeout: float = 300.0) -> None:
        (x0, x1), (y0, y1) = limits_mm
        if not all(math.isfinite(v) for v in (x0, x1, y0, y1)) or not (x0 < x1 and y0 < y1):
            raise UserError(f"gantry limits {limits_mm!r} must be finite (min, max) pairs with min < max")
        if not (math.isfinite(feed_mm_min) and feed_mm_min > 0):
            raise UserError(f"feed rate {feed_mm_min!r} mm/min must be > 0")
        self.config = config or TelemetrixConfig()
        self.limits_mm = ((float(x0), float(x1)), (float(y0), float(y1)))
        self.config.check_reach(self.limits_mm)
        self.feed_mm_min = float(feed_mm_min)
        self.timeout, self.boot_s, self.answer_s, self.move_timeout = timeout, boot_s, answer_s, move_timeout
        self.port_name = port if isinstance(port, str) else getattr(port, "port", None) or repr(port)
        self._ser, self._owned = open_serial(port, 115200)
        self._packets = tp.PacketReader()
        self._inbox: list[tuple[int, bytes]] = []
        self.firmware: str | None = None
        self.features: int | None = None
        self.steps: tuple[int, int] | None = None
        self.last_xy: tuple | None = None
        self.moves = 0

    # ------------------------------------------------------------------ link
    def _write(self, data: bytes) -> None:
        import serial

        try:
            self._ser.write(data)
            self._ser.flush()
        except (serial.SerialException, OSError) as exc:
            raise ConnectionLost(f"gantry on {self.port_name}: serial link lost: {exc}") from None

    def _read_packets(self) -> None:
        import serial

        try:
            waiting = getattr(self._ser, "in_waiting", 0) or 1
            data = self._ser.read(min(max(waiting, 1), 4096))
        except (serial.SerialException, OSError) as exc:
            raise ConnectionLost(f"gantry on {self.port_name}: serial link lost: {exc}") from None
        if data:
            try:
                self._inbox += self._packets.feed(data)
            except tp.PacketError as exc:
                raise TelemetrixError(f"gantry on {self.port_name}: {exc}") from None
        else:
            time.sleep(0.002)

    def _await(self, kind: int, what: str, timeout: float | None = None, motor: int | None = None) -> bytes:
        """The data of the next report of type ``kind`` (for ``motor``), reports of other types kept."""
        deadline = time.monotonic() + (self.timeout if timeout is None else timeout)
        while True:
            for i, (k, data) in enumerate(self._inbox):
                if k == kind and (motor is None or (data and data[0] == motor)):
                    del self._inbox[i]
                    return data
            if time.monotonic() > deadline:
                raise DeviceTimeout(f"gantry on {self.port_name}: no Telemetrix {what} report within "
                                    f"{self.timeout if timeout is None else timeout:g} s")
            self._read_packets()

    # ------------------------------------------------------------------ session
    def connect(self) -> str:
        """Find Telemetrix4Arduino on the port; returns its version (``major.minor.patch``).

        Sends nothing for ``boot_s`` (the board resets as the port opens), then the firmware-version request
        every 0.5 s until it answers or ``answer_s`` pass; never a GRBL byte.

        Raises
        ------
        WrongFirmware
            GRBL (or bytes of no known firmware) answers; or the firmware lacks stepper support.
        DeviceTimeout
            Nothing answers.
        """
        waited = self.boot_s + self.answer_s
        found = probe_firmware(self._ser, timeout=waited, quiet_s=self.boot_s, query_every_s=0.5, grbl_after_s=None)
        if found.kind == "grbl":
            raise WrongFirmware(f"gantry on {self.port_name} runs GRBL ({found.text}), not Telemetrix4Arduino: use "
                                "--gantry-kind grbl (or auto)")
        if found.kind is None:
            if found.seen:
                raise WrongFirmware(f"gantry on {self.port_name} answers, but not like Telemetrix4Arduino "
                                    f"({found.describe_seen()}): another firmware, or not 115200 baud")
            raise DeviceTimeout(f"no Telemetrix answer from {self.port_name} within {waited:g} s (sent nothing for "
                                f"{self.boot_s:g} s while the board reset, then asked for its firmware version "
                                "every 0.5 s): is this the gantry's port, powered, and flashed with "
                                "Telemetrix4Arduino?")
        self.firmware = found.text
        try:
            self._inbox += self._packets.feed(found.rest)
        except tp.PacketError as exc:
            raise TelemetrixError(f"gantry on {self.port_name}: {exc}") from None
        self._write(tp.enable_all_reports())
        self._write(tp.get_features())
        self.features = self._await(tp.Report.FEATURES, "features")[0]
        # answers to the repeated version requests that waited in the board's buffer
        self._inbox = [pkt for pkt in self._inbox if pkt[0] != tp.Report.FIRMWARE]
        if not self.features & tp.STEPPERS_FEATURE:
            raise WrongFirmware(f"Telemetrix4Arduino {self.firmware} on {self.port_name} was built without stepper "
                                "support (STEPPERS_ENABLED): flash the stock sketch")
        return self.firmware

    def prepare(self, *, home: bool = False, unlock: bool = False) -> None:
        """Connect, create both steppers, enable their drivers, read where they are.

        Raises
        ------
        UserError
            ``home`` or ``unlock`` (GRBL's; a Telemetrix gantry has neither switches nor alarms).
        """
        if home or unlock:
            raise UserError("--home and --unlock are GRBL's; a Telemetrix gantry has no limit switches and no alarm "
                            "lock (its position 0 is where the carriage was when the board reset)")
        self.connect()
        cfg = self.config
        for motor, ax in enumerate(cfg.axes()):
            self._write(tp.set_pin_mode_stepper(motor, ax.step_pin, ax.dir_pin))
            self._write(tp.set_enable_pin(motor, cfg.enable_pin))   # drives the pin "disabled": not inverted yet
            self._write(tp.set_3_pins_inverted(motor, enable=cfg.enable_inverted))
            self._write(tp.set_max_speed(motor, cfg.max_speed))
            if cfg.acceleration:
                self._write(tp.set_acceleration(motor, cfg.acceleration))
        for motor in (0, 1):   # the shared enable pin: drive it to "enabled" (holding torque from now on)
            self._write(tp.enable_outputs(motor))
        self.where()

    # ------------------------------------------------------------------ motion
    def check_limits(self, x_mm: float, y_mm: float) -> None:
        """Raise :class:`~nlosplan.hardware.gantry.LimitError` when (x, y) mm is outside the limits."""
        check_box(self.limits_mm, x_mm, y_mm)

    def origin_xy(self) -> tuple[float, float]:
        """The user-frame position the step counters call 0 after a reset (the rig file's ``origin_mm``)."""
        return float(self.config.origin_mm[0]), float(self.config.origin_mm[1])

    def targets(self, x_mm: float, y_mm: float) -> tuple[int, int]:
        """Step targets of motors 0 (x) and 1 (y) for (x, y) mm, checked against the firmware's 16-bit range.

        Raises
        ------
        LimitError
            A target beyond +-32,767 steps (the firmware would drive elsewhere).
        """
        return self.config.checked_steps(x_mm, y_mm)

    def _speeds(self, feed_mm_min: float) -> tuple[int, int]:
        return tuple(max(1, min(self.config.max_speed, round(feed_mm_min / 60.0 * ax.steps_per_mm)))
                     for ax in self.config.axes())

    def move_to(self, x_mm: float, y_mm: float, *, feed_mm_min: float | None = None) -> GantryPosition:
        """Move both axes to (x, y) mm in the user frame (absolute step targets) and wait for both to arrive.

        Raises
        ------
        LimitError, TelemetrixError, DeviceTimeout, ConnectionLost
        """
        x, y = float(x_mm), float(y_mm)
        self.check_limits(x, y)
        feed = self.feed_mm_min if feed_mm_min is None else float(feed_mm_min)
        if not (math.isfinite(feed) and feed > 0):
            raise UserError(f"feed rate {feed_mm_min!r} mm/min must be > 0")
        targets = self.targets(x, y)
        speeds = self._speeds(feed)
        here = self.steps or (0, 0)
        self._inbox = [p for p in self._inbox if p[0] != tp.Report.STEPPER_RUN_COMPLETE]
        for motor, (t, v) in enumerate(zip(targets, speeds)):
            self._write(tp.move_to(motor, t))
            if self.config.acceleration:
                self._write(tp.set_max_speed(motor, v))
                self._write(tp.run(motor))
            else:
                self._write(tp.set_speed(motor, v))   # after move_to, which recomputes the speed
                self._write(tp.run_speed_to_position(motor))
        slowest = max(abs(t - h) / min(v, 4000) for t, h, v in zip(targets, here, speeds))
        timeout = min(self.move_timeout, 5.0 + 2.0 * slowest)
        for motor, name in enumerate("xy"):
            self._await(tp.Report.STEPPER_RUN_COMPLETE, f"motion-complete ({name} axis)", timeout, motor=motor)
        self.moves += 1
        pos = self.where()
        if self.steps != targets:
            raise TelemetrixError(f"gantry on {self.port_name} stopped at {self.steps} steps, target {targets} "
                                  f"(({x:.3f}, {y:.3f}) mm)")
        return pos

    def where(self) -> GantryPosition:
        """Both stepper positions, in the user frame (and raw steps)."""
        steps = []
        for motor in (0, 1):
            self._write(tp.get_current_position(motor))
            data = self._await(tp.Report.STEPPER_CURRENT_POSITION, "current-position", motor=motor)
            steps.append(tp.signed32(data[1:5]))
        self.steps = (steps[0], steps[1])
        x, y = self.config.to_mm(*self.steps)
        self.last_xy = (round(x, 4), round(y, 4))
        return GantryPosition(self.last_xy, {"steps": list(self.steps)}, "Idle")

    def blocked(self) -> str | None:
        """Telemetrix has no alarm state: never blocked."""
        return None

    def describe(self) -> dict:
        """Port, firmware, rig file values (stored with every capture)."""
        return {"kind": "telemetrix", "port": self.port_name, "firmware": self.firmware, "features": self.features,
                "boot_wait_s": self.boot_s, "moves": "absolute (STEPPER_MOVE_TO)", "feed_mm_min": self.feed_mm_min, "limits_mm": [list(v) for v in self.limits_mm],
                "step_mm": [1.0 / ax.steps_per_mm for ax in self.config.axes()], **self.config.describe()}

    def close(self) -> None:
        """Close the port (if this driver opened it); the steppers stay enabled (holding torque)."""
        close_serial(self._ser, self._owned)
        if self._owned:
            self._ser = None

    def __enter__(self) -> "TelemetrixGantry":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
