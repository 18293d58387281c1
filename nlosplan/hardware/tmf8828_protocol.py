"""The ams TMF8828 Arduino firmware's text protocol: modes, start sequences, line and frame parsing.

Pure functions and a line-fed frame assembler; no serial port here (the
driver, :mod:`nlosplan.hardware.tmf8828`, feeds it lines). Facts and their
sources are in SENSOR_FACTS.md.

Lines
-----
``#Raw,<addr>,<n>,<b0>,...,<b127>`` (131 fields), n = 0..29: channel
``n % 10`` (0 is the reference SPAD), byte plane ``n // 10`` (0 LSB, 1 mid,
2 MSB); a channel's count is ``b0 + 256 b1 + 65536 b2`` (24 bits). ``#Cal``
has the same layout (calibration histograms). ``#Obj,<addr>,<result_number>,
<temperature>,<n_valid>,<systick>,`` then 36 ``<distance_mm>,<confidence>``
pairs (78 fields). Anything else (``#Err``, ``#Conf``, help text, the
recording script's ``#RCo``/``#CCo``) is skipped.

Frames
------
One *dump* is the 30 ``#Raw`` lines of one readout (10 channels x 128 bins).
The firmware prints the dumps of one measurement result, then its ``#Obj``
line. The zone modes differ in how many dumps a result has, how many results
make a frame and which channels are zones (DENALI/cc-hardware driver):

=====  ===========  =============  ========  ==========================================
mode   dumps/result results/frame  channels  zone of (dump s, channel c)
=====  ===========  =============  ========  ==========================================
3x3    1            1              1-9       row-major zone c - 1
4x4    2            1              1-8       row-major zone 8 s + c - 1
8x8    2            4              1-8       the fixed TMF8828 pixel map (:func:`zone_map_8x8`)
=====  ===========  =============  ========  ==========================================

In 8x8 mode the four results of a frame are told apart by
``result_number % 4`` (the sub-capture; the four time-multiplexed 4x4
captures of DS §7.4.4), so the assembler can start at any result and waits
for sub-capture 0. A frame is returned only when every line of every dump and
every ``#Obj`` line arrived in order and parsed; otherwise it is dropped and
counted (:class:`AssemblerStats`), never returned.
"""

from __future__ import annotations

import enum
import time
from dataclasses import dataclass, field

import numpy as np

from nlosplan.constants import MAX_COUNT_24BIT as MAX_COUNT  # a bin register's maximum, defined once

__all__ = ["AssemblerStats", "Dump", "Frame", "FrameAssembler", "LineError", "ObjResult", "RangeMode", "ZoneMode",
           "dump_lines", "frame_dumps", "obj_line", "parse_hist_line", "parse_obj_line", "start_sequence", "zone_map", "zone_map_8x8"]

N_BINS = 128
N_CHANNELS = 10
N_LINES = 30  # lines per dump: 10 channels x 3 byte planes


class ZoneMode(enum.Enum):
    """Zone layout of the TMF8828 (the firmware's SPAD map)."""

    Z3X3 = "3x3"
    Z4X4 = "4x4"
    Z8X8 = "8x8"

    @property
    def shape(self) -> tuple[int, int]:
        """(rows, cols) of zones."""
        n = int(self.value[0])
        return n, n

    @property
    def dumps_per_result(self) -> int:
        return 1 if self is ZoneMode.Z3X3 else 2

    @property
    def results_per_frame(self) -> int:
        return 4 if self is ZoneMode.Z8X8 else 1

    @property
    def channels(self) -> int:
        """Zone channels per dump (channels 1..this)."""
        return 9 if self is ZoneMode.Z3X3 else 8


class RangeMode(enum.Enum):
    """Ranging mode: the firmware starts in long range; ``O`` toggles to short (≈ 1.5 m window)."""

    SHORT = "short"
    LONG = "long"


def start_sequence(zones: ZoneMode, range_mode: RangeMode) -> list[str]:
    """Single-character commands that start the DENALI firmware in a mode.

    ``h`` (help, proves the link), ``d`` (disable), then ``o`` + ``E``
    (TMF882x firmware: 3x3; ``c`` next configuration for 4x4) or ``e``
    (TMF8828 firmware: 8x8), ``O`` for short range, ``z`` (histogram dumps
    on: raw), ``m`` (measure). SENSOR_FACTS.md, the DENALI start sequence.
    """
    seq = ["h", "d"]
    if zones is ZoneMode.Z8X8:
        seq += ["e"]
    else:
        seq += ["o", "E"] + (["c"] if zones is ZoneMode.Z4X4 else [])
    if range_mode is RangeMode.SHORT:
        seq += ["O"]
    return seq + ["z", "m"]


