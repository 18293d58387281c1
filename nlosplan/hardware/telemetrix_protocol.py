"""Telemetrix4Arduino's serial protocol: the subset a stepper gantry uses (byte layout from the firmware).

Source: Telemetrix4Arduino (MrYsLab), ``examples/Telemetrix4Arduino/Telemetrix4Arduino.ino``
(firmware 5.4.4): ``get_next_command``, the ``stepper_*`` handlers,
``run_steppers``; 115200 baud.

Framing
-------
Every packet, both ways, is ``[length, type, data...]`` with ``length = 1 +
len(data)`` (the type byte counts, the length byte does not). Commands are at
most 30 bytes of data. Multi-byte integers are big-endian.

Commands used here (host -> board)
----------------------------------
=====================================  ====  ==============================================
command                                type  data
=====================================  ====  ==============================================
GET_FIRMWARE_VERSION                      5  -
ENABLE_ALL_REPORTS                       17  - (stepper motion runs only while reports are on)
SET_PIN_MODE_STEPPER                     33  motor, interface (1 = step/dir driver), pin1 (step), pin2 (dir),
                                             pin3, pin4, enable outputs
STEPPER_MOVE_TO                          34  motor, |position| as 4 bytes, polarity (1: negative)
STEPPER_MOVE                             35  motor, |relative steps| as 4 bytes, polarity (DENALI's way)
STEPPER_RUN                              36  motor (accelerate to max speed, decelerate; AccelStepper run())
STEPPER_SET_MAX_SPEED                    38  motor, speed (2 bytes, steps/s)
STEPPER_SET_ACCELERATION                 39  motor, acceleration (2 bytes, steps/s^2)
STEPPER_SET_SPEED                        40  motor, |speed| (2 bytes), polarity
STEPPER_RUN_SPEED_TO_POSITION            42  motor (constant speed, no ramps; DENALI's way)
STEPPER_STOP                             43  motor (stop and disable outputs)
STEPPER_ENABLE_OUTPUTS                   45  motor (drive the enable pin to "enabled")
STEPPER_SET_ENABLE_PIN                   47  motor, pin
STEPPER_SET_3_PINS_INVERTED              48  motor, direction, step, enable (0/1)
STEPPER_IS_RUNNING                       50  motor
STEPPER_GET_CURRENT_POSITION             51  motor
GET_FEATURES                             54  -
=====================================  ====  ==============================================

Reports (board -> host)
-----------------------
``[4, 5, major, minor, patch]`` firmware version; ``[2, 20, features]``
(bit 0x04: steppers compiled in); ``[6, 17, motor, b3, b2, b1, b0]`` current
position (signed 32 bits); ``[3, 18, motor, running]``; ``[2, 19, motor]``
motion complete (sent once when the target is reached).

Firmware facts that matter
--------------------------
- The board resets when the port opens (an Arduino's DTR). For about 1-2 s
  its bootloader owns the serial line and **what arrives is lost**; then
  ``setup()`` blinks the LED for 2 s with the port open (what arrives waits
  in the 64-byte receive ring) and ``loop()`` starts reading. The real
  client (telemetrix 1.46 and DENALI's fork) sends nothing for
  ``arduino_wait = 4`` s after opening. Every stepper position counts from
  that reset.
- ``get_next_command`` takes any byte as a length and reads that many bytes
  into a 30-byte buffer, then calls ``command_table[command]`` (58 entries,
  ids 0..57) without a bounds check: a GRBL ``?`` (63) overruns the buffer
  and the next byte picks the command; an id past the table jumps through
  a stray pointer. The board then answers nothing until the next reset.
- **16-bit arithmetic** (AVR ``int``): a position's low bytes are added as
  ``command_buffer[3] << 8``, so a magnitude with bit 15 set arrives 65,536
  too small (32,768 -> -32,768; 40,000 -> -25,536; the sign travels in its
  own byte, so -32,768 arrives as +32,768): step targets (and relative
  moves) are safe only within +-32,767 (:data:`STEP_LIMIT`).
  Speeds and accelerations ``(msb << 8) + lsb`` above 32,767 arrive
  negative (a max speed of 65,535 runs at 1 step/s): at most 32,767
  (:data:`SPEED_LIMIT`).
- ``STEPPER_SET_CURRENT_POSITION`` (41) builds its value from the wrong byte
  in 5.4.4 (``command_buffer[2]`` twice), so it is not used.
- AccelStepper's ``setEnablePin`` drives the pin at once with the inversion
  set so far (not yet inverted: HIGH, which disables a CNC shield's drivers);
  ``setPinsInverted`` only stores the flag; the drivers are enabled by
  ``enableOutputs`` (command 45, or ``run_steppers`` before each step).
"""

