"""A device on a pseudo-terminal: the driver opens its port name like a real serial port.

The emulator thread owns the pty's master side: it reads what the driver
writes, hands the bytes to the device logic, and writes the device's output
without blocking (output waits in a queue while the driver is not reading:
backpressure, like a USB serial link's flow control). Every open and close of
the port is seen (inotify on the pty's device node; where that is missing,
the master side's hang-up clearing, which misses a close and reopen within
one tick), so a device can reset and greet the driver the way an Arduino
does after its open-time (DTR) reset, every time. The port name is a
symlink in a private folder, so a simulated unplug (:meth:`PtyDevice.disconnect`)
can bring the device back on a new pty under the same name.
"""

from __future__ import annotations

import abc
import ctypes
import ctypes.util
import errno
import os
import select
import struct
import tempfile
import threading
import time
import tty
from pathlib import Path

__all__ = ["PtyDevice"]

_IN_OPEN, _IN_CLOSE = 0x20, 0x08 | 0x10       # inotify: IN_OPEN, IN_CLOSE_WRITE | IN_CLOSE_NOWRITE


def _inotify_open_close(path: str) -> int:
    """A non-blocking inotify descriptor watching opens and closes of ``path``, or -1 where unavailable."""
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
        fd = libc.inotify_init1(os.O_NONBLOCK | os.O_CLOEXEC)
        if fd < 0:
            return -1
        if libc.inotify_add_watch(fd, path.encode(), _IN_OPEN | _IN_CLOSE) < 0:
            os.close(fd)
            return -1
        return fd
    except (OSError, AttributeError):
        return -1


def _open_close_events(fd: int) -> list[bool]:
    """The pending events of :func:`_inotify_open_close`, in order: True for an open, False for a close."""
    out = []
    while True:
        try:
            buf = os.read(fd, 4096)
        except BlockingIOError:
            return out
        except OSError:
            return out
        off = 0
        while off + 16 <= len(buf):
            _, mask, _, n = struct.unpack_from("iIII", buf, off)
            off += 16 + n
            if mask & _IN_OPEN:
                out.append(True)
            elif mask & _IN_CLOSE:
                out.append(False)