_PIX8_BASE = (57, 61, 41, 45, 25, 29, 9, 13)  # pixel (1..64) of channels 1..8 in dump 0


def zone_map(zones: ZoneMode) -> np.ndarray:
    """Flat zone index (row-major) of every (dump in frame, channel 1..channels).

    Returns
    -------
    ndarray of int, shape (dumps per frame, channels)
    """
    if zones is ZoneMode.Z3X3:
        return np.arange(9).reshape(1, 9)
    if zones is ZoneMode.Z4X4:
        return np.arange(16).reshape(2, 8)
    out = np.empty((8, 8), int)
    for s in range(8):
        for c in range(8):
            pixel = _PIX8_BASE[c] + (s % 4) - (8 if s >= 4 else 0)
            out[s, c] = pixel - 1  # pixel p is row (p-1)//8, col (p-1)%8
    return out


def zone_map_8x8() -> np.ndarray:
    """The 8x8 pixel map: zone index (0..63, row-major) of (sub-capture dump 0..7, channel 1..8)."""
    return zone_map(ZoneMode.Z8X8)


class LineError(ValueError):
    """A protocol line that does not parse (garbled, truncated, out of range)."""


def _ints(fields: list[str], what: str) -> np.ndarray:
    try:
        return np.array(fields, dtype=np.int64)
    except ValueError:
        raise LineError(f"{what}: a field is not an integer") from None


def parse_hist_line(line: str) -> tuple[str, int, int, np.ndarray]:
    """Parse a ``#Raw``/``#Cal`` line.

    Returns
    -------
    kind : {"Raw", "Cal"}
    address : int
        I2C address.
    n : int
        Sub-packet 0..29 (channel ``n % 10``, byte plane ``n // 10``).
    values : ndarray of int64, shape (128,)
        Bytes 0..255.

    Raises
    ------
    LineError
        Wrong field count, non-integer fields, n or a byte out of range.
    """
    parts = line.split(",")
    if len(parts) != 3 + N_BINS:
        raise LineError(f"{parts[0][:8]!r} line has {len(parts)} fields, expected {3 + N_BINS}")
    kind = parts[0][1:]
    if kind not in ("Raw", "Cal"):
        raise LineError(f"not a histogram line: {parts[0][:8]!r}")
    head = _ints(parts[1:3], kind)
    values = _ints(parts[3:], kind)
    n = int(head[1])
    if not 0 <= n < N_LINES:
        raise LineError(f"{kind} sub-packet {n} is out of range 0..29")
    if values.min() < 0 or values.max() > 255:
        raise LineError(f"{kind} byte out of range 0..255")
    return kind, int(head[0]), n, values


@dataclass(frozen=True)
class ObjResult:
    """One ``#Obj`` result record.

    Attributes
    ----------
    address, result_number, temperature_c, n_valid, systick : int
    distance_mm : ndarray of int64, shape (36,)
    confidence : ndarray of int64, shape (36,)
    """

    address: int
    result_number: int
    temperature_c: int
    n_valid: int
    systick: int
    distance_mm: np.ndarray
    confidence: np.ndarray

    def to_dict(self) -> dict:
        return {"result_number": self.result_number, "temperature_c": self.temperature_c,
                "n_valid": self.n_valid, "systick": self.systick}


def parse_obj_line(line: str) -> ObjResult:
    """Parse an ``#Obj`` line (78 fields).

    Raises
    ------
    LineError
        Wrong field count or a non-integer field.
    """
    parts = line.split(",")
    if len(parts) != 78 or parts[0] != "#Obj":
        raise LineError(f"#Obj line has {len(parts)} fields, expected 78")
    v = _ints(parts[1:], "#Obj")
    pairs = v[5:].reshape(36, 2)
    return ObjResult(int(v[0]), int(v[1]), int(v[2]), int(v[3]), int(v[4]), pairs[:, 0].copy(), pairs[:, 1].copy())


@dataclass(frozen=True)
class Dump:
    """One complete histogram readout: counts of the 10 channels, shape (10, 128), int64."""

    kind: str
    address: int
    counts: np.ndarray


