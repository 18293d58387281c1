"""LineReader.read_until_quiet: a pause inside a line (a device slowed by a loaded host) does not split it."""

import time

from nlosplan.hardware.transport import LineReader


class _Trickle:
    """A fake serial port that releases chunks of bytes at given times (s after creation)."""

    def __init__(self, chunks):
        self.t0 = time.monotonic()
        self.chunks = list(chunks)

    @property
    def in_waiting(self):
        return 0

    def read(self, n):
        now = time.monotonic() - self.t0
        if self.chunks and self.chunks[0][0] <= now:
            return self.chunks.pop(0)[1]
        time.sleep(0.005)
        return b""


def test_whole_lines_wait_through_a_pause_inside_a_line():
    chunks = [(0.0, b"ok\r\nA"), (0.25, b"LARM:8\r\n")]
    assert LineReader(_Trickle(chunks)).read_until_quiet(0.1, 2.0, whole_lines=True) == ["ok", "ALARM:8"]
    # without it, silence ends the read mid-line and the tail is returned as it is
    assert LineReader(_Trickle(chunks)).read_until_quiet(0.1, 2.0) == ["ok", "A"]


def test_whole_lines_still_end_at_the_timeout():
    reader = LineReader(_Trickle([(0.0, b"ok\r\nA"), (0.6, b"LARM:8\r\n")]))
    assert reader.read_until_quiet(0.05, 0.4, whole_lines=True) == ["ok"]
    # the cut line waited in the buffer: the next read returns it whole
    assert reader.read_until_quiet(0.05, 1.0, whole_lines=True) == ["ALARM:8"]
