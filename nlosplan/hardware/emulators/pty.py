"""A device on a pseudo-terminal: the driver opens its port name like a real serial port.

The emulator thread owns the pty's master side: it reads what the driver
writes, hands the bytes to the device logic, and writes the device's output
without blocking (output waits in a queue while the driver is not reading:
backpressure, like a USB serial link's flow control). Opening the port is
seen as the master side's hang-up clearing, so a device can greet the
driver the way an Arduino does after its open-time reset. The port name is a
symlink in a private folder, so a simulated unplug (:meth:`PtyDevice.disconnect`)
can bring the device back on a new pty under the same name.
"""

from __future__ import annotations

import abc
import errno
import os
import select
import tempfile
import threading
import time
import tty
from pathlib import Path

__all__ = ["PtyDevice"]


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
        tmp.symlink_to(os.ttyname(slave))
        tmp.replace(self.port)
        os.close(slave)  # only the driver holds the slave side: POLLHUP on the master means "not open"
        self._master, self._slave = master, -1
        self._connected.set()

    def _close_pty(self) -> None:
        self._connected.clear()
        for fd in (self._master, self._slave):
            if fd >= 0:
                try:
                    os.close(fd)
                except OSError:
                    pass
        self._master = self._slave = -1
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
        poller, registered, opened = None, -1, False
        while not self._stop.is_set():
            if not self._connected.is_set():
                poller, registered, opened = None, -1, False
                time.sleep(self.tick_s)
                continue
            master = self._master
            if registered != master:
                poller, registered = select.poll(), master
                poller.register(master, select.POLLIN)
            with self._lock:
                want_write = bool(self._out)
            poller.modify(master, select.POLLIN | (select.POLLOUT if want_write else 0))
            try:
                events = poller.poll(self.tick_s * 1000)
            except (OSError, ValueError):
                time.sleep(self.tick_s)
                continue
            mask = 0
            for _, ev in events:
                mask |= ev
            hung = bool(mask & select.POLLHUP)
            if hung != (not opened):  # the driver opened or closed the port
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
