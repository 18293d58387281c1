"""Misbehaving ports for the rig's bad-input tests: one that never answers, one that sends only noise."""

from __future__ import annotations

import time

import numpy as np

from nlosplan.hardware.emulators.pty import PtyDevice


class SilentPort(PtyDevice):
    """A port that takes every byte and never says anything (a device that is off, or another port)."""

    def __init__(self) -> None:
        super().__init__("silent")

    def on_bytes(self, data: bytes) -> None:
        pass


class NoisePort(PtyDevice):
    """A port that streams random bytes (with a line end now and then), as a device at the wrong baud rate does."""

    def __init__(self, seed: int = 0, bytes_per_s: float = 20000.0) -> None:
        super().__init__("noise")
        self._rng = np.random.default_rng(seed)
        self._rate = bytes_per_s
        self._last = time.monotonic()

    def on_bytes(self, data: bytes) -> None:
        pass

    def tick(self, now: float) -> None:
        n = int((now - self._last) * self._rate)
        if n < 64 or self.queued() > 4096:
            return
        self._last = now
        chunk = self._rng.integers(128, 256, size=n, dtype=np.uint8)
        chunk[self._rng.random(n) < 0.02] = ord("\n")
        self.send(chunk.tobytes())


class ChattyPort(PtyDevice):
    """Answers every byte with a line of text and streams text lines after ``m``: printable, never histograms
    (another Arduino sketch on the sensor's port)."""

    def __init__(self) -> None:
        super().__init__("chatty")
        self._streaming = False
        self._next = 0.0

    def on_bytes(self, data: bytes) -> None:
        for ch in data.decode("ascii", errors="replace"):
            self.send(f"got {ch}\r\n")
            self._streaming = self._streaming or ch == "m"

    def tick(self, now: float) -> None:
        if self._streaming and now >= self._next and self.queued() < 4096:
            self._next = now + 0.01
            self.send("temperature,21.5,humidity,40\r\n")
