"""GRBL 1.1 gantry driver over pyserial (an XY gantry on a CNC shield).

Send-and-wait (every line waits for its ``ok``) for commands, character
counting (GRBL's 128-byte receive buffer) for :meth:`Grbl.stream`, ``?``
status polling to wait for Idle, soft limits checked here before anything is
sent, ``ALARM:``/``error:`` raised as :class:`GrblAlarm`/:class:`GrblError`.
The driver never unlocks (``$X``) by itself: :meth:`Grbl.unlock` does, when asked.

Examples
--------
>>> with Grbl("/dev/ttyUSB0", limits_mm=((0, 320), (0, 320))) as gantry:   # doctest: +SKIP
...     gantry.connect()
...     status = gantry.move_to(35.6, 0.0, feed_mm_min=3000)   # waits for Idle
...     status.mpos
(35.6, 0.0, 0.0)
"""

from __future__ import annotations

import math
import time
from collections import deque

from nlosplan.errors import UserError
from nlosplan.hardware.grbl_protocol import GrblAlarm, GrblError, Status, parse_status
from nlosplan.hardware.transport import ConnectionLost, DeviceTimeout, LineReader, open_serial

__all__ = ["Grbl", "GrblAlarm", "GrblError", "LimitError", "Status"]

RX_BUFFER = 128


class LimitError(UserError):
    """A move target outside the gantry's soft limits (refused before anything is sent)."""


