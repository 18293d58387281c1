"""GRBL 1.1's serial link: lines with ``ok``/``error:N``, ``ALARM:N``, status reports and real-time bytes.

:class:`GrblLink` is the framing half of the GRBL driver
(:class:`~nlosplan.hardware.grbl.Grbl` adds the session: setup, alarms,
homing, the user frame, motion). Send-and-wait (every line waits for its
``ok``) for commands, character counting (GRBL's 128-byte receive buffer) for
:meth:`GrblLink.stream`, ``?`` polling for status, ``!``/``~``/0x18.
"""

from __future__ import annotations

import time
from collections import deque

from nlosplan.errors import UserError
from nlosplan.hardware.grbl_protocol import CRITICAL_ALARMS, GrblAlarm, GrblError, Status, parse_status
from nlosplan.hardware.transport import ConnectionLost, DeviceTimeout, LineReader, close_serial, open_serial

__all__ = ["RX_BUFFER", "GrblLink"]

RX_BUFFER = 128


class GrblLink:
    """The line protocol of a GRBL 1.1 controller on a port.

    Parameters
    ----------
    port : str or serial object
    baudrate : int
    timeout : float
        Seconds to wait for an answer to one line.
    poll_s : float
        Status polling period while waiting for Idle.
    move_timeout : float
        Seconds a move may take before :meth:`wait_idle` gives up.
    """

    def __init__(self, port, baudrate: int = 115200, *, timeout: float = 5.0, poll_s: float = 0.05,
                 move_timeout: float = 120.0) -> None:
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
        """Classify one incoming line; returns "ok", "error:N", "status", "banner", "bad status" or None."""
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
                st = parse_status(s, self._wco)
            except ValueError:
                return "bad status"
            if st.wco is not None:
                self._wco = st.wco
            self.last_status = st
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

    def exchange(self, data: bytes, quiet_s: float = 0.3, timeout: float = 3.0) -> list[str]:
        """Write raw bytes and return every line that comes back until ``quiet_s`` of silence (diagnostics).

        Lines are returned as they are, not interpreted (no exception for ``ALARM:`` or ``error:``). GRBL ends
        every line with a newline, so a pause inside a line waits for the rest (up to ``timeout``).
        """
        self._write(data)
        try:
            return self._reader.read_until_quiet(quiet_s, timeout, whole_lines=True)
        except DeviceTimeout:
            return []

    def send(self, line: str, timeout: float | None = None) -> list[str]:
        """Send one line and wait for its ``ok`` (send-and-wait); returns the lines before it.

        Raises
        ------
        GrblError, GrblAlarm, DeviceTimeout, ConnectionLost
        """
        line = line.strip()
        if not line or "\n" in line or "\r" in line or len(line) >= RX_BUFFER:
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

    # ------------------------------------------------------------------ real-time
    def status(self, timeout: float | None = None, context: str = "while polling status") -> Status:
        """Poll ``?`` and return the report.

        Raises
        ------
        GrblAlarm
            An ``ALARM:`` line arrived while waiting.
        DeviceTimeout
            No report (GRBL halted by ALARM:1/2 answers nothing until a soft reset).
        """
        timeout = self.timeout if timeout is None else timeout
        self._write(b"?")
        deadline = time.monotonic() + timeout
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                hint = (" (GRBL answers nothing after ALARM:1/2 until a soft reset)"
                        if self.alarm in CRITICAL_ALARMS else "")
                raise DeviceTimeout(f"gantry on {self.port_name}: no status report within {timeout:g} s{hint}")
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
        """``!``: decelerate to a stop and hold (``Hold:1``, then ``Hold:0``; resume with :meth:`resume`)."""
        self._write(b"!")

    def resume(self) -> None:
        """``~``: resume after a feed hold (GRBL resumes only once the hold is complete)."""
        self._write(b"~")

    def soft_reset(self, timeout: float = 5.0) -> str:
        """0x18: reset GRBL (during motion it reports ALARM:3 first); returns the new banner."""
        self._write(b"\x18")   # no flush first: an ALARM:3 in the answer says the reset stopped a move
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            try:
                line = self._reader.readline(max(deadline - time.monotonic(), 0.01))
            except DeviceTimeout:
                break
            try:
                if self._handle(line, "at reset") == "banner":
                    break
            except GrblAlarm:
                continue   # ALARM:3 when it was moving
        else:
            line = ""
        if not (line or "").strip().startswith("Grbl "):
            raise DeviceTimeout(f"gantry on {self.port_name}: no GRBL banner within {timeout:g} s after a soft reset")
        try:
            for ln in self._reader.read_until_quiet(0.1, 0.3):
                self._handle(ln, "after reset")
        except (DeviceTimeout, GrblAlarm):
            pass
        st = self.status(context="after reset")
        self.alarm = (self.alarm or -1) if st.state == "Alarm" else None
        return self.banner

    def close(self) -> None:
        """Close the port (if this driver opened it)."""
        close_serial(self._ser, self._owned)
        if self._owned:
            self._ser = None

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()
