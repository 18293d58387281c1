"""``bench rig``: host time per frame (parse + store) and parser throughput against the serial line rate."""

from __future__ import annotations

import os
import platform
import statistics
import tempfile
import time

import numpy as np

from nlosplan.hardware.tmf8828_protocol import FrameAssembler, ZoneMode, dump_lines, frame_dumps, obj_line

__all__ = ["bench_rig", "frame_text"]

BITS_PER_BYTE = 10  # 8N1: start bit, 8 data bits, stop bit


def frame_text(counts: np.ndarray, zones: ZoneMode, first_result: int = 0) -> list[str]:
    """The firmware lines of one frame (``#Raw`` dumps and ``#Obj`` records), with ``\\r\\n``."""
    lines, dumps = [], frame_dumps(counts, zones, reference=np.zeros(128, np.int64))
    per = zones.dumps_per_result
    for r in range(zones.results_per_frame):
        for d in dumps[r * per:(r + 1) * per]:
            lines += dump_lines(d)
        lines.append(obj_line(first_result + r))
    return [ln + "\r\n" for ln in lines]


def _frames(zones: ZoneMode, n: int, rng) -> list[list[str]]:
    rows, cols = zones.shape
    nres = zones.results_per_frame
    return [frame_text(rng.poisson(3000.0, size=(rows, cols, 128)), zones, (i * nres) % 256) for i in range(n)]


def _per_frame(zones: ZoneMode, n: int, store_path: str, synchronous: str, rng) -> dict:
    from nlosplan.hardware.rig import sensor_preset
    from nlosplan.data.store import CaptureStore

    sensor = sensor_preset(zones.value, "short")
    frames = _frames(zones, n, rng)
    asm = FrameAssembler(zones)
    parse, store_s = [], []
    with CaptureStore(store_path, synchronous=synchronous) as store:
        for i, lines in enumerate(frames):
            t0 = time.perf_counter()
            out = [f for ln in lines for f in asm.feed(ln)]
            t1 = time.perf_counter()
            store.put(out[0].counts, {"object": "A", "size": "8in", "position": i % 100, "lights": "off",
                                      "repeat": i // 100, "source": "bench:rig", "capture_id": f"bench/{i:06d}"},
                      sensor=sensor, meta={"step": i, "commanded_mm": [0.0, 0.0], "reported_mm": [0.0, 0.0]})
            t2 = time.perf_counter()
            parse.append(t1 - t0)
            store_s.append(t2 - t1)
    nbytes = sum(len(ln) for ln in frames[0])
    total = [a + b for a, b in zip(parse, store_s)]
    return {"zones": zones.value, "frames": n, "synchronous": synchronous, "bytes_per_frame": nbytes,
            "parse_ms_median": 1e3 * statistics.median(parse), "store_ms_median": 1e3 * statistics.median(store_s),
            "total_ms_median": 1e3 * statistics.median(total),
            "total_ms_p95": 1e3 * float(np.percentile(total, 95)),
            "line_time_ms": 1e3 * nbytes * BITS_PER_BYTE / 2_000_000}


def _throughput(zones: ZoneMode, seconds: float, rng) -> dict:
    frames = _frames(zones, 20, rng)
    lines = [ln for f in frames for ln in f]
    nbytes = sum(len(ln) for ln in lines)
    asm = FrameAssembler(zones)
    done, t0 = 0, time.perf_counter()
    while True:
        for ln in lines:
            asm.feed(ln)
        done += 1
        el = time.perf_counter() - t0
        if el >= seconds:
            break
    bps = done * nbytes / el
    line_rate = 2_000_000 / BITS_PER_BYTE
    return {"zones": zones.value, "bytes_per_second": bps, "frames_per_second": done * len(frames) / el,
            "line_rate_bytes_per_second": line_rate, "times_line_rate": bps / line_rate,
            "dropped_frames": asm.stats.dropped_frames}


def _end_to_end(seconds: float) -> dict:
    """Frames per second read by the driver from the emulated sensor over a pty (same process)."""
    from nlosplan.hardware.emulators import EmulatedTMF8828
    from nlosplan.hardware.tmf8828 import TMF8828

    mean = np.full((3, 3, 128), 3000.0)
    with EmulatedTMF8828(lambda z, r: (mean, 92.8), frame_period_s=0.0) as emu:
        lidar = TMF8828(emu.port, quiet_s=0.05)
        try:
            lidar.start("3x3", "short")
            lidar.read_frame()
            n, t0 = 0, time.perf_counter()
            while time.perf_counter() - t0 < seconds:
                lidar.read_frame()
                n += 1
            el = time.perf_counter() - t0
        finally:
            lidar.close()
    nbytes = sum(len(ln) for ln in frame_text(mean.astype(np.int64), ZoneMode.Z3X3))
    return {"zones": "3x3", "frames_per_second": n / el, "bytes_per_second": n * nbytes / el,
            "times_line_rate": n * nbytes / el / (2_000_000 / BITS_PER_BYTE)}


def bench_rig(*, frames_3x3: int = 300, frames_8x8: int = 60, seconds: float = 1.0, synchronous: str = "FULL",
              seed: int = 0, end_to_end: bool = True) -> dict:
    """Measure the host side of the rig.

    Parameters
    ----------
    frames_3x3, frames_8x8 : int
        Frames parsed and stored for the per-frame figures.
    seconds : float
        Timed seconds of each throughput figure.
    synchronous : {"FULL", "NORMAL"}
        The store's durability (the rig uses FULL: an fsync per capture).
    end_to_end : bool
        Also time the driver reading the emulated sensor over a pty.

    Returns
    -------
    dict
        ``per_frame`` (median/p95 ms per frame: parse, store, total; the
        frame's transfer time at 2 Mbaud), ``parser`` (bytes/s and multiple of
        the 2 Mbaud line rate, 200,000 bytes/s at 8N1), ``end_to_end``,
        ``targets`` (3x3 total <= 5 ms, parser >= 10x line rate, met or not), ``host``.
    """
    rng = np.random.default_rng(seed)
    with tempfile.TemporaryDirectory() as tmp:
        per = [_per_frame(ZoneMode.Z3X3, frames_3x3, os.path.join(tmp, "a.db"), synchronous, rng),
               _per_frame(ZoneMode.Z8X8, frames_8x8, os.path.join(tmp, "b.db"), synchronous, rng)]
    parser = [_throughput(ZoneMode.Z3X3, seconds, rng), _throughput(ZoneMode.Z8X8, seconds, rng)]
    out = {"per_frame": per, "parser": parser}
    if end_to_end:
        out["end_to_end"] = _end_to_end(seconds)
    out["targets"] = {"host_ms_per_3x3_frame_max": 5.0, "met_3x3": per[0]["total_ms_median"] <= 5.0,
                      "parser_times_line_rate_min": 10.0, "met_parser": min(p["times_line_rate"] for p in parser) >= 10}
    out["host"] = {"python": platform.python_version(), "machine": platform.machine(), "cpus": os.cpu_count(),
                   "load_1min": os.getloadavg()[0]}
    return out
