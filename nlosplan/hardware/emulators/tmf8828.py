"""An emulated TMF8828 on the ams Arduino firmware, on a pty: commands, modes and histogram streaming.

It answers the single-character commands of SENSOR_FACTS.md with short
text, keeps the firmware's state (TMF8828/TMF882x firmware, configuration,
short/long range, histogram dump mode) and, while measuring, prints frames in
the firmware's format (``#Raw`` byte planes, ``#Cal`` in the dump modes that
ask for it, ``#Obj`` records; 8x8 as four results of two dumps each with the
fixed pixel map). The counts come from ``expected(zones, range)`` (the
simulator at the emulated gantry's current position, see
:mod:`nlosplan.hardware.bench_factory`) with Poisson noise from a seeded
generator, clipped to 24 bits. Channel 0 (the reference SPAD) carries a
stand-in pulse (2,000 counts peak at bin 8): the simulator does not model it.
"""

from __future__ import annotations

import threading
import time
from typing import Callable

import numpy as np

from nlosplan.hardware.emulators.faults import SensorFaults, garble, truncate
from nlosplan.hardware.emulators.pty import PtyDevice
from nlosplan.hardware.tmf8828_protocol import MAX_COUNT, N_BINS, ZoneMode, dump_lines, frame_dumps, obj_line
from nlosplan.sensor_models.noise import CaptureNoise

__all__ = ["EmulatedTMF8828"]

HELP = ("TMF8828 Arduino driver (emulated)", "h help, d disable, e enable TMF8828, E enable TMF882x, o toggle mode",
        "O toggle short/long range, c next configuration, z histogram dump mode, m measure, s stop")
_REF = 2000.0 * np.exp(-0.5 * ((np.arange(N_BINS) - 8.0) / 1.5) ** 2)
C_MM_PER_PS = 0.299792458 / 2  # one-way distance per picosecond of round trip