from __future__ import annotations

__all__ = ["Cmd", "PacketError", "PacketReader", "Report", "SPEED_LIMIT", "STEPPERS_FEATURE", "STEP_LIMIT", "packet",
           "signed32"]

MAX_COMMAND_LENGTH = 30
#: Step targets (and relative moves) the firmware decodes right: -STEP_LIMIT .. STEP_LIMIT (AVR int).
STEP_LIMIT = 32767
#: Largest speed / acceleration the firmware decodes right (steps/s, steps/s^2; AVR int).
SPEED_LIMIT = 32767
STEPPERS_FEATURE = 0x04
INTERFACE_DRIVER = 1


class Cmd:
    """Command types (Telemetrix4Arduino's ``#define``\\s)."""

    GET_FIRMWARE_VERSION = 5
    ARE_U_THERE = 6
    STOP_ALL_REPORTS = 15
    ENABLE_ALL_REPORTS = 17
    RESET = 18
    SET_PIN_MODE_STEPPER = 33
    STEPPER_MOVE_TO = 34
    STEPPER_MOVE = 35
    STEPPER_RUN = 36
    STEPPER_SET_MAX_SPEED = 38
    STEPPER_SET_ACCELERATION = 39
    STEPPER_SET_SPEED = 40
    STEPPER_RUN_SPEED_TO_POSITION = 42
    STEPPER_STOP = 43
    STEPPER_DISABLE_OUTPUTS = 44
    STEPPER_ENABLE_OUTPUTS = 45
    STEPPER_SET_ENABLE_PIN = 47
    STEPPER_SET_3_PINS_INVERTED = 48
    STEPPER_IS_RUNNING = 50
    STEPPER_GET_CURRENT_POSITION = 51
    GET_FEATURES = 54


class Report:
    """Report types."""

    FIRMWARE = 5
    I_AM_HERE = 6
    STEPPER_CURRENT_POSITION = 17
    STEPPER_RUNNING = 18
    STEPPER_RUN_COMPLETE = 19
    FEATURES = 20
    DEBUG_PRINT = 99


class PacketError(ValueError):
    """A packet that cannot be framed (bad byte values, too long, length 0)."""


def packet(kind: int, *data: int) -> bytes:
    """``[1 + len(data), kind, *data]``.

    Raises
    ------
    PacketError
        A value outside 0..255, or more data than the firmware's 30-byte buffer.
    """
    if len(data) > MAX_COMMAND_LENGTH:
        raise PacketError(f"Telemetrix command {kind} has {len(data)} data bytes; the firmware takes at most 30")
    for v in (kind, *data):
        if not (isinstance(v, int) and 0 <= v <= 255):
            raise PacketError(f"Telemetrix packet byte {v!r} (command {kind}) is not 0..255")
    return bytes([1 + len(data), kind, *data])


def u16(value: int) -> tuple[int, int]:
    """(msb, lsb) of 0 <= value <= 65535."""
    value = int(value)
    if not 0 <= value <= 0xFFFF:
        raise PacketError(f"{value} does not fit the 16-bit field (0..65535)")
    return value >> 8, value & 0xFF


def magnitude32(value: int) -> tuple[int, int, int, int, int]:
    """|value| as 4 big-endian bytes, then the polarity byte (1: negative), as STEPPER_MOVE_TO sends it."""
    value = int(value)
    if abs(value) > 0x7FFFFFFF:
        raise PacketError(f"stepper position {value} does not fit 32 bits")
    m = abs(value)
    return (m >> 24) & 0xFF, (m >> 16) & 0xFF, (m >> 8) & 0xFF, m & 0xFF, 1 if value < 0 else 0


def signed32(b: bytes) -> int:
    """A big-endian signed 32-bit integer (position reports)."""
    return int.from_bytes(bytes(b[:4]), "big", signed=True)


# ---------------------------------------------------------------------- commands (host -> board)
def firmware_version() -> bytes:
    return packet(Cmd.GET_FIRMWARE_VERSION)


def get_features() -> bytes:
    return packet(Cmd.GET_FEATURES)


def enable_all_reports() -> bytes:
    return packet(Cmd.ENABLE_ALL_REPORTS)


def set_pin_mode_stepper(motor: int, step_pin: int, dir_pin: int, *, pin3: int = 4, pin4: int = 5,
                         enable: bool = True) -> bytes:
    """A step/dir driver (interface 1) on ``step_pin``/``dir_pin`` (pin3/pin4 unused; the client's defaults)."""
    return packet(Cmd.SET_PIN_MODE_STEPPER, motor, INTERFACE_DRIVER, step_pin, dir_pin, pin3, pin4, int(enable))