class Grbl:
    """A GRBL 1.1 controller.

    Parameters
    ----------
    port : str or serial object
    baudrate : int
        115200 for GRBL 1.1.
    limits_mm : ((xmin, xmax), (ymin, ymax))
        Soft limits checked before every move (mm, machine frame).
    feed_mm_min : float
        Default feed rate of moves (mm/min).
    timeout : float
        Seconds to wait for an answer to one line.
    poll_s : float
        Status polling period while waiting for Idle.
    move_timeout : float
        Seconds a move may take before :meth:`wait_idle` gives up.
    """

    def __init__(self, port, *, baudrate: int = 115200, limits_mm=((0.0, 320.0), (0.0, 320.0)),
                 feed_mm_min: float = 3000.0, timeout: float = 5.0, poll_s: float = 0.05,
                 move_timeout: float = 120.0) -> None:
        (x0, x1), (y0, y1) = limits_mm
        if not (x0 < x1 and y0 < y1) or not all(math.isfinite(v) for v in (x0, x1, y0, y1)):
            raise UserError(f"gantry limits {limits_mm!r} must be finite (min, max) pairs with min < max")
        if not (math.isfinite(feed_mm_min) and feed_mm_min > 0):
            raise UserError(f"feed rate {feed_mm_min!r} mm/min must be > 0")
        self.limits_mm = ((float(x0), float(x1)), (float(y0), float(y1)))
        self.feed_mm_min = float(feed_mm_min)
        self.timeout, self.poll_s, self.move_timeout = timeout, poll_s, move_timeout
        self.repoll_s = 0.5   # ask again for a status report not answered within this
        self.port_name = port if isinstance(port, str) else getattr(port, "port", None) or repr(port)
        self._ser, self._owned = open_serial(port, baudrate)
        self._reader = LineReader(self._ser)
        self.banner: str | None = None
        self.messages: list[str] = []
        self.last_status: Status | None = None
        self._wco: tuple | None = None
        self.alarm: int | None = None

    # ------------------------------------------------------------------ low level
    def _write(self, data: bytes) -> None:
        self._reader.write(data)

    def _handle(self, line: str, context: str) -> str | None:
        """Classify one incoming line; returns "ok", a status marker, or None (feedback)."""
        s = line.strip()
        if not s:
            return None
        if s == "ok":
            return "ok"
        if s.startswith("error:"):
            return s
        if s.startswith("ALARM:"):
            try:
                code = int(s[6:])
            except ValueError:
                code = 0
            self.alarm = code
            raise GrblAlarm(code, context)
        if s.startswith("<"):
            try:
                self.last_status = parse_status(s, self._wco)
            except ValueError:
                return "bad status"
            if "WCO:" in s:
                self._wco = tuple(float(v) for v in s.split("WCO:")[1].split("|")[0].rstrip(">").split(","))
            return "status"
        if s.startswith("Grbl "):
            self.banner = s
            return "banner"
        self.messages.append(s)
        return None

    def _wait_ok(self, line: str, timeout: float) -> list[str]:
        out = []
        deadline = time.monotonic() + timeout
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                raise DeviceTimeout(f"gantry on {self.port_name}: no 'ok' for {line!r} within {timeout:g} s")
            try:
                got = self._reader.readline(left)
            except DeviceTimeout:
                continue
            kind = self._handle(got, f"after {line!r}")
            if kind == "ok":
                return out
            if kind and kind.startswith("error:"):
                try:
                    code = int(kind[6:])
                except ValueError:
                    code = 0
                raise GrblError(code, line)
            if kind == "banner":
                raise ConnectionLost(f"gantry on {self.port_name} reset while running {line!r}")
            if kind is None and got.strip():
                out.append(got.strip())

    def send(self, line: str, timeout: float | None = None) -> list[str]:
        """Send one line and wait for its ``ok`` (send-and-wait); returns the lines before it.

        Raises
        ------
        GrblError, GrblAlarm, DeviceTimeout, ConnectionLost
        """
        line = line.strip()
        if not line or "\n" in line or len(line) >= RX_BUFFER:
            raise UserError(f"gantry line {line!r} must be one non-empty line under {RX_BUFFER} characters")
        self._write((line + "\n").encode("ascii"))
        return self._wait_ok(line, self.timeout if timeout is None else timeout)

    def stream(self, lines, timeout: float | None = None) -> int:
        """Send many lines by character counting (at most 128 bytes unacknowledged in GRBL's buffer).

        Returns
        -------
        int
            Lines sent (all acknowledged).
        """
        timeout = self.timeout if timeout is None else timeout
        pending: deque[tuple[str, int]] = deque()
        n = 0
        for raw in lines:
            line = raw.strip()
            if not line:
                continue
            size = len(line) + 1
            if size > RX_BUFFER:
                raise UserError(f"gantry line {line!r} is longer than GRBL's {RX_BUFFER}-byte buffer")
            while pending and sum(k for _, k in pending) + size > RX_BUFFER:
                self._wait_ok(pending.popleft()[0], timeout)
            self._write((line + "\n").encode("ascii"))
            pending.append((line, size))
            n += 1
        while pending:
            self._wait_ok(pending.popleft()[0], timeout)
        return n

    # ------------------------------------------------------------------ session
    def connect(self, timeout: float = 5.0) -> str:
        """Wake GRBL and read its banner (soft reset if it says nothing).

        Returns
        -------
        str
            The banner, e.g. ``Grbl 1.1h ['$' for help]``.

        Raises
        ------
        DeviceTimeout
            No banner (wrong port or baud rate, not GRBL).
        """
        self._write(b"\r\n\r\n")
        for attempt in range(2):
            if self._await_banner(time.monotonic() + timeout / 2, "at connect"):
                return self.banner
            if attempt == 0:
                self._write(b"\x18")
        raise DeviceTimeout(f"no GRBL banner from {self.port_name} within {timeout:g} s "
                            "(wrong port or baud rate, or not GRBL 1.1?)")

    def _await_banner(self, deadline: float, context: str) -> bool:
        """Read lines until a banner (then drain what follows it) or the deadline; alarms before it are skipped."""
        while time.monotonic() < deadline:
            try:
                line = self._reader.readline(max(deadline - time.monotonic(), 0.01))
            except DeviceTimeout:
                return False
            try:
                if self._handle(line, context) == "banner":
                    self._after_banner()
                    return True
            except GrblAlarm:
                continue
        return False

    def _after_banner(self) -> None:
        # drain the feedback that follows a banner ([MSG:'$H'|'$X' to unlock] when homing is enabled)
        try:
            for line in self._reader.read_until_quiet(0.1, 0.3):
                self._handle(line, "after reset")
        except (DeviceTimeout, GrblAlarm):
            pass
        self.alarm = None
        st = self.status()
        if st.state == "Alarm":
            self.alarm = -1

    def settings(self) -> dict[int, float]:
        """``$$``: the settings as ``{number: value}``."""
        out = {}
        for line in self.send("$$"):
            if line.startswith("$") and "=" in line:
                k, _, v = line[1:].partition("=")
                try:
                    out[int(k)] = float(v.split()[0])
                except ValueError:
                    continue
        return out

    def set_setting(self, number: int, value: float) -> None:
        """``$N=value`` (one at a time, as GRBL asks)."""
        self.send(f"${int(number)}={value:g}")

    def home(self, timeout: float = 120.0) -> Status:
        """``$H`` homing cycle (needs ``$22=1``); returns the status after it."""
        self.send("$H", timeout=timeout)
        self.alarm = None
        return self.wait_idle()

    def unlock(self) -> None:
        """``$X``: clear an alarm lock without homing (only when the user asks for it)."""
        self.send("$X")
        self.alarm = None

    # ------------------------------------------------------------------ real-time
    def status(self, timeout: float | None = None, context: str = "while polling status") -> Status:
        """Poll ``?`` and return the report.

        Raises
        ------
        GrblAlarm
            An ``ALARM:`` line arrived while waiting.
        """
        timeout = self.timeout if timeout is None else timeout
        self._write(b"?")
        deadline = time.monotonic() + timeout
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                raise DeviceTimeout(f"gantry on {self.port_name}: no status report within {timeout:g} s")
            try:
                line = self._reader.readline(min(left, self.repoll_s))
            except DeviceTimeout:
                self._write(b"?")   # the report was lost or garbled beyond recognition: ask again
                continue
            kind = self._handle(line, context)
            if kind == "status":
                return self.last_status
            if kind == "bad status":
                self._write(b"?")

    def wait_idle(self, timeout: float | None = None, context: str = "") -> Status:
        """Poll ``?`` until the state is Idle; returns that report.

        Raises
        ------
        GrblAlarm
            ``ALARM:N`` arrived or the state turned Alarm (e.g. a hard limit mid-move).
        DeviceTimeout
            Not Idle within ``timeout`` (default ``move_timeout``).
        """
        timeout = self.move_timeout if timeout is None else timeout
        deadline = time.monotonic() + timeout
        while True:
            st = self.status(context=context)
            if st.state == "Idle":
                return st
            if st.state == "Alarm":
                self.alarm = self.alarm or -1
                raise GrblAlarm(self.alarm if self.alarm and self.alarm > 0 else 0, context)
            if time.monotonic() > deadline:
                raise DeviceTimeout(f"gantry not Idle within {timeout:g} s (state {st.state})")
            time.sleep(self.poll_s)

    def feed_hold(self) -> None:
        """``!``: decelerate to a stop and hold (resume with :meth:`resume`)."""
        self._write(b"!")

    def resume(self) -> None:
        """``~``: resume after a feed hold."""
        self._write(b"~")

    def soft_reset(self, timeout: float = 5.0) -> str:
        """0x18: reset GRBL (a reset during motion raises ALARM:3 afterwards); returns the new banner."""
        self._write(b"\x18")
        if self._await_banner(time.monotonic() + timeout, "at reset"):
            return self.banner
        raise DeviceTimeout(f"no GRBL banner within {timeout:g} s after a soft reset")

    # ------------------------------------------------------------------ motion
    def check_limits(self, x_mm: float, y_mm: float) -> None:
        """Raise :class:`LimitError` when (x, y) mm is outside the soft limits (nothing is sent)."""
        (x0, x1), (y0, y1) = self.limits_mm
        if not (math.isfinite(x_mm) and math.isfinite(y_mm)):
            raise LimitError(f"gantry target ({x_mm}, {y_mm}) mm is not finite")
        if not (x0 <= x_mm <= x1 and y0 <= y_mm <= y1):
            raise LimitError(f"gantry target ({x_mm:.3f}, {y_mm:.3f}) mm is outside the limits "
                             f"x {x0:g}..{x1:g}, y {y0:g}..{y1:g} mm; nothing was sent")

    def move_to(self, x_mm: float, y_mm: float, *, feed_mm_min: float | None = None, wait: bool = True) -> Status | None:
        """Absolute move in mm (``G90 G21 G1 X Y F``); waits for Idle unless ``wait=False``.

        Returns
        -------
        Status or None
            The Idle report at the target (its ``mpos`` is the reported position).

        Raises
        ------
        LimitError
            Target outside the soft limits (checked before sending).
        GrblAlarm, GrblError, DeviceTimeout, ConnectionLost
        """
        x, y = float(x_mm), float(y_mm)
        self.check_limits(x, y)
        feed = self.feed_mm_min if feed_mm_min is None else float(feed_mm_min)
        if not (math.isfinite(feed) and feed > 0):
            raise UserError(f"feed rate {feed_mm_min!r} mm/min must be > 0")
        self.send(f"G90 G21 G1 X{x:.3f} Y{y:.3f} F{feed:.0f}")
        if not wait:
            return None
        return self.wait_idle(context=f"moving to ({x:.3f}, {y:.3f}) mm")

    def close(self) -> None:
        """Close the port (if this driver opened it)."""
        if self._owned and self._ser is not None:
            try:
                self._ser.close()
            except Exception:  # noqa: BLE001 - closing a dead port
                pass
            self._ser = None

    def __enter__(self) -> "Grbl":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