class EmulatedTMF8828(PtyDevice):
    """TMF8828 firmware on a pty (use :attr:`port` as the LiDAR port).

    Parameters
    ----------
    expected : callable
        ``expected(zones: str, range: str) -> (mean counts (rows, cols, 128), bin width ps)``,
        called once per frame.
    frame_period_s : float
        Minimum seconds between frame starts (the real sensor: ~0.03 s
        ranging, ~0.3 s with histogram dumps over serial).
    seed : int
        Poisson noise seed.
    faults : SensorFaults, optional
    address : int
        I2C address printed in every line (65 = 0x41).
    """

    def __init__(self, expected: Callable, *, frame_period_s: float = 0.05, seed: int = 0,
                 faults: SensorFaults | None = None, address: int = 65) -> None:
        super().__init__("lidar")
        self.expected = expected
        self.frame_period_s = frame_period_s
        self.rng = np.random.default_rng(seed)
        self.faults = faults or SensorFaults()
        self._frng = np.random.default_rng(self.faults.seed)
        self.address = address
        self._flock = threading.Lock()
        self._firmware_reset()
        self.frames_sent = 0
        self.data_lines = 0
        self._next_frame = 0.0
        self._result = 0
        self._unplugged = False
        self._pending: list[tuple[float, list[str]]] = []
        self.commands: list[str] = []

    def _firmware_reset(self) -> None:
        self.tmf8828_mode = True    # firmware image: TMF8828 (8x8) or TMF882x (3x3/4x4)
        self.config = 0             # 'c' configuration in TMF882x mode: 0 3x3, 1 4x4
        self.enabled = False
        self.short_range = False
        self.dump_mode = 0          # 0 off, 1 raw, 2 cal, 3 both
        self.measuring = False

    @property
    def zones(self) -> ZoneMode:
        if self.tmf8828_mode:
            return ZoneMode.Z8X8
        return ZoneMode.Z4X4 if self.config == 1 else ZoneMode.Z3X3

    # ------------------------------------------------------------------ hooks
    def on_open(self) -> None:
        with self._flock:   # an Arduino Uno resets when its port opens
            self._firmware_reset()
            self._pending.clear()
        self.drop_output()
        self.send("Tmf8828 Arduino Uno\r\n")

    def on_bytes(self, data: bytes) -> None:
        for ch in data.decode("ascii", errors="replace"):
            if ch in "\r\n ":
                continue
            self.commands.append(ch)
            lines = self._command(ch)
            if lines:
                due = time.monotonic() + self.faults.slow_answer_s
                with self._flock:
                    self._pending.append((due, lines))

    def _command(self, ch: str) -> list[str]:
        with self._flock:
            if ch == "h":
                return list(HELP)
            if ch == "d":
                self.measuring, self.enabled = False, False
                return ["TMF8828 state=0 (disabled)"]
            if ch == "e":
                self.tmf8828_mode, self.enabled = True, True
                return ["Download TMF8828 firmware", "TMF8828 state=1 (app running)"]
            if ch == "E":
                self.tmf8828_mode, self.enabled, self.config = False, True, 0
                return ["Download TMF882x firmware", "TMF8828 state=1 (app running)"]
            if ch == "o":
                self.tmf8828_mode = not self.tmf8828_mode
                return ["TMF8828 mode" if self.tmf8828_mode else "TMF882x mode"]
            if ch == "c":
                self.config = (self.config + 1) % 2
                return [f"#Conf,{self.address},{self.config},{self.zones.value}"]
            if ch == "O":
                self.short_range = not self.short_range
                return ["Short range" if self.short_range else "Long range"]
            if ch == "z":
                self.dump_mode = (self.dump_mode + 1) % 4
                return [f"Histogram is {self.dump_mode}"]
            if ch == "m":
                if not self.enabled:
                    return [f"#Err,{self.address},not enabled"]
                self.measuring = True
                self._next_frame = time.monotonic()
                return ["Measure"]
            if ch == "s":
                self.measuring = False
                return ["Stop"]
            if ch in "pwflrxaitq+-#":
                return [f"cmd {ch}"]
            return [f"#Err,{self.address},unknown command {ch!r}"]

    def tick(self, now: float) -> None:
        with self._flock:
            due = [t for t in self._pending if t[0] <= now]
            if due:
                self._pending = [t for t in self._pending if t[0] > now]
            measuring = self.measuring
        for _, lines in due:
            self.send("".join(f"{ln}\r\n" for ln in lines))
        if not measuring or now < self._next_frame or self.queued():
            return
        self._next_frame = now + self.frame_period_s
        self._emit_frame()

    # ------------------------------------------------------------------ frames
    def _emit_frame(self) -> None:
        zones = self.zones
        mean, bin_ps = self.expected(zones.value, "short" if self.short_range else "long")
        counts = CaptureNoise(MAX_COUNT).draw(self.rng, mean)  # the sensor's noise model: Poisson, 24-bit clip
        ref = CaptureNoise().draw(self.rng, _REF)
        dumps = frame_dumps(counts, zones, ref)
        peak = np.argmax(counts.reshape(-1, N_BINS), axis=1)
        flat_dist = np.rint((peak + 0.5) * bin_ps * C_MM_PER_PS).astype(np.int64)
        lines: list[str] = []
        per, nres = zones.dumps_per_result, zones.results_per_frame
        self._result = -(-self._result // nres) * nres % 256  # sub-capture k has result_number % 4 == k
        for r in range(zones.results_per_frame):
            for d in dumps[r * per:(r + 1) * per]:
                if self.dump_mode in (2, 3):
                    cal = np.zeros_like(d)
                    cal[0] = ref
                    lines += dump_lines(cal, "Cal", self.address)
                if self.dump_mode in (1, 3):
                    lines += dump_lines(d, "Raw", self.address)
            dist = np.zeros(36, np.int64)
            conf = np.zeros(36, np.int64)
            k = min(18, flat_dist.size)
            dist[:k], conf[:k] = flat_dist[:k], 100
            lines.append(obj_line(self._result, address=self.address, systick=int(time.monotonic() * 1e6) % 2**32,
                                  distances_mm=dist, confidences=conf))
            self._result = (self._result + 1) % 256
        self.send("".join(f"{ln}\r\n" for ln in self._faulty(lines)))
        self.frames_sent += 1
        n = self.faults.disconnect_after_frames
        if n and self.frames_sent == n and not self._unplugged:
            self._unplugged = True
            self.disconnect(self.faults.down_s)

    def _faulty(self, lines: list[str]) -> list[str]:
        f = self.faults
        if not (f.garble_every or f.truncate_every or f.drop_every):
            self.data_lines += len(lines)
            return lines
        out = []
        for ln in lines:
            self.data_lines += 1
            k = self.data_lines
            if f.drop_every and k % f.drop_every == 0:
                continue
            if f.garble_every and k % f.garble_every == 0:
                ln = garble(ln, self._frng)
            if f.truncate_every and k % f.truncate_every == 0:
                ln = truncate(ln, self._frng)
            out.append(ln)
        return out