class PtyDevice(abc.ABC):
    """Base class of the pty emulators: subclasses implement :meth:`on_bytes` and :meth:`tick`.

    Parameters
    ----------
    name : str
        Used for the port symlink (``<tmpdir>/<name>``) and the thread name.
    tick_s : float
        Period of :meth:`tick` calls (device timers: motion, frame streaming).
    """

    def __init__(self, name: str, *, tick_s: float = 0.002) -> None:
        self.name = name
        self.tick_s = tick_s
        self._dir = Path(tempfile.mkdtemp(prefix="nlosplan-pty-"))
        self.port = str(self._dir / name)
        self._lock = threading.RLock()
        self._out = bytearray()
        self._master = self._slave = -1
        self._watch = -1
        self._stop = threading.Event()
        self._connected = threading.Event()
        self._thread: threading.Thread | None = None
        self.bytes_out = 0
        self._open_pty()

    # ------------------------------------------------------------------ pty
    def _open_pty(self) -> None:
        master, slave = os.openpty()
        tty.setraw(slave)
        os.set_blocking(master, False)
        tmp = self._dir / f".{self.name}.new"
        if tmp.exists() or tmp.is_symlink():
            tmp.unlink()
        name = os.ttyname(slave)
        tmp.symlink_to(name)
        tmp.replace(self.port)
        os.close(slave)  # only the driver holds the slave side: POLLHUP on the master means "not open"
        self._watch = _inotify_open_close(name)
        self._master, self._slave = master, -1
        self._connected.set()

    def _close_pty(self) -> None:
        self._connected.clear()
        for fd in (self._master, self._slave, self._watch):
            if fd >= 0:
                try:
                    os.close(fd)
                except OSError:
                    pass
        self._master = self._slave = self._watch = -1
        with self._lock:
            self._out.clear()

    def disconnect(self, down_s: float = 0.3) -> None:
        """Simulate an unplug: close the pty now, come back on a new one after ``down_s`` seconds."""
        self._close_pty()
        self.on_disconnect()

        def back() -> None:
            time.sleep(down_s)
            if not self._stop.is_set():
                self._open_pty()
                self.on_connect()

        threading.Thread(target=back, name=f"{self.name}-replug", daemon=True).start()

    # ------------------------------------------------------------------ hooks
    @abc.abstractmethod
    def on_bytes(self, data: bytes) -> None:
        """Bytes the driver wrote (every emulator speaks its own protocol here)."""

    def tick(self, now: float) -> None:
        """Called every ``tick_s`` seconds with ``time.monotonic()``."""

    def on_connect(self) -> None:
        """After the pty (re)appears."""

    def on_disconnect(self) -> None:
        """After an unplug."""

    def on_open(self) -> None:
        """The driver opened the port (a real Arduino resets here: DTR)."""

    def on_close(self) -> None:
        """The driver closed the port."""

    # ------------------------------------------------------------------ output
    def send(self, data: bytes | str) -> None:
        """Queue output for the driver."""
        if isinstance(data, str):
            data = data.encode("ascii")
        with self._lock:
            if self._connected.is_set():
                self._out += data

    def queued(self) -> int:
        """Output bytes not yet taken by the driver's side of the pty."""
        with self._lock:
            return len(self._out)

    def drop_output(self) -> None:
        with self._lock:
            self._out.clear()

    # ------------------------------------------------------------------ thread
    def start(self) -> "PtyDevice":
        self._thread = threading.Thread(target=self._run, name=f"{self.name}-emulator", daemon=True)
        self._thread.start()
        return self

    def _run(self) -> None:
        poller, registered, opened, opens = None, -1, False, 0
        while not self._stop.is_set():
            if not self._connected.is_set():
                poller, registered, opened, opens = None, -1, False, 0
                time.sleep(self.tick_s)
                continue
            master, watch = self._master, self._watch
            if registered != master:
                poller, registered = select.poll(), master
                poller.register(master, select.POLLIN)
                if watch >= 0:
                    poller.register(watch, select.POLLIN)
            with self._lock:
                want_write = bool(self._out)
            poller.modify(master, select.POLLIN | (select.POLLOUT if want_write else 0))
            try:
                events = poller.poll(self.tick_s * 1000)
            except (OSError, ValueError):
                time.sleep(self.tick_s)
                continue
            mask = 0
            for fd, ev in events:
                if fd == master:
                    mask |= ev
            hung = bool(mask & select.POLLHUP)
            if watch >= 0:   # every open and close, in order (a close and reopen within one tick included)
                for is_open in _open_close_events(watch):
                    opens = opens + 1 if is_open else max(opens - 1, 0)
                    if is_open and opens == 1 or not is_open and opens == 0 and opened:
                        opened = opens > 0
                        (self.on_open if opened else self.on_close)()
            elif hung != (not opened):  # the driver opened or closed the port
                opened = not hung
                (self.on_open if opened else self.on_close)()
            if hung:
                time.sleep(self.tick_s)
            if mask & select.POLLIN and not hung:
                try:
                    data = os.read(master, 4096)
                except OSError as exc:
                    data = b""
                    if exc.errno not in (errno.EAGAIN, errno.EIO):
                        raise
                if data:
                    self.on_bytes(data)
            if mask & select.POLLOUT and opened:
                with self._lock:
                    chunk = bytes(self._out[:4096])
                try:
                    n = os.write(master, chunk) if chunk else 0
                except OSError:
                    n = 0
                with self._lock:
                    del self._out[:n]
                self.bytes_out += n
            self.tick(time.monotonic())

    def close(self) -> None:
        """Stop the thread and remove the pty and its folder."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        self._close_pty()
        for p in self._dir.iterdir():
            p.unlink()
        self._dir.rmdir()

    def __enter__(self):
        return self.start() if self._thread is None else self

    def __exit__(self, *exc) -> None:
        self.close()
