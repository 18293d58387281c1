"""An emulated Telemetrix4Arduino board with steppers (DENALI's gantry) on a pty, as a real Uno behaves.

The byte protocol of :mod:`~nlosplan.hardware.telemetrix_protocol`, as the
firmware (5.4.4) and the board handle it:

- **The reset when the port opens** (an Uno's DTR): for ``boot_s`` seconds
  the bootloader owns the serial line and what arrives is lost; then the
  sketch's ``setup()`` blinks the LED for 2 s (``blink_s``) with the serial
  port open, so what arrives waits in the core's 64-byte ring buffer (63
  bytes fit; more are lost) and is read when ``loop()`` starts. Steppers
  are forgotten and every step counter restarts at 0 -- where the carriage
  stands (:meth:`EmulatedTelemetrix.carriage_steps` keeps the carriage's
  place across resets; :meth:`EmulatedTelemetrix.steps` are the counters).
- ``get_next_command`` reads a length byte, a command byte, then length - 1
  data bytes into a 30-byte buffer, whatever they are, and calls
  ``command_table[command]`` with no bounds check. More than 30 data bytes
  overrun the buffer (a GRBL ``?`` = 63 as a length brings 62), a command
  id past the table's 58 entries jumps through a stray pointer: both are
  modelled as a **hung** board (:attr:`EmulatedTelemetrix.hung` says why)
  that answers nothing until the next reset. A length of 0 still reads its
  command byte.
- **AVR arithmetic**: ``int`` is 16 bits. A step target's low two bytes are
  added as ``command_buffer[3] << 8`` (an ``int``), so a magnitude with bit
  15 set arrives 65,536 too small (32,768 -> -32,768; 40,000 -> -25,536);
  speeds and accelerations ``(msb << 8) + lsb`` above 32,767 arrive
  negative (AccelStepper takes the magnitude of a max speed and an
  acceleration: 65,535 -> 1 step/s).
- Steppers follow AccelStepper: max speed 1 step/s until set, ``moveTo``
  (and ``move``, relative) recomputes the speed (about 1 step/s from rest,
  so a host sets the speed after it), ``set_speed`` is clamped to the max
  speed, ``run_speed_to_position`` moves at constant speed, ``run`` with
  the acceleration ramps; either reports motion complete once at the
  target; motion runs only while reports are enabled (``run_steppers`` in
  ``loop``), and each pass drives the enable pin to "enabled"
  (``enableOutputs``). ``set_enable_pin`` drives it at once with the
  inversion set *so far* (``HIGH`` before ``set_3_pins_inverted``: a CNC
  shield's drivers stay disabled), ``stop`` disables.
- The step rate is capped at ``step_rate_limit`` (AccelStepper's ~4000
  steps/s on a 16 MHz AVR).

Not emulated: pins other than steppers (digital/analog reports, servos, I2C,
SPI, sonar, DHT), ``STEPPER_SET_CURRENT_POSITION`` (buggy in 5.4.4), the
stall of ``loop()`` while a packet's bytes trickle in.
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
COMMAND_TABLE_SIZE = 58        # command_table[] of Telemetrix4Arduino 5.4.4 (ids 0..57)
RING_BUFFER = 63               # HardwareSerial's 64-byte receive ring holds 63


def int16(value: int) -> int:
    """An AVR ``int`` (16-bit two's complement) of ``value``."""
    value &= 0xFFFF
    return value - 0x10000 if value & 0x8000 else value


def decode_position(d: bytes) -> int:
    """STEPPER_MOVE_TO / STEPPER_MOVE's target as the firmware computes it (``d`` from the motor byte on)."""
    value = ((d[1] << 24) + (d[2] << 16) + int16(d[3] << 8) + d[4]) & 0xFFFFFFFF   # an AVR long (32 bits)
    value = value - (1 << 32) if value & 0x80000000 else value
    return -value if d[5] else value


def decode_u16(msb: int, lsb: int) -> int:
    """``(msb << 8) + lsb`` in AVR ``int`` arithmetic (above 32,767: negative)."""
    return int16((msb << 8) + lsb)


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
        Motion runs this many times faster than real time (the boot does not).
    boot_s : float
        Seconds after the port opens during which the bootloader loses what arrives (an Uno: ~1-2 s).
    blink_s : float
        Seconds ``setup()`` then blinks before ``loop()`` reads commands (the firmware: 4 x 500 ms); bytes wait.
    step_rate_limit : float
        Most steps per second a stepper makes.
    features : int
        The features byte (0x04: steppers).
    reset_on_open : bool
        Opening the port resets the board (an Arduino's DTR reset); False: a board that keeps running.
    """

    def __init__(self, *, time_scale: float = 1.0, boot_s: float = 1.5, blink_s: float = 2.0,
                 step_rate_limit: float = 4000.0, features: int = ALL_FEATURES, reset_on_open: bool = True) -> None:
        super().__init__("gantry")
        self.time_scale, self.step_rate_limit = float(time_scale), float(step_rate_limit)
        self.boot_s, self.blink_s = float(boot_s), float(blink_s)
        self.features, self.reset_on_open = features, reset_on_open
        self._lock_ = threading.RLock()
        self._rx = bytearray()
        self._boot_until = self._ready_at = 0.0
        self.steppers: dict[int, _Stepper] = {}
        self.pins: dict[int, int] = {}
        self._carriage = [0, 0]       # steps of each motor's carriage from where it stood at the first power-up
        self.reports_on = True
        self.hung: str | None = None
        self.lost_bytes = 0
        self.resets = 0
        self.commands: list[tuple[int, bytes]] = []

    def _now(self) -> float:
        return time.monotonic() * self.time_scale

    def steps(self) -> tuple[int, int]:
        """The firmware's step counters of motors 0 and 1 (0 for a motor not created; thread-safe)."""
        with self._lock_:
            self._advance(self._now())
            return tuple(self.steppers[m].position if m in self.steppers else 0 for m in (0, 1))

    def carriage_steps(self) -> tuple[int, int]:
        """Where the carriage is, in steps of motors 0 and 1 from its place at the first power-up.

        Equal to :meth:`steps` until a reset (opening the port) restarts the counters wherever the carriage stands.
        """
        with self._lock_:
            counted = self.steps()
            return self._carriage[0] + counted[0], self._carriage[1] + counted[1]

    def drivers_enabled(self, pin: int = 8, *, active_low: bool = True) -> bool:
        """Whether a stepper driver board with its enable input on ``pin`` is enabled now (CNC shield: active low)."""
        with self._lock_:
            level = self.pins.get(pin)
        return level is not None and level == (0 if active_low else 1)

    # ------------------------------------------------------------------ pty hooks
    def on_open(self) -> None:
        if not self.reset_on_open:
            return
        with self._lock_:
            here = self.steps()
            self._carriage = [self._carriage[0] + here[0], self._carriage[1] + here[1]]
            self.steppers.clear()
            self.pins.clear()
            self.reports_on = True
            self.hung = None
            self._rx.clear()
            now = time.monotonic()
            self._boot_until = now + self.boot_s
            self._ready_at = self._boot_until + self.blink_s
            self.resets += 1
        self.drop_output()

    def on_bytes(self, data: bytes) -> None:
        with self._lock_:
            now = time.monotonic()
            if self.hung is not None or now < self._boot_until:
                self.lost_bytes += len(data)        # a hung sketch, or the bootloader: nobody reads them
                return
            if now < self._ready_at:                # setup() blinks: the ring buffer fills, then overflows
                room = max(RING_BUFFER - len(self._rx), 0)
                self.lost_bytes += max(len(data) - room, 0)
                self._rx += data[:room]
                return
            self._rx += data
            self._process()

    def tick(self, now: float) -> None:
        with self._lock_:
            if self._rx and now >= self._ready_at and self.hung is None:
                self._process()
            self._advance(self._now())

    # ------------------------------------------------------------------ commands
    def _process(self) -> None:
        while self._rx and self.hung is None:
            if len(self._rx) < 2:
                return                               # the length byte read, waiting for the command byte
            n, kind = self._rx[0], self._rx[1]
            data_len = max(n - 1, 0)
            if len(self._rx) < 2 + data_len:
                return                               # the firmware waits for the rest of the packet
            data = bytes(self._rx[2:2 + data_len])
            del self._rx[:2 + data_len]
            self.commands.append((kind, data))
            if data_len > tp.MAX_COMMAND_LENGTH:
                self.hung = (f"a packet of {data_len} data bytes (length byte {n}) overran the firmware's "
                             f"{tp.MAX_COMMAND_LENGTH}-byte command buffer")
            elif kind >= COMMAND_TABLE_SIZE:
                self.hung = (f"command id {kind} is past the firmware's {COMMAND_TABLE_SIZE}-entry command table "
                             "(no bounds check)")
            else:
                self._command(kind, data)
        if self.hung is not None:
            self._rx.clear()

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
        elif kind == C.STOP_ALL_REPORTS:
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
        if kind in (C.STEPPER_MOVE_TO, C.STEPPER_MOVE) and len(d) >= 6:
            value = decode_position(d)
            s.target = value if kind == C.STEPPER_MOVE_TO else s.position + value
            s.speed = min(1.0, s.max_speed)   # AccelStepper's moveTo recomputes the speed: ~1 step/s from rest
        elif kind == C.STEPPER_SET_MAX_SPEED and len(d) >= 3:
            s.max_speed = float(abs(decode_u16(d[1], d[2])))
        elif kind == C.STEPPER_SET_ACCELERATION and len(d) >= 3:
            a = abs(decode_u16(d[1], d[2]))
            s.accel = float(a) if a else s.accel
        elif kind == C.STEPPER_SET_SPEED and len(d) >= 4:
            v = float(decode_u16(d[1], d[2])) * (-1 if d[3] == 1 else 1)
            s.speed = max(-s.max_speed, min(s.max_speed, v))
        elif kind in (C.STEPPER_RUN, C.STEPPER_RUN_SPEED_TO_POSITION):
            s.mode = "run" if kind == C.STEPPER_RUN else "rstp"
            self._start(s, now)
        elif kind == C.STEPPER_STOP:
            s.mode, s.seg = None, None
            self._drive_enable(s, enabled=False)
        elif kind == C.STEPPER_ENABLE_OUTPUTS:
            self._drive_enable(s, enabled=True)
        elif kind == C.STEPPER_DISABLE_OUTPUTS:
            self._drive_enable(s, enabled=False)
        elif kind == C.STEPPER_SET_ENABLE_PIN and len(d) >= 2:
            s.enable_pin = d[1]
            self._drive_enable(s, enabled=True)    # setEnablePin writes HIGH ^ the inversion set so far
        elif kind == C.STEPPER_SET_3_PINS_INVERTED and len(d) >= 4:
            s.inverted = (d[1], d[2], d[3])        # the flag only: the pin keeps its level
        elif kind == C.STEPPER_IS_RUNNING:
            self._report(tp.Report.STEPPER_RUNNING, d[0], int(s.seg is not None))
        elif kind == C.STEPPER_GET_CURRENT_POSITION:
            self._report(tp.Report.STEPPER_CURRENT_POSITION, d[0],
                         *(s.position & 0xFFFFFFFF).to_bytes(4, "big"))

    def _drive_enable(self, s: _Stepper, *, enabled: bool) -> None:
        """AccelStepper's enableOutputs (HIGH ^ inverted) / disableOutputs (LOW ^ inverted) on the enable pin."""
        if s.enable_pin is not None:
            self.pins[s.enable_pin] = (1 if enabled else 0) ^ int(bool(s.inverted[2]))

    # ------------------------------------------------------------------ motion
    def _start(self, s: _Stepper, now: float) -> None:
        if s.mode == "run":
            v, a = min(s.max_speed, self.step_rate_limit), s.accel
        else:
            v, a = min(abs(s.speed), self.step_rate_limit), 0.0
        s.seg = Segment((float(s.position),), (float(s.target),), now, v, a) if v > 0 else None

    def _advance(self, now: float) -> None:
        if not self.reports_on or self.hung is not None:
            return   # run_steppers() is skipped while reports are stopped (and a hung sketch runs nothing)
        for motor, s in self.steppers.items():
            if s.mode is None:
                continue
            self._drive_enable(s, enabled=True)   # run_steppers: enableOutputs() before each step
            if s.seg is not None:
                s.position = round(s.seg.position(now)[0])
            if s.position == s.target or (s.seg is not None and s.seg.done(now)):
                s.position = s.target if s.seg is not None or s.position == s.target else s.position
                s.mode, s.seg = None, None
                self._report(tp.Report.STEPPER_RUN_COMPLETE, motor)
