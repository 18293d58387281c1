"""Cross-validation of the two simulators on the DENALI rig.

Both backends model the same physics (flash -> wall -> object -> wall ->
zone, cosines and ``1/r^2`` per leg, one-sided surfaces; a retroreflective
lobe plus a Lambertian base; objects that do not shadow each other), so
their three-bounce histograms must agree. The reflectance models checked
(:data:`MODELS`): Lambertian objects, the mixed model (retroreflective lobe
plus diffuse base) and a Lambertian object with its mount and plate in the
signal. Per case (model, object, size, gantry position):

- normalized relative L1: ``sum |twin - fast| / sum |fast|`` over every zone and bin
  of the signal (capture minus the no-object capture);
- centroid shift: the largest difference, over the zones holding at least
  5 % of the signal, of the signal's mean bin (bins).

Targets (issues 4 and 16): L1 <= 5 % and centroid within 0.5 bin for every case.
"""

from __future__ import annotations

import time

import numpy as np

from nlosplan.errors import UserError
from nlosplan.sensor_models.presets import preset
from nlosplan.simulators.fast.simulator import FastSimulator
from nlosplan.simulators.mitsuba.simulator import TwinSimulator
from nlosplan.simulators.presets.denali import denali_scene

L1_TARGET = 0.05
CENTROID_TARGET_BINS = 0.5
#: Zones below this share of the signal are left out of the centroid comparison (their centroid is noise).
ZONE_SHARE = 0.05
#: Reflectance models of the cross-validation: name -> ``denali_scene`` options. "mixed": a 2 deg
#: retroreflective lobe of albedo 0.4 on a Lambertian base of 0.4; "mount": a Lambertian object (0.5) with
#: the mount and plate (0.8) in the signal (a background without the mount).
MODELS: dict[str, dict] = {
    "lambertian": {"reflectance": "lambertian"},
    "mixed": {"reflectance": "retroreflective", "albedo": 0.4, "diffuse_albedo": 0.4},
    "mount": {"reflectance": "lambertian", "mount": True, "mount_in_background": False},
}


def check_models(models) -> tuple[str, ...]:
    """The model names, validated (one-line :class:`UserError` naming an unknown one)."""
    out = tuple(models)
    if not out:
        raise UserError(f"no cross-validation model given; allowed: {', '.join(MODELS)}")
    for m in out:
        if m not in MODELS:
            raise UserError(f"unknown cross-validation model {m!r}; allowed: {', '.join(MODELS)}")
    return out


def compare_signals(twin: np.ndarray, fast: np.ndarray) -> dict:
    """L1 and centroid agreement of two signal histograms.

    Parameters
    ----------
    twin, fast : ndarray, shape (..., zones..., n_bins)
        Background-subtracted three-bounce counts; ``fast`` is the reference.

    Returns
    -------
    dict
        ``rel_l1``, ``centroid_shift_bins`` (worst zone with >= 5 % of the
        signal), ``total_ratio`` (twin / fast signal sum).
    """
    a = np.asarray(twin, dtype=np.float64).reshape(-1, twin.shape[-1])
    b = np.asarray(fast, dtype=np.float64).reshape(-1, fast.shape[-1])
    total = np.abs(b).sum()
    if total <= 0:
        raise ValueError("the reference signal is zero: nothing to compare")
    bins = np.arange(b.shape[-1])
    keep = b.sum(-1) >= ZONE_SHARE * b.sum()
    ca = (a[keep] * bins).sum(-1) / np.maximum(a[keep].sum(-1), 1e-300)
    cb = (b[keep] * bins).sum(-1) / b[keep].sum(-1)
    return {"rel_l1": float(np.abs(a - b).sum() / total), "centroid_shift_bins": float(np.max(np.abs(ca - cb))),
            "total_ratio": float(a.sum() / b.sum())}