@dataclass(frozen=True)
class Frame:
    """One assembled frame.

    Attributes
    ----------
    zones : ZoneMode
    counts : ndarray of int64, shape (rows, cols, 128)
        24-bit counts per zone and bin.
    reference : ndarray of int64, shape (dumps, 128)
        Channel 0 (reference SPAD) of every dump of the frame.
    results : tuple of ObjResult
        The frame's ``#Obj`` records (1, or 4 in 8x8 mode).
    received_s : float
        ``time.monotonic()`` when the last line arrived.
    """

    zones: ZoneMode
    counts: np.ndarray
    reference: np.ndarray
    results: tuple
    received_s: float = 0.0


@dataclass
class AssemblerStats:
    """Counters of a :class:`FrameAssembler` (what was returned, dropped or skipped)."""

    lines: int = 0
    frames: int = 0
    dropped_frames: int = 0
    dropped_dumps: int = 0
    garbage_lines: int = 0
    skipped_lines: int = 0
    calibration_dumps: int = 0

    def to_dict(self) -> dict:
        return dict(self.__dict__)


class _DumpBuilder:
    """Assembles the 30 lines of one dump in order."""

    def __init__(self) -> None:
        self.planes = np.zeros((3, N_CHANNELS, N_BINS), np.int64)
        self.next = -1  # -1: no dump in progress
        self.address = 0

    def add(self, n: int, address: int, values: np.ndarray) -> tuple[Dump | None, bool]:
        """Add line n; returns (finished dump or None, whether a partial dump was abandoned)."""
        abandoned = False
        if n == 0:
            abandoned = self.next > 0
            self.next, self.address = 0, address
        elif n != self.next:   # a line lost or out of order: this dump cannot complete
            abandoned = self.next > 0
            self.next = -1
            return None, abandoned
        plane, ch = divmod(n, N_CHANNELS)
        self.planes[plane, ch] = values
        self.next += 1
        if self.next == N_LINES:
            self.next = -1
            counts = self.planes[0] + (self.planes[1] << 8) + (self.planes[2] << 16)
            return Dump("", self.address, counts), abandoned
        return None, abandoned

    def abandon(self) -> bool:
        was = self.next > 0
        self.next = -1
        return was


class FrameAssembler:
    """Turns firmware lines into complete frames; resynchronises after garbage.

    Parameters
    ----------
    zones : ZoneMode or str

    Examples
    --------
    >>> asm = FrameAssembler("3x3")
    >>> frames = [f for line in lines for f in asm.feed(line)]  # doctest: +SKIP
    """

    def __init__(self, zones: ZoneMode | str) -> None:
        self.zones = ZoneMode(zones)
        self.stats = AssemblerStats()
        self._map = zone_map(self.zones)
        self._raw = _DumpBuilder()
        self._cal = _DumpBuilder()
        self.last_calibration: Dump | None = None
        self._group: list[Dump] = []
        self._group_bad = False
        self._subs: list[tuple[list[Dump], ObjResult]] = []
        self._frame_bad = False
        self._syncing = False

    def reset(self) -> None:
        """Forget partial dumps and frames and resynchronise (e.g. after flushing input).

        Until the ``#Obj`` line that ends a frame, lines are only counted: the
        rest of a frame cut by the flush is neither returned nor counted as dropped.
        """
        self._raw.abandon()
        self._cal.abandon()
        self._group, self._group_bad, self._subs, self._frame_bad = [], False, [], False
        self._syncing = True

    def _corrupt(self) -> None:
        self._group_bad = True

    def _drop_frame(self) -> None:
        if self._subs or self._group or self._frame_bad or self._group_bad:
            self.stats.dropped_frames += 1
        self._subs, self._frame_bad = [], False

    def feed(self, line: str) -> list[Frame]:
        """Feed one line (with or without its line ending); returns the frames it completes (0 or 1)."""
        line = line.strip("\r\n\x00 ")
        if not line:
            return []
        self.stats.lines += 1
        head = line[:4]
        if self._syncing:
            if head == "#Obj":
                try:
                    rn = parse_obj_line(line).result_number
                except LineError:
                    return []
                self._syncing = rn % self.zones.results_per_frame != self.zones.results_per_frame - 1
            return []
        if head in ("#Raw", "#Cal"):
            builder = self._raw if head == "#Raw" else self._cal
            try:
                kind, addr, n, values = parse_hist_line(line)
            except LineError:
                self.stats.garbage_lines += 1
                if builder.abandon():
                    self.stats.dropped_dumps += 1
                if head == "#Raw":
                    self._corrupt()
                return []
            dump, abandoned = builder.add(n, addr, values)
            if abandoned:
                self.stats.dropped_dumps += 1
                if kind == "Raw":
                    self._corrupt()
            if dump is not None:
                if kind == "Cal":
                    self.stats.calibration_dumps += 1
                    self.last_calibration = Dump("Cal", dump.address, dump.counts)
                else:
                    self._group.append(Dump("Raw", dump.address, dump.counts))
            return []
        if head == "#Obj":
            try:
                obj = parse_obj_line(line)
            except LineError:
                self.stats.garbage_lines += 1
                self._group, self._group_bad = [], False
                self._frame_bad = True
                self._drop_frame()
                return []
            return self._end_result(obj)
        if line[0] == "#" and line[1:4].isalpha():
            self.stats.skipped_lines += 1
        elif any(ord(ch) < 32 or ord(ch) > 126 for ch in line) or line.count(",") > 3:
            self.stats.garbage_lines += 1   # binary noise or a cut-off data line
            if self._raw.abandon():
                self.stats.dropped_dumps += 1
                self._corrupt()
        else:
            self.stats.skipped_lines += 1   # firmware text (help, state, banners)
        return []

    def _end_result(self, obj: ObjResult) -> list[Frame]:
        if self._raw.abandon():  # a result record in the middle of a dump
            self.stats.dropped_dumps += 1
            self._group_bad = True
        group, bad = self._group, self._group_bad
        self._group, self._group_bad = [], False
        nsub = self.zones.results_per_frame
        sub = obj.result_number % nsub
        if bad or len(group) != self.zones.dumps_per_result:
            self._frame_bad = True
            self._drop_frame()
            return []
        if sub == 0:
            if self._subs or self._frame_bad:
                self._drop_frame()
        elif sub != len(self._subs) or self._frame_bad or not self._subs:
            # a result out of order, or the frame's start was missed: wait for sub-capture 0
            if self._subs or self._frame_bad:
                self._drop_frame()
            return []
        elif (obj.result_number - self._subs[-1][1].result_number) % 256 != 1:
            self._drop_frame()
            return []
        self._subs.append((group, obj))
        if len(self._subs) < nsub:
            return []
        frame = self._assemble()
        self._subs = []
        self.stats.frames += 1
        return [frame]

    def _assemble(self) -> Frame:
        rows, cols = self.zones.shape
        dumps = [d for group, _ in self._subs for d in group]
        flat = np.zeros((rows * cols, N_BINS), np.int64)
        nch = self.zones.channels
        for s, d in enumerate(dumps):
            flat[self._map[s]] = d.counts[1:nch + 1]
        ref = np.stack([d.counts[0] for d in dumps])
        return Frame(self.zones, flat.reshape(rows, cols, N_BINS), ref, tuple(o for _, o in self._subs),
                     time.monotonic())


