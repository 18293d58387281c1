"""Benchmark of histogram formation (``nlosplan bench histogram``).

Times the full sensor pipeline -- exact binning through pulse + jitter,
ambient, Poisson noise, 24-bit clip -- for 3x3x128 and 8x8x128 frames, one
frame per call and batched with ``vmap``, with the JAX compile time reported
apart. A NumPy/SciPy implementation of the same expected histogram + Poisson
draw runs in the same process as the baseline for the speed-up ratio.
"""

from __future__ import annotations

import time
from typing import Callable

import numpy as np
from scipy.special import erfc

from nlosplan._jax import jax, jnp
from nlosplan.sensor_models.config import SensorConfig
from nlosplan.constants import MAX_COUNT_24BIT
from nlosplan.sensor_models.noise import CaptureNoise, floor_per_bin
from nlosplan.sensor_models.pipeline import expected_counts
from nlosplan.sensor_models.presets import preset


def _frame_fn(sensor: SensorConfig, dtype) -> Callable:
    edges = jnp.asarray(sensor.bin_edges_ps(), dtype)
    bg = floor_per_bin(sensor, lights_on=True)
    noise = CaptureNoise(MAX_COUNT_24BIT)

    def frame(key, times, weights):
        mean = expected_counts(
            times, weights, edges_ps=edges, sigma_ps=jnp.asarray(sensor.impulse_sigma_ps, dtype),
            photon_scale=sensor.photon_scale, iterations=float(sensor.iterations),
            floor_per_bin=bg, max_count=None,
        )
        return noise.draw(key, mean)

    return frame


def _numpy_frame(rng, sensor: SensorConfig, times, weights):
    edges = sensor.bin_edges_ps()
    s = sensor.impulse_sigma_ps
    cdf = 0.5 * erfc(-(edges - times[..., None]) / (s * np.sqrt(2)))
    lam = np.einsum("...kb,...k->...b", np.diff(cdf, axis=-1), weights * sensor.photon_scale)
    lam = lam + floor_per_bin(sensor, True)
    return np.minimum(rng.poisson(lam * sensor.iterations), sensor.max_count)


def _time(fn: Callable[[], object], min_seconds: float) -> tuple[float, int]:
    n, t0 = 0, time.perf_counter()
    while True:
        out = fn()
        jax.block_until_ready(out) if not isinstance(out, np.ndarray) else None
        n += 1
        elapsed = time.perf_counter() - t0
        if elapsed >= min_seconds:
            return elapsed / n, n


def bench_histogram(
    *, arrivals_per_zone: int = 16, batch: int = 256, min_seconds: float = 1.0, dtypes=("float32", "float64")
) -> dict:
    """Measure histogram formation throughput.

    Parameters
    ----------
    arrivals_per_zone : int
        Arrival impulses per zone (K).
    batch : int
        Frames per batched (vmap) call.
    min_seconds : float
        Minimum timed duration per measurement.
    dtypes : sequence of str
        Float dtypes to measure.

    Returns
    -------
    dict
        ``{"rows": [{"zones", "dtype", "mode", "frames_per_second",
        "zone_histograms_per_second", "seconds_per_call", "compile_seconds",
        "speedup_vs_numpy"}...], "config": {...}}``.
    """
    rows = []
    for zones in ((3, 3), (8, 8)):
        sensor = preset("tmf8828-3x3-short").replace(
            zones_rows=zones[0], zones_cols=zones[1], jitter_fwhm_ps=100.0, pulse_shape=None, pulse_fwhm_ps=200.0
        )
        rng = np.random.default_rng(0)
        shape = zones + (arrivals_per_zone,)
        times = rng.uniform(2000.0, 9000.0, shape)
        weights = rng.uniform(1e-4, 1e-2, shape)
        nz = zones[0] * zones[1]
        np_rng = np.random.default_rng(1)
        np_sec, _ = _time(lambda: _numpy_frame(np_rng, sensor, times, weights), min_seconds)
        rows.append(dict(zones=f"{zones[0]}x{zones[1]}", dtype="float64", mode="numpy-baseline",
                         frames_per_second=1 / np_sec, zone_histograms_per_second=nz / np_sec,
                         seconds_per_call=np_sec, compile_seconds=0.0, speedup_vs_numpy=1.0))
        for dtype_name in dtypes:
            dtype = jnp.dtype(dtype_name)
            frame = _frame_fn(sensor, dtype)
            t_j, w_j = jnp.asarray(times, dtype), jnp.asarray(weights, dtype)
            single = jax.jit(frame)
            batched = jax.jit(jax.vmap(frame))
            keys = jax.random.split(jax.random.key(0), batch)
            tb, wb = jnp.broadcast_to(t_j, (batch,) + shape), jnp.broadcast_to(w_j, (batch,) + shape)
            for mode, fn, args, frames in (
                ("single", single, (jax.random.key(0), t_j, w_j), 1),
                (f"batched-{batch}", batched, (keys, tb, wb), batch),
            ):
                t0 = time.perf_counter()
                jax.block_until_ready(fn(*args))
                compile_s = time.perf_counter() - t0
                sec, _ = _time(lambda: fn(*args), min_seconds)
                fps = frames / sec
                rows.append(dict(zones=f"{zones[0]}x{zones[1]}", dtype=dtype_name, mode=mode,
                                 frames_per_second=fps, zone_histograms_per_second=fps * nz,
                                 seconds_per_call=sec, compile_seconds=compile_s,
                                 speedup_vs_numpy=fps * np_sec))
    return {
        "rows": rows,
        "config": {
            "arrivals_per_zone": arrivals_per_zone,
            "n_bins": 128,
            "terms": "Gaussian IRF (pulse 200 ps + jitter 100 ps FWHM), ambient, Poisson, 24-bit clip",
            "jax_devices": [str(d) for d in jax.devices()],
        },
    }
