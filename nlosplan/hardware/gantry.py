"""What every gantry driver offers the rig (GRBL, Telemetrix), and which firmware answers on a port.

A gantry driver (:class:`~nlosplan.hardware.grbl.Grbl`,
:class:`~nlosplan.hardware.telemetrix.TelemetrixGantry`) works in the
*user frame*: the gantry coordinates of the plans (DENALI: 0..320 mm per
axis). How that frame maps onto the controller's own coordinates is the
driver's business (GRBL: a work offset it sets and checks; Telemetrix: steps
per mm, axis flips and the power-up origin of the rig file), and every
position it reports says both (:class:`GantryPosition`).

:func:`probe_firmware` tells GRBL from Telemetrix4Arduino on a port without
confusing either. Opening the port resets an Arduino, and its bootloader
loses what arrives for about 1-2 s; Telemetrix4Arduino then reads any byte
as a packet length (GRBL's ``?`` = 63 overruns its 30-byte buffer and hangs
it until the next reset), while GRBL drops control characters. So the probe
(1) sends nothing while the board boots (``quiet_s``; the real telemetrix
client waits 4 s, :data:`BOOT_WAIT_S`) and takes a GRBL banner if one comes,
(2) then asks Telemetrix for its firmware version (two control bytes GRBL
ignores), again every ``query_every_s``, and (3) only when asked to, and
only after that, sends GRBL's ``?`` (and a soft reset, 0x18). The Telemetrix
driver never sends (3); ``--gantry-kind auto`` sends it only once a
Telemetrix board would have answered.
"""

from __future__ import annotations

import re
import time
from dataclasses import dataclass, field
from typing import Protocol

from nlosplan.errors import UserError
from nlosplan.hardware.transport import DeviceTimeout

__all__ = ["BOOT_WAIT_S", "GANTRY_KINDS", "GantryDriver", "GantryPosition", "LimitError", "Probe", "WrongFirmware",
           "check_box", "probe_firmware"]

GANTRY_KINDS = ("grbl", "telemetrix", "auto")
#: Seconds to send nothing after opening a port that may hold a Telemetrix board (the telemetrix client's
#: ``arduino_wait``, which DENALI keeps at 4): its bootloader loses what arrives meanwhile.
BOOT_WAIT_S = 4.0
#: Telemetrix4Arduino: GET_FIRMWARE_VERSION (packet length 1, command 5); the answer is [4, 5, major, minor, patch].
TELEMETRIX_VERSION_QUERY = b"\x01\x05"
_TELEMETRIX_VERSION = re.compile(rb"\x04\x05([\x00-\x3f])([\x00-\x63])([\x00-\x63])")
_GRBL_BANNER = re.compile(rb"Grbl (\d+\.\d+\w*)[^\r\n]*\r?\n")
_GRBL_STATUS = re.compile(rb"<[A-Z][a-z]+(:\d)?\|[MW]Pos:[-0-9.,]+[^<>\r\n]*>\r?\n")


class LimitError(UserError):
    """A move target outside the gantry's limits (refused before anything is sent)."""


def check_box(limits_mm, x_mm: float, y_mm: float) -> None:
    """Raise :class:`LimitError` when (x, y) mm is not finite or outside ``limits_mm`` (user frame)."""
    import math

    (x0, x1), (y0, y1) = limits_mm
    if not (math.isfinite(x_mm) and math.isfinite(y_mm)):
        raise LimitError(f"gantry target ({x_mm}, {y_mm}) mm is not finite")
    if not (x0 <= x_mm <= x1 and y0 <= y_mm <= y1):
        raise LimitError(f"gantry target ({x_mm:.3f}, {y_mm:.3f}) mm is outside the limits "
                         f"x {x0:g}..{x1:g}, y {y0:g}..{y1:g} mm; nothing was sent")


class WrongFirmware(UserError):
    """The port answers, but with another firmware than the one asked for (or none we know)."""


@dataclass(frozen=True)
class GantryPosition:
    """Where the gantry is, in the user frame and in the controller's own units.

    Attributes
    ----------
    xy_mm : (float, float)
        Position in the user frame (the plan's gantry coordinates), mm.
    raw : dict
        The controller's own numbers, for audit (GRBL: ``mpos_mm`` and
        ``wco_mm``; Telemetrix: ``steps``).
    state : str
        The controller's state (GRBL: Idle, Run, Alarm, ...; Telemetrix: Idle or Run).
    """

    xy_mm: tuple
    raw: dict = field(default_factory=dict)
    state: str = "Idle"


