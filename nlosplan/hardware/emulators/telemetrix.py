"""An emulated Telemetrix4Arduino board with steppers (DENALI's gantry) on a pty.

The byte protocol of :mod:`~nlosplan.hardware.telemetrix_protocol`, as the
firmware (5.4.4) handles it:

- ``get_next_command`` reads a length byte and then waits for that many
  bytes, whatever they are (a GRBL ``?`` = 63 swallows the next 63 bytes);
- opening the port resets the board (DTR): steppers forgotten, positions 0,
  and nothing is read for ``boot_s`` (the 2 s LED blink; bytes wait);
- steppers follow AccelStepper: max speed 1 step/s until set, ``move_to``
  recomputes the speed (about 1 step/s from rest, so a host sets the speed
  after it), ``set_speed`` is clamped to the max speed,
  ``run_speed_to_position`` moves at constant speed, ``run`` with the
  acceleration ramps; either reports motion complete once at the target;
  motion runs only while reports are enabled (as ``run_steppers`` in ``loop``);
- the step rate is capped at ``step_rate_limit`` (AccelStepper's ~4000 steps/s
  on a 16 MHz AVR).

Not emulated: pins other than steppers (digital/analog reports, servos, I2C,
SPI, sonar, DHT), ``STEPPER_SET_CURRENT_POSITION`` (buggy in 5.4.4).
"""

from __future__ import annotations

import threading
import time

from nlosplan.hardware import telemetrix_protocol as tp
from nlosplan.hardware.emulators.motion import Segment
from nlosplan.hardware.emulators.pty import PtyDevice

__all__ = ["EmulatedTelemetrix"]

FIRMWARE_VERSION = (5, 4, 4)
ALL_FEATURES = 0x7F


class _Stepper:
    def __init__(self, step_pin: int, dir_pin: int) -> None:
        self.pins = (step_pin, dir_pin)
        self.enable_pin, self.inverted = None, (0, 0, 0)
        self.max_speed, self.speed, self.accel = 1.0, 0.0, 1.0
        self.position, self.target = 0, 0
        self.mode = None            # None (stopped), "run", "rstp" (run speed to position)
        self.seg: Segment | None = None