def cross_validate(objects=("A", "circle", "3"), sizes=("4in", "8in"), positions=range(0, 100, 10), *,
                   models=("lambertian",), sensor: str = "tmf8828-3x3-short", twin_fidelity=None,
                   fast_fidelity: str = "high", seed: int = 0, progress=None) -> dict:
    """Twin against fast backend, every model x object x size x position.

    Parameters
    ----------
    objects, sizes, positions : sequences
        DENALI objects, sizes and gantry positions (0..99).
    models : sequence of str
        Names in :data:`MODELS` (default: Lambertian objects only).
    sensor : str
        Sensor preset.
    twin_fidelity : dict or str, optional
        The twin's knobs (default ``spp=4096, zone_sub=8``).
    fast_fidelity : str
        Fast backend level (float64).
    seed : int
        Twin seed (each case uses ``seed + case index``).
    progress : callable, optional
        Called with a short text after each case.

    Returns
    -------
    dict
        ``cases`` (object, size, position, rel_l1, centroid_shift_bins,
        total_ratio, twin_seconds, fast_seconds, passed), ``summary``
        (worst and mean L1 and centroid, cases passed) and ``config``.
    """
    models = check_models(models)
    s = preset(sensor)
    twin_fidelity = twin_fidelity or {"spp": 4096, "zone_sub": 8}
    cases = []
    k = 0
    for model in models:
        for obj in objects:
            for size in sizes:
                for pos in positions:
                    scene = denali_scene(obj, size, int(pos), **MODELS[model])
                    t0 = time.perf_counter()
                    twin = TwinSimulator(scene, s, fidelity=twin_fidelity, seed=seed + k).expected(parts=True)["object"]
                    t1 = time.perf_counter()
                    fast = FastSimulator(scene, s, fidelity=fast_fidelity, dtype="float64").expected(parts=True)["object"]
                    t2 = time.perf_counter()
                    m = compare_signals(twin, fast)
                    ok = m["rel_l1"] <= L1_TARGET and m["centroid_shift_bins"] <= CENTROID_TARGET_BINS
                    cases.append({"model": model, "object": obj, "size": size, "position": int(pos), **m,
                                  "twin_seconds": t1 - t0, "fast_seconds": t2 - t1, "passed": bool(ok)})
                    k += 1
                    if progress is not None:
                        progress(f"{model} {obj}_{size} p{int(pos)}: L1 {100 * m['rel_l1']:.2f} %")
    l1 = np.array([c["rel_l1"] for c in cases])
    cen = np.array([c["centroid_shift_bins"] for c in cases])
    summary = {"cases": len(cases), "passed": int(sum(c["passed"] for c in cases)),
               "rel_l1_max": float(l1.max()), "rel_l1_mean": float(l1.mean()),
               "centroid_shift_max_bins": float(cen.max()), "centroid_shift_mean_bins": float(cen.mean()),
               "l1_target": L1_TARGET, "centroid_target_bins": CENTROID_TARGET_BINS}
    config = {"sensor": sensor, "twin_fidelity": twin_fidelity if isinstance(twin_fidelity, (str, dict)) else
              twin_fidelity.to_dict(), "fast_fidelity": fast_fidelity, "seed": seed, "models": list(models),
              "model_options": {m: MODELS[m] for m in models}}
    return {"cases": cases, "summary": summary, "config": config}


def format_table(result: dict) -> str:
    """Markdown table: per model, object and size, worst and mean L1 and centroid over the positions."""
    rows = ["| model | object | size | positions | rel. L1 max | rel. L1 mean | centroid shift max (bins) | "
            "twin/fast total | passed |", "|---|---|---|---|---|---|---|---|---|"]
    groups: dict = {}
    for c in result["cases"]:
        groups.setdefault((c.get("model", "lambertian"), c["object"], c["size"]), []).append(c)
    for (model, obj, size), cs in groups.items():
        l1 = [c["rel_l1"] for c in cs]
        cen = [c["centroid_shift_bins"] for c in cs]
        tr = [c["total_ratio"] for c in cs]
        rows.append(f"| {model} | {obj} | {size} | {len(cs)} | {100 * max(l1):.2f} % | {100 * np.mean(l1):.2f} % | "
                    f"{max(cen):.3f} | {min(tr):.3f}-{max(tr):.3f} | {sum(c['passed'] for c in cs)}/{len(cs)} |")
    s = result["summary"]
    rows.append(f"| **all** | | | {s['cases']} | **{100 * s['rel_l1_max']:.2f} %** | {100 * s['rel_l1_mean']:.2f} % | "
                f"**{s['centroid_shift_max_bins']:.3f}** | | {s['passed']}/{s['cases']} |")
    return "\n".join(rows)
