"""Error against run time of both simulators against a converged twin reference (``nlosplan bench fidelity``).

Scenes: DENALI 3x3 with Lambertian objects (both backends model the same
physics there). Reference: the twin at ``reference_spp`` samples per pixel
on :data:`REFERENCE_ZONE_SUB` film pixels per zone axis (its own Monte-Carlo
error is estimated from two independent halves and reported). Error: relative L1 of the three-bounce histogram summed over the
scenes; seconds: per scene, compile and scene loading included for the
twin's render (what a user waits for), JAX compile excluded for the fast
backend (a warm-up call per level, then the mean of 5 calls; also batched:
the scenes' objects at 10 positions each in one call). The speed-up at equal error compares
each fast level's time with the twin's time at the same error, interpolated
in log-log between twin levels (or extrapolated with the Monte-Carlo slope
``error ~ time^-1/2`` beyond them).
"""

from __future__ import annotations

import math
import time

import numpy as np

from nlosplan.sensor_models.presets import preset
from nlosplan.simulators.fast.simulator import FastSimulator
from nlosplan.simulators.mitsuba.simulator import TwinSimulator
from nlosplan.simulators.presets.denali import denali_scene

FAST_LEVELS = ("draft", "low", "default", "high")
TWIN_LEVELS = ("draft", "low", "default", "high", "reference")
#: Film pixels per zone axis of the converged reference (16: its wall quadrature is finer than every level's
#: but the twin ``reference`` level's own; at 8 it differed from 16 by 0.44 % L1).
REFERENCE_ZONE_SUB = 16
SCENES = (("A", "8in", 19), ("circle", "4in", 73), ("3", "4in", 47), ("minus", "8in", 99))


def _rel_l1(a, b) -> float:
    return float(np.abs(np.asarray(a) - np.asarray(b)).sum() / np.abs(np.asarray(b)).sum())


def twin_time_at_error(twin_rows: list[dict], error: float) -> float:
    """Twin seconds per scene at ``error``: log-log interpolation, Monte-Carlo slope -1/2 outside the rows."""
    pts = sorted((r["rel_l1_error"], r["seconds"]) for r in twin_rows)
    errs = np.log([p[0] for p in pts])
    secs = np.log([p[1] for p in pts])
    le = math.log(error)
    if le <= errs[0]:  # more accurate than the best twin level: t ~ e^-2
        return float(math.exp(secs[0] - 2.0 * (le - errs[0])))
    if le >= errs[-1]:
        return float(math.exp(secs[-1] - 2.0 * (le - errs[-1])))
    return float(math.exp(np.interp(le, errs, secs)))


