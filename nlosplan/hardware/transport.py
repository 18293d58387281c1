"""The serial transport shared by the drivers: open a port, read lines with deadlines.

A driver takes a port name (``/dev/ttyACM0``, ``COM3``, a pty, or a pyserial
URL such as ``loop://`` or ``spy:///dev/ttyACM0`` to record a session) or an
already-open pyserial object (STYLE.md 4). Every read here has a deadline:
nothing waits forever on a silent device.
"""

from __future__ import annotations

import time

from nlosplan.errors import UserError

__all__ = ["ConnectionLost", "DeviceTimeout", "LineReader", "close_serial", "open_serial"]

#: Baud rates the TMF8828 firmwares use (ams example, UW-Madison readers, DENALI).
TMF8828_BAUDS = (115200, 1_000_000, 2_000_000)
_MAX_LINE = 16384  # bytes without a newline before the buffer is thrown away as garbage


class DeviceTimeout(TimeoutError):
    """A device did not answer within its deadline."""


class ConnectionLost(ConnectionError):
    """The serial link went away (unplugged, emulator closed)."""


def open_serial(port, baudrate: int, *, read_timeout: float = 0.05):
    """Open ``port`` (a name or URL) or return an already-open pyserial object unchanged.

    Parameters
    ----------
    port : str or serial.SerialBase
    baudrate : int
    read_timeout : float
        Seconds one low-level read may block (the line reader loops to its deadline).

    Returns
    -------
    (serial object, owned) : tuple
        ``owned`` is True when this call opened it (the driver then closes it).

    Raises
    ------
    UserError
        The port cannot be opened (the message names it and the reason).
    """
    if not isinstance(port, str):
        if not all(hasattr(port, a) for a in ("read", "write")):
            raise UserError(f"port must be a name or an open pyserial object, not {type(port).__name__}")
        if getattr(port, "timeout", 0) is None:  # a blocking read would never meet a deadline
            port.timeout = read_timeout
        return port, False
    import serial

    try:
        ser = serial.serial_for_url(port, baudrate=int(baudrate), timeout=read_timeout, write_timeout=2.0)
    except (serial.SerialException, OSError, ValueError) as exc:
        raise UserError(f"cannot open serial port {port!r}: {exc}") from None
    return ser, True


def close_serial(ser, owned: bool) -> None:
    """Close a port :func:`open_serial` opened (``owned``); one given open is the caller's to close.

    A dead port may fail to close; it is gone either way, so that error is dropped.
    """
    if owned and ser is not None:
        try:
            ser.close()
        except Exception:  # noqa: BLE001 - closing a dead port
            pass


class LineReader:
    """Reads ``\\n``-terminated lines from a serial object, each read with a deadline.

    Parameters
    ----------
    ser : serial object
        Anything with ``read(n)`` (returning b"" on its own timeout) and ``in_waiting``.
    """

    def __init__(self, ser) -> None:
        self.ser = ser
        self._buf = bytearray()
        self.overlong = 0
        self._cut = False  # after a flush the first line may be a cut-off tail: drop it

    def _fill(self) -> int:
        import serial

        try:
            waiting = getattr(self.ser, "in_waiting", 0) or 1
            data = self.ser.read(min(max(waiting, 1), 65536))
        except (serial.SerialException, OSError) as exc:
            raise ConnectionLost(f"serial link lost: {exc}") from None
        if data:
            self._buf += data
            if len(self._buf) > _MAX_LINE and b"\n" not in self._buf:
                self._buf.clear()
                self.overlong += 1
        return len(data)

    def readline(self, timeout: float) -> str:
        """The next line (without its ending), decoded as ASCII (bad bytes replaced).

        Raises
        ------
        DeviceTimeout
            No complete line within ``timeout`` seconds (a partial line stays buffered).
        ConnectionLost
            The port failed.
        """
        deadline = time.monotonic() + timeout
        while True:
            i = self._buf.find(b"\n")
            if i >= 0:
                raw = bytes(self._buf[:i])
                del self._buf[:i + 1]
                if self._cut:
                    self._cut = False
                    continue
                return raw.decode("ascii", errors="replace").rstrip("\r")
            if time.monotonic() >= deadline:
                raise DeviceTimeout(f"no complete line within {timeout:g} s")
            self._fill()

    def read_until_quiet(self, quiet_s: float, timeout: float, *, whole_lines: bool = False) -> list[str]:
        """Lines until the device has been silent for ``quiet_s`` (at most ``timeout`` s).

        With ``whole_lines``, silence in the middle of a line does not end the read (a device slowed by a loaded
        host can pause between the bytes of one line); only ``timeout`` does.

        Returns
        -------
        list of str
            Complete lines; a trailing partial line (cut by ``timeout``) is returned too, except with
            ``whole_lines``: then it stays buffered and the next read returns it whole.

        Raises
        ------
        DeviceTimeout
            Nothing at all arrived within ``timeout``.
        """
        start = time.monotonic()
        last = None
        self._cut = False  # an answer is read whole
        while True:
            now = time.monotonic()
            if self._fill():
                last = time.monotonic()
            elif last is not None and now - last >= quiet_s and not (whole_lines and not self._buf.endswith(b"\n")):
                break
            if now - start >= timeout:
                if last is None:
                    raise DeviceTimeout(f"no answer within {timeout:g} s")
                break
        keep = len(self._buf)
        if whole_lines and not self._buf.endswith(b"\n"):   # a line cut by the timeout waits for its rest
            keep = self._buf.rfind(b"\n") + 1
        text = bytes(self._buf[:keep]).decode("ascii", errors="replace")
        del self._buf[:keep]
        return [ln.rstrip("\r") for ln in text.split("\n") if ln.strip()]

    def unread(self, data: bytes) -> None:
        """Put bytes read elsewhere (e.g. by a firmware probe) back in front of the buffer."""
        if data:
            self._buf[:0] = data

    def flush(self) -> None:
        """Drop what is buffered here and in the OS input queue (and the cut line that follows)."""
        self._buf.clear()
        self._cut = True
        try:
            self.ser.reset_input_buffer()
        except Exception:  # noqa: BLE001 - some URL handlers lack it; the buffer here is cleared anyway
            pass

    def write(self, data: bytes) -> None:
        import serial

        try:
            self.ser.write(data)
            self.ser.flush()
        except (serial.SerialException, OSError) as exc:
            raise ConnectionLost(f"serial link lost: {exc}") from None