# ------------------------------------------------------------------ writing (emulator side)
def dump_lines(counts: np.ndarray, kind: str = "Raw", address: int = 65) -> list[str]:
    """The 30 lines of one dump.

    Parameters
    ----------
    counts : array of int, shape (10, 128)
        Channel counts, 0 to 2**24 - 1 (clipped).
    """
    c = np.clip(np.asarray(counts, np.int64), 0, MAX_COUNT)
    out = []
    for plane in range(3):
        b = (c >> (8 * plane)) & 0xFF
        for ch in range(N_CHANNELS):
            out.append(f"#{kind},{address},{plane * 10 + ch}," + ",".join(map(str, b[ch].tolist())))
    return out


def obj_line(result_number: int, *, address: int = 65, temperature_c: int = 25, systick: int = 0,
             distances_mm=None, confidences=None) -> str:
    """An ``#Obj`` line (36 distance/confidence pairs; zeros where not given)."""
    d = np.zeros(36, np.int64) if distances_mm is None else np.asarray(distances_mm, np.int64)
    k = np.zeros(36, np.int64) if confidences is None else np.asarray(confidences, np.int64)
    valid = int(np.count_nonzero(k))
    pairs = ",".join(f"{a},{b}" for a, b in zip(d.tolist(), k.tolist()))
    return f"#Obj,{address},{result_number % 256},{temperature_c},{valid},{systick},{pairs}"


def frame_dumps(counts: np.ndarray, zones: ZoneMode, reference: np.ndarray | None = None) -> list[np.ndarray]:
    """Split a frame's zone counts (rows, cols, 128) into its dumps' channel arrays, each (10, 128)."""
    zm = zone_map(zones)
    flat = np.asarray(counts, np.int64).reshape(-1, N_BINS)
    out = []
    for s in range(zm.shape[0]):
        d = np.zeros((N_CHANNELS, N_BINS), np.int64)
        if reference is not None:
            d[0] = reference
        d[1:zm.shape[1] + 1] = flat[zm[s]]
        out.append(d)
    return out