class EmulatedTelemetrix(PtyDevice):
    """Telemetrix4Arduino on a pty (use :attr:`port` as the gantry port).

    Parameters
    ----------
    time_scale : float
        Motion runs this many times faster than real time.
    boot_s : float
        Seconds after the port opens before commands are read (the firmware's blink: 2 s).
    step_rate_limit : float
        Most steps per second a stepper makes.
    features : int
        The features byte (0x04: steppers).
    reset_on_open : bool
        Opening the port resets the board (an Arduino's DTR reset).
    """

    def __init__(self, *, time_scale: float = 1.0, boot_s: float = 0.05, step_rate_limit: float = 4000.0,
                 features: int = ALL_FEATURES, reset_on_open: bool = True) -> None:
        super().__init__("gantry")
        self.time_scale, self.boot_s, self.step_rate_limit = float(time_scale), boot_s, float(step_rate_limit)
        self.features, self.reset_on_open = features, reset_on_open
        self._lock_ = threading.RLock()
        self._rx = bytearray()
        self._boot_until = 0.0
        self.steppers: dict[int, _Stepper] = {}
        self.reports_on = True
        self.commands: list[tuple[int, bytes]] = []

    def _now(self) -> float:
        return time.monotonic() * self.time_scale

    def steps(self) -> tuple[int, int]:
        """Current positions of motors 0 and 1 in steps (thread-safe; 0 for a motor not created)."""
        with self._lock_:
            self._advance(self._now())
            return tuple(self.steppers[m].position if m in self.steppers else 0 for m in (0, 1))

    # ------------------------------------------------------------------ pty hooks
    def on_open(self) -> None:
        if not self.reset_on_open:
            return
        with self._lock_:
            self.steppers.clear()
            self.reports_on = True
            self._rx.clear()
            self._boot_until = time.monotonic() + self.boot_s
        self.drop_output()

    def on_bytes(self, data: bytes) -> None:
        with self._lock_:
            self._rx += data
            if time.monotonic() >= self._boot_until:
                self._process()

    def tick(self, now: float) -> None:
        with self._lock_:
            if self._rx and now >= self._boot_until:
                self._process()
            self._advance(self._now())

    # ------------------------------------------------------------------ commands
    def _process(self) -> None:
        while self._rx:
            n = self._rx[0]
            if len(self._rx) < n + 1 or n == 0:
                if n == 0:
                    del self._rx[:1]
                    continue
                return   # the firmware waits for the rest of the packet
            kind, data = (self._rx[1], bytes(self._rx[2:n + 1])) if n >= 1 else (None, b"")
            del self._rx[:n + 1]
            self.commands.append((kind, data))
            self._command(kind, data)

    def _report(self, kind: int, *data: int) -> None:
        self.send(bytes([1 + len(data), kind, *data]))

    def _command(self, kind: int, d: bytes) -> None:
        C = tp.Cmd
        if kind == C.GET_FIRMWARE_VERSION:
            self._report(tp.Report.FIRMWARE, *FIRMWARE_VERSION)
        elif kind == C.ARE_U_THERE:
            self._report(tp.Report.I_AM_HERE, 1)
        elif kind == C.GET_FEATURES:
            self._report(tp.Report.FEATURES, self.features)
        elif kind in (C.ENABLE_ALL_REPORTS, C.RESET):
            self.reports_on = True
        elif kind == 15:   # STOP_ALL_REPORTS
            self.reports_on = False
        elif not self.features & tp.STEPPERS_FEATURE:
            return
        elif kind == C.SET_PIN_MODE_STEPPER and len(d) >= 7:
            self.steppers[d[0]] = _Stepper(d[2], d[3])
        elif d and d[0] in self.steppers:
            self._stepper_command(kind, self.steppers[d[0]], d)

    def _stepper_command(self, kind: int, s: _Stepper, d: bytes) -> None:
        C, now = tp.Cmd, self._now()
        self._advance(now)
        if kind == C.STEPPER_MOVE_TO and len(d) >= 6:
            value = int.from_bytes(d[1:5], "big")
            s.target = -value if d[5] else value
            s.speed = min(1.0, s.max_speed)   # AccelStepper's moveTo recomputes the speed: ~1 step/s from rest
        elif kind == C.STEPPER_SET_MAX_SPEED and len(d) >= 3:
            s.max_speed = float((d[1] << 8) + d[2])
        elif kind == C.STEPPER_SET_ACCELERATION and len(d) >= 3:
            s.accel = float((d[1] << 8) + d[2])
        elif kind == C.STEPPER_SET_SPEED and len(d) >= 4:
            v = float((d[1] << 8) + d[2]) * (-1 if d[3] == 1 else 1)
            s.speed = max(-s.max_speed, min(s.max_speed, v))
        elif kind in (C.STEPPER_RUN, C.STEPPER_RUN_SPEED_TO_POSITION):
            s.mode = "run" if kind == C.STEPPER_RUN else "rstp"
            self._start(s, now)
        elif kind == C.STEPPER_STOP:
            s.mode, s.seg = None, None
        elif kind == C.STEPPER_SET_ENABLE_PIN and len(d) >= 2:
            s.enable_pin = d[1]
        elif kind == C.STEPPER_SET_3_PINS_INVERTED and len(d) >= 4:
            s.inverted = (d[1], d[2], d[3])
        elif kind == C.STEPPER_IS_RUNNING:
            self._report(tp.Report.STEPPER_RUNNING, d[0], int(s.seg is not None))
        elif kind == C.STEPPER_GET_CURRENT_POSITION:
            self._report(tp.Report.STEPPER_CURRENT_POSITION, d[0], *s.position.to_bytes(4, "big", signed=True))

    # ------------------------------------------------------------------ motion
    def _start(self, s: _Stepper, now: float) -> None:
        if s.mode == "run":
            v, a = min(s.max_speed, self.step_rate_limit), s.accel
        else:
            v, a = min(abs(s.speed), self.step_rate_limit), 0.0
        s.seg = Segment((float(s.position),), (float(s.target),), now, v, a) if v > 0 else None

    def _advance(self, now: float) -> None:
        if not self.reports_on:
            return   # run_steppers() is skipped while reports are stopped
        for motor, s in self.steppers.items():
            if s.mode is None:
                continue
            if s.seg is not None:
                s.position = round(s.seg.position(now)[0])
            if s.position == s.target or (s.seg is not None and s.seg.done(now)):
                s.position = s.target if s.seg is not None or s.position == s.target else s.position
                s.mode, s.seg = None, None
                self._report(tp.Report.STEPPER_RUN_COMPLETE, motor)
