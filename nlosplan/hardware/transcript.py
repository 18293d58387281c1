"""A serial stand-in that replays a command/response transcript (STYLE.md 5).

Each pair is (bytes the driver must write, bytes the device answers). A write
that differs from the next expected one fails at once with both shown, and
:meth:`TranscriptSerial.assert_consumed` fails on any pair left over, so a
test proves the driver sent exactly the transcript's bytes, in order.
"""

from __future__ import annotations

__all__ = ["TranscriptError", "TranscriptSerial"]


class TranscriptError(AssertionError):
    """The driver wrote something the transcript did not expect (or left pairs unconsumed)."""


class TranscriptSerial:
    """Replays ``pairs`` of (expected write, answer); ``greeting`` is readable before any write.

    Parameters
    ----------
    pairs : list of (bytes, bytes)
    greeting : bytes
        What the device says on its own when the port opens (a banner).
    """

    def __init__(self, pairs, greeting: bytes = b"") -> None:
        self.pairs = [(bytes(w), bytes(a)) for w, a in pairs]
        self._out = bytearray(greeting)
        self._pending = bytearray()
        self.written = bytearray()
        self.timeout = 0.0
        self.port = "transcript"
        self.is_open = True

    @property
    def in_waiting(self) -> int:
        return len(self._out)

    def write(self, data: bytes) -> int:
        self.written += data
        self._pending += data
        while self.pairs and self._pending:
            want = self.pairs[0][0]
            n = min(len(want), len(self._pending))
            if bytes(self._pending[:n]) != want[:n]:
                raise TranscriptError(f"driver wrote {bytes(self._pending)!r}, transcript expects {want!r}")
            if n < len(want):
                break
            del self._pending[:n]
            self._out += self.pairs.pop(0)[1]
        if self._pending and not self.pairs:
            raise TranscriptError(f"driver wrote {bytes(self._pending)!r} after the transcript ended")
        return len(data)

    def read(self, n: int = 1) -> bytes:
        data = bytes(self._out[:n])
        del self._out[:n]
        return data

    def flush(self) -> None:
        pass

    def reset_input_buffer(self) -> None:
        self._out.clear()

    def close(self) -> None:
        self.is_open = False

    def assert_consumed(self) -> None:
        """Raise :class:`TranscriptError` if pairs remain or a partial write is pending."""
        if self.pairs or self._pending:
            raise TranscriptError(f"{len(self.pairs)} transcript pair(s) not consumed, next {self.pairs[:1]!r}; "
                                  f"pending write {bytes(self._pending)!r}")