class GantryDriver(Protocol):
    """The interface the rig executor uses (both drivers implement it)."""

    kind: str
    port_name: str
    limits_mm: tuple
    #: Whether reported positions are referenced to the machine (homed, or a controller that kept counting)
    #: rather than to wherever the carriage stood when the port opened (a reset restarts the counters there).
    referenced: bool

    def prepare(self, *, home: bool = False, unlock: bool = False) -> None:
        """Connect, read the controller's setup, clear what the user allowed, set up the user frame."""

    def check_limits(self, x_mm: float, y_mm: float) -> None:
        """Raise a UserError when (x, y) is outside the limits (nothing is sent)."""

    def origin_xy(self) -> tuple[float, float]:
        """The user-frame position the controller's counters call zero after a reset (its power-up origin)."""

    def move_to(self, x_mm: float, y_mm: float, *, feed_mm_min: float | None = None) -> GantryPosition:
        """Move in the user frame and wait until it stands still there."""

    def where(self) -> GantryPosition:
        """The reported position now."""

    def blocked(self) -> str | None:
        """Why the gantry must not be moved now (e.g. an alarm), or None."""

    def describe(self) -> dict:
        """Firmware, port and frame, stored with every capture."""

    def close(self) -> None:
        """Close the port (if the driver opened it)."""


@dataclass
class Probe:
    """What :func:`probe_firmware` found on a port.

    Attributes
    ----------
    kind : {"grbl", "telemetrix"} or None
    how : str
        ``banner`` (GRBL reset when the port opened), ``status`` (GRBL was
        running), ``reset`` (GRBL answered only after a soft reset: it was
        halted by ALARM:1/2), ``version`` (Telemetrix), or ``""``.
    text : str
        The banner, the status report, or ``major.minor.patch``.
    rest : bytes
        What arrived after the recognised answer (the driver reads it next).
    seen : bytes
        Everything that arrived (for error messages).
    """

    kind: str | None
    how: str = ""
    text: str = ""
    rest: bytes = b""
    seen: bytes = b""

    def describe_seen(self) -> str:
        if not self.seen:
            return "nothing"
        return f"{len(self.seen)} bytes, e.g. {bytes(self.seen[:24])!r}"


def probe_firmware(ser, *, timeout: float = 5.0, quiet_s: float = 0.0, query_every_s: float | None = 0.5,
                   grbl_after_s: float | None = None, reset_after_s: float | None = None,
                   poll_s: float = 0.5) -> Probe:
    """Find out which gantry firmware answers on an open serial object.

    Parameters
    ----------
    ser : serial object
        ``read(n)``/``write(b)`` (the driver's transport).
    timeout : float
        Seconds to wait in all, from the call (opening the port just before it).
    quiet_s : float
        Send nothing for this many seconds (the board's boot after the port opened: bytes sent then are
        lost); a GRBL banner printed meanwhile is recognised.
    query_every_s : float or None
        From ``quiet_s`` on, send Telemetrix's firmware-version request, and again at this period
        (None: once). Harmless to GRBL, which drops control characters.
    grbl_after_s : float or None
        Send GRBL's ``?`` from this many seconds on, every ``poll_s`` (``?`` would hang a Telemetrix board,
        so only after a Telemetrix board would have answered); None: never (the Telemetrix driver).
    reset_after_s : float or None
        Send GRBL's soft reset (0x18) once after this many seconds without a recognised answer (a GRBL
        halted by ALARM:1/2 answers nothing else); None: never. Ignored without ``grbl_after_s``.
    poll_s : float
        Period of the ``?`` requests.

    Returns
    -------
    Probe
        ``kind`` None when nothing recognisable arrived (``seen`` says what did).
    """
    seen = bytearray()
    t0 = time.monotonic()
    next_query, next_poll, reset_sent = t0 + quiet_s, None, False
    if grbl_after_s is not None:
        next_poll = t0 + max(grbl_after_s, quiet_s)
    while True:
        now = time.monotonic()
        if next_query is not None and now >= next_query:
            ser.write(TELEMETRIX_VERSION_QUERY)
            _flush(ser)
            next_query = None if query_every_s is None else now + query_every_s
        try:
            waiting = getattr(ser, "in_waiting", 0) or 1
            data = ser.read(min(max(waiting, 1), 4096))
        except OSError as exc:
            raise DeviceTimeout(f"serial link failed while probing: {exc}") from None
        if data:
            seen += data
            found = _recognise(bytes(seen), reset_sent)
            if found is not None:
                found.seen = bytes(seen)
                return found
        if now - t0 >= timeout:
            return Probe(None, seen=bytes(seen))
        if next_poll is not None and now >= next_poll:
            ser.write(b"?")
            _flush(ser)
            next_poll = now + poll_s
        if (next_poll is not None and reset_after_s is not None and not reset_sent
                and now - t0 >= max(reset_after_s, quiet_s)):
            ser.write(b"\x18")
            _flush(ser)
            reset_sent = True
        if not data:
            time.sleep(0.005)


def _flush(ser) -> None:
    try:
        ser.flush()
    except Exception:  # noqa: BLE001 - URL handlers without flush
        pass


def _recognise(buf: bytes, reset_sent: bool) -> Probe | None:
    m = _GRBL_BANNER.search(buf)
    if m:
        return Probe("grbl", "reset" if reset_sent else "banner", m.group(0).decode("ascii", "replace").strip(),
                     buf[m.end():])
    m = _GRBL_STATUS.search(buf)
    if m:
        return Probe("grbl", "status", m.group(0).decode("ascii", "replace").strip(), buf[m.end():])
    m = _TELEMETRIX_VERSION.search(buf)
    if m:
        return Probe("telemetrix", "version", ".".join(str(g[0]) for g in m.groups()), buf[m.end():])
    return None