def steps16(value: int) -> int:
    """``value`` if the firmware decodes it as sent (|value| <= :data:`STEP_LIMIT`).

    Raises
    ------
    PacketError
        Beyond it: Telemetrix4Arduino would move to another target (16-bit arithmetic).
    """
    value = int(value)
    if abs(value) > STEP_LIMIT:
        raise PacketError(f"step target {value} is beyond what Telemetrix4Arduino decodes (16-bit AVR int: "
                          f"-{STEP_LIMIT}..{STEP_LIMIT} steps)")
    return value


def speed16(value: int) -> int:
    """``value`` if the firmware decodes it as sent (0..:data:`SPEED_LIMIT`).

    Raises
    ------
    PacketError
        Above it: Telemetrix4Arduino would read a negative number (16-bit AVR int).
    """
    value = int(value)
    if not 0 <= value <= SPEED_LIMIT:
        raise PacketError(f"{value} does not fit the 16-bit field as Telemetrix4Arduino reads it "
                          f"(an AVR int: 0..{SPEED_LIMIT})")
    return value


def move_to(motor: int, position: int) -> bytes:
    return packet(Cmd.STEPPER_MOVE_TO, motor, *magnitude32(steps16(position)))


def move(motor: int, steps: int) -> bytes:
    """STEPPER_MOVE: ``steps`` relative to where the motor is (DENALI's cc-hardware moves this way)."""
    return packet(Cmd.STEPPER_MOVE, motor, *magnitude32(steps16(steps)))


def enable_outputs(motor: int) -> bytes:
    """STEPPER_ENABLE_OUTPUTS: drive the motor's enable pin to "enabled" (AccelStepper ``enableOutputs``)."""
    return packet(Cmd.STEPPER_ENABLE_OUTPUTS, motor)


def set_max_speed(motor: int, steps_s: int) -> bytes:
    return packet(Cmd.STEPPER_SET_MAX_SPEED, motor, *u16(speed16(steps_s)))


def set_acceleration(motor: int, steps_s2: int) -> bytes:
    return packet(Cmd.STEPPER_SET_ACCELERATION, motor, *u16(speed16(steps_s2)))


def set_speed(motor: int, steps_s: int) -> bytes:
    return packet(Cmd.STEPPER_SET_SPEED, motor, *u16(speed16(abs(int(steps_s)))), 1 if steps_s < 0 else 0)


def run(motor: int) -> bytes:
    return packet(Cmd.STEPPER_RUN, motor)


def run_speed_to_position(motor: int) -> bytes:
    return packet(Cmd.STEPPER_RUN_SPEED_TO_POSITION, motor)


def stop(motor: int) -> bytes:
    return packet(Cmd.STEPPER_STOP, motor)


def set_enable_pin(motor: int, pin: int) -> bytes:
    return packet(Cmd.STEPPER_SET_ENABLE_PIN, motor, pin)


def set_3_pins_inverted(motor: int, *, direction: bool = False, step: bool = False, enable: bool = False) -> bytes:
    return packet(Cmd.STEPPER_SET_3_PINS_INVERTED, motor, int(direction), int(step), int(enable))


def get_current_position(motor: int) -> bytes:
    return packet(Cmd.STEPPER_GET_CURRENT_POSITION, motor)


def is_running(motor: int) -> bytes:
    return packet(Cmd.STEPPER_IS_RUNNING, motor)


# ---------------------------------------------------------------------- reports (board -> host)
class PacketReader:
    """Splits a byte stream into ``(type, data)`` packets (keeps a partial packet for the next feed)."""

    def __init__(self) -> None:
        self._buf = bytearray()

    def feed(self, data: bytes) -> list[tuple[int, bytes]]:
        """Add bytes; returns the complete packets.

        Raises
        ------
        PacketError
            A zero length byte (the firmware never sends one: the stream is not Telemetrix, or out of step).
        """
        self._buf += data
        out = []
        while self._buf:
            n = self._buf[0]
            if n == 0:
                bad = bytes(self._buf[:16])
                self._buf.clear()
                raise PacketError(f"a Telemetrix packet of length 0 (stream {bad!r}): not Telemetrix, or out of step")
            if len(self._buf) < n + 1:
                break
            out.append((self._buf[1], bytes(self._buf[2:n + 1])))
            del self._buf[:n + 1]
        return out

    @property
    def pending(self) -> int:
        return len(self._buf)