def bench_fidelity(*, fast_levels=FAST_LEVELS, twin_levels=TWIN_LEVELS, scenes=SCENES,
                   sensor: str = "tmf8828-3x3-short", reference_spp: int = 32768, seed: int = 0,
                   progress=None) -> dict:
    """Rows of (backend, fidelity, seconds, rel_l1_error) and the speed-up at equal error.

    Returns
    -------
    dict
        ``rows`` (backend, fidelity, seconds per scene, rel_l1_error,
        centroid-free), ``reference`` (spp, its own error, seconds),
        ``speedup_at_equal_error`` (at the fast ``default`` level, or the
        first fast level given), ``speedups`` per fast level, ``config``.
    """
    s = preset(sensor)
    sc = [denali_scene(o, z, p, reflectance="lambertian") for o, z, p in scenes]
    tell = progress or (lambda text: None)
    t0 = time.perf_counter()
    half = reference_spp // 2
    ref_fid = {"spp": half, "zone_sub": REFERENCE_ZONE_SUB}
    ref_a = [TwinSimulator(x, s, fidelity=ref_fid, seed=seed + 1000).expected(parts=True)["object"] for x in sc]
    ref_b = [TwinSimulator(x, s, fidelity=ref_fid, seed=seed + 2000).expected(parts=True)["object"] for x in sc]
    ref = [0.5 * (a + b) for a, b in zip(ref_a, ref_b)]
    # the mean of two halves has half the variance of one half: its error is ~ |a - b| / 2
    ref_self = 0.5 * _rel_l1(np.stack(ref_a), np.stack(ref_b))
    ref_seconds = (time.perf_counter() - t0) / len(sc)
    tell(f"reference: {reference_spp} spp, own error {100 * ref_self:.2f} %")
    rows = []
    for level in fast_levels:
        sims = [FastSimulator(x, s, fidelity=level, dtype="float32") for x in sc]
        for sim in sims:
            sim.expected(parts=True)  # compile (the same static arguments as the timed call)
        reps = 5
        t = time.perf_counter()
        for _ in range(reps):
            outs = [sim.expected(parts=True)["object"] for sim in sims]
        sec = (time.perf_counter() - t) / (reps * len(sc))
        batch = FastSimulator([denali_scene(o, z, p, reflectance="lambertian") for o, z, _ in scenes
                               for p in range(0, 100, 10)], s, fidelity=level, dtype="float32")
        batch.expected(parts=True)  # compile
        t = time.perf_counter()
        batch.expected(parts=True)
        sec_batched = (time.perf_counter() - t) / len(batch.scenes)
        rows.append({"backend": "fast", "fidelity": level, "seconds": sec, "seconds_batched": sec_batched,
                     "rel_l1_error": _rel_l1(np.stack(outs), np.stack(ref))})
        tell(f"fast {level}: {100 * rows[-1]['rel_l1_error']:.2f} %")
    for level in twin_levels:
        t = time.perf_counter()
        outs = [TwinSimulator(x, s, fidelity=level, seed=seed).expected(parts=True)["object"] for x in sc]
        sec = (time.perf_counter() - t) / len(sc)
        rows.append({"backend": "mitsuba", "fidelity": level, "seconds": sec,
                     "rel_l1_error": _rel_l1(np.stack(outs), np.stack(ref))})
        tell(f"twin {level}: {100 * rows[-1]['rel_l1_error']:.2f} %")
    twin_rows = [r for r in rows if r["backend"] == "mitsuba"]
    speedups = {r["fidelity"]: twin_time_at_error(twin_rows, r["rel_l1_error"]) / r["seconds"]
                for r in rows if r["backend"] == "fast"}
    batched = {r["fidelity"]: twin_time_at_error(twin_rows, r["rel_l1_error"]) / r["seconds_batched"]
               for r in rows if r["backend"] == "fast"}
    key = "default" if "default" in speedups else next(iter(speedups))
    return {"rows": rows, "speedup_at_equal_error": speedups[key], "speedup_level": key, "speedups": speedups,
            "speedup_at_equal_error_batched": batched[key], "speedups_batched": batched,
            "reference": {"spp": reference_spp, "zone_sub": REFERENCE_ZONE_SUB, "rel_l1_self_error": ref_self,
                          "seconds_per_scene": ref_seconds},
            "config": {"sensor": sensor, "scenes": [f"{o}_{z} p{p}" for o, z, p in scenes],
                       "reflectance": "lambertian", "seed": seed}}


def format_bench_fidelity(result: dict) -> str:
    """The rows as a Markdown table and the speed-up line."""
    lines = ["| backend | fidelity | seconds / scene | seconds / scene, batched | rel. L1 vs twin reference |",
             "|---|---|---|---|---|"]
    for r in result["rows"]:
        b = f"{r['seconds_batched']:.4g}" if "seconds_batched" in r else "-"
        lines.append(f"| {r['backend']} | {r['fidelity']} | {r['seconds']:.4g} | {b} | {100 * r['rel_l1_error']:.2f} % |")
    ref = result["reference"]
    lines.append(f"reference: twin at {ref['spp']} spp ({ref['seconds_per_scene']:.1f} s / scene), own error "
                 f"{100 * ref['rel_l1_self_error']:.2f} %")
    lines.append(f"speed-up of the fast backend over the twin at equal error ({result['speedup_level']}): "
                 f"{result['speedup_at_equal_error']:.0f}x; per level: " +
                 ", ".join(f"{k} {v:.0f}x" for k, v in result["speedups"].items()))
    if "speedups_batched" in result:
        n = 10 * len(result["config"]["scenes"])
        lines.append(f"batched ({n} scenes per call): {result['speedup_at_equal_error_batched']:.0f}x at "
                     f"{result['speedup_level']}; per level: " +
                     ", ".join(f"{k} {v:.0f}x" for k, v in result["speedups_batched"].items()))
    return "\n".join(lines)
