"""Error against run time of the fast simulator (``nlosplan bench simulate``).

For each fidelity level the benchmark times DENALI 3x3 expected histograms
one scene per call and batched over the gantry positions (JAX compile time
apart), and measures the error of the three-bounce (object) histogram
against a converged float64 reference. It also times what pruning saves
(the plan leaving out what a scene does not need) and compares the achieved
arithmetic rate with a float32 matrix product measured in the same process.

Error measures (on the background-subtracted three-bounce histogram
``h = expected(parts=True)["object"]``, which is ``expected - background``
without pile-up and saturation):

- relative L1: ``sum |h - ref| / sum |ref|`` over all zones and bins, the
  largest over the reference positions;
- centroid shift: ``|c(h) - c(ref)|`` in bins with ``c(h) = sum_b b h_b /
  sum_b h_b`` per zone, the largest over positions and over zones that hold
  at least :data:`CENTROID_MIN_SHARE` of the largest zone's object light.

Examples
--------
>>> res = bench_simulate(levels=("draft",), positions=range(4), reference_positions=(0,))  # doctest: +SKIP
>>> print(format_bench_simulate(res))  # doctest: +SKIP
"""

from __future__ import annotations

import dataclasses
import math
import time
from typing import Callable, Iterable, Sequence

import numpy as np

from nlosplan._jax import jax
from nlosplan.denali import N_POSITIONS
from nlosplan.errors import UserError
from nlosplan.sensor_models.config import SensorConfig
from nlosplan.sensor_models import compiled
from nlosplan.resources import default_threads
from nlosplan.sensor_models.presets import resolve_sensor
from nlosplan.sensor_models.transient import default_deposit
from nlosplan.simulators.fast.bench_metrics import (
    CENTROID_MIN_SHARE,
    FLOPS_DEPOSIT,
    FLOPS_FAR_COUPLING,
    FLOPS_POLYGON,
    FLOPS_RETRO_PATH,
    MATMUL_N,
    best_time,
    errors,
    flop_estimate,
    load_average,
    machine_facts,
    matmul_gflops,
    max_rel_diff,
    xla_cost,
)
from nlosplan.simulators.fast.fidelity import FIDELITY_LEVELS, Fidelity
from nlosplan.simulators.fast.simulator import FastSimulator
from nlosplan.simulators.presets.denali import denali_scene

#: Target of the fast simulator: relative L1 error of the object histogram at most this ...
TARGET_REL_L1 = 0.01
#: ... at this many DENALI 3x3x128 expected histograms per second, batched.
TARGET_SCENES_PER_SECOND = 200.0
#: Stretch target (histograms per second).
STRETCH_SCENES_PER_SECOND = 1000.0
#: ``FastSimulator`` options of the path before issue 20, timed beside the current one by ``--baseline``:
#: two scalar scatter-adds, each chunk's parameters gathered from the device arrays on every call, the chunks one
#: after the other.
BASELINE_PATH = {"deposit": "scatter", "cache_chunks": False, "threads": 1}
#: Default levels, reference positions and plot path.
DEFAULT_LEVELS = ("draft", "low", "default", "high")
#: A mixed batch: five objects of every class (letters, shapes, digits) and both sizes; the reference
#: positions hold A_8in, S_8in, circle_4in, 3_8in and minus_4in.
DEFAULT_OBJECTS = ("A", "S", "circle", "3", "minus")
DEFAULT_SIZES = ("8in", "4in")
DEFAULT_REFERENCE_POSITIONS = (0, 21, 47, 73, 99)
DEFAULT_PLOT = "nlosplan-out/bench_simulate.png"
#: The level whose pruning and arithmetic are studied.
STUDY_LEVEL = "default"
#: Scene models timed at the study level and scored against the reference: name -> ``denali_scene`` options.
#: "mixed": DENALI's Table-2 fit (retroreflective 0.36 on a Lambertian base of 0.2, docs/scene-physics.md);
#: "mixed+mount": the same with the mount and its plate (0.8) in the signal.
MODEL_OPTIONS: dict[str, dict] = {
    "retroreflective": {},
    "mixed": {"albedo": 0.36, "diffuse_albedo": 0.2},
    "mixed+mount": {"albedo": 0.36, "diffuse_albedo": 0.2, "mount": True, "mount_in_background": False},
}

Progress = Callable[[str], None]


def check_levels(levels: Iterable[str]) -> tuple[str, ...]:
    """The timed fidelity levels of a benchmark run, checked: known, not ``reference``, none twice."""
    out = tuple(levels)
    allowed = [k for k in FIDELITY_LEVELS if k != "reference"]
    if not out:
        raise UserError(f"give at least one fidelity level; allowed: {', '.join(allowed)}")
    for lv in out:
        if lv == "reference":
            raise UserError("the 'reference' level is the benchmark's reference; it cannot also be a timed level")
        if lv not in FIDELITY_LEVELS:
            raise UserError(f"unknown fidelity level {lv!r}; allowed: {', '.join(allowed)}")
    if len(set(out)) != len(out):
        raise UserError("a fidelity level is given twice")
    return out


def _check_positions(positions: Iterable[int], what: str) -> tuple[int, ...]:
    out = tuple(positions)
    if not out:
        raise UserError(f"give at least one {what}")
    for p in out:
        if isinstance(p, bool) or not isinstance(p, (int, np.integer)) or not 0 <= p < N_POSITIONS:
            raise UserError(f"{what} {p!r} is not allowed; allowed: integers 0 to {N_POSITIONS - 1}")
    if len(set(out)) != len(out):
        raise UserError(f"a {what} is given twice")
    return tuple(int(p) for p in out)


def bench_steps(levels: Sequence[str] = DEFAULT_LEVELS, reference_positions: Sequence[int] = DEFAULT_REFERENCE_POSITIONS,
                models: Sequence[str] = tuple(MODEL_OPTIONS), baseline: bool = False) -> int:
    """Number of ``progress`` calls :func:`bench_simulate` makes (for a progress bar)."""
    parts = sum(_lambertian_parts(MODEL_OPTIONS[m]) for m in models)
    mounts = sum(bool(MODEL_OPTIONS[m].get("mount")) for m in models)
    return (2 * len(levels) + 2 * len(reference_positions) + 5 + (2 if baseline else 1) * len(models) + mounts
            + parts * len(reference_positions))


def _lambertian_parts(options: dict) -> int:
    """Lambertian parts of a model's scene referenced on their own: the diffuse base, the mount and its plate."""
    base = 1 if options.get("diffuse_albedo", 0.0) > 0 else 0
    mount = 2 if options.get("mount") and not options.get("mount_in_background", True) else 0
    return base + mount


def _check_models(models: Iterable[str]) -> tuple[str, ...]:
    out = tuple(models)
    for m in out:
        if m not in MODEL_OPTIONS:
            raise UserError(f"unknown scene model {m!r}; allowed: {', '.join(MODEL_OPTIONS)}")
    if len(set(out)) != len(out):
        raise UserError("a scene model is given twice")
    return out


def _warm_and_time(sim: FastSimulator, repeats: int, min_seconds: float) -> tuple[float, float]:
    """``(first_call_seconds, best_call_seconds)`` of ``sim.expected()``; the first call compiles."""
    t0 = time.perf_counter()
    sim.expected()
    first = time.perf_counter() - t0
    return first, best_time(sim.expected, repeats, min_seconds)


def _built(scenes, sensor, **kw) -> tuple[FastSimulator, float]:
    t0 = time.perf_counter()
    sim = FastSimulator(scenes, sensor, **kw)
    return sim, time.perf_counter() - t0


def bench_simulate(
    *,
    levels: Sequence[str] = DEFAULT_LEVELS,
    positions: Iterable[int] = range(N_POSITIONS),
    reference_positions: Sequence[int] = DEFAULT_REFERENCE_POSITIONS,
    objects: Sequence[str] = DEFAULT_OBJECTS,
    sizes: Sequence[str] = DEFAULT_SIZES,
    sensor: str | SensorConfig = "tmf8828-3x3-short",
    dtype: str = "float32",
    repeats: int = 3,
    progress: Progress | None = None,
    study_level: str = STUDY_LEVEL,
    matmul_n: int = MATMUL_N,
    min_seconds: float = 1.0,
    models: Sequence[str] = tuple(MODEL_OPTIONS),
    baseline: bool = False,
) -> dict:
    """Error against run time of the fast simulator on the DENALI preset.

    Parameters
    ----------
    levels : sequence of str
        Fidelity levels to time (names of :data:`FIDELITY_LEVELS`, not ``reference``).
    positions : iterable of int
        Gantry positions of the batched timing (0..99).
    reference_positions : sequence of int
        Positions (among ``positions``) where the error is measured against
        the float64 ``reference`` level (about 10-20 s each on a CPU).
    objects, sizes : sequence of str
        DENALI objects and sizes of the batch: position ``p`` holds
        ``objects[p % len(objects)]`` at ``sizes[(p // len(objects)) % len(sizes)]``
        (one mixed batch, as a dataset builder runs it).
    sensor : str or SensorConfig
        Preset name, sensor file, or configuration.
    dtype : {"float32", "float64"}
        Precision of the timed levels (the reference is always float64).
    repeats : int
        Timed calls per figure, at least (the fastest is kept).
    progress : callable, optional
        Called with a short text before each step (:func:`bench_steps` of them).
    study_level : str
        Level of the pruning study and of the arithmetic estimate.
    matmul_n : int
        Size of the float32 matrix product that measures the arithmetic peak.
    min_seconds : float
        Each figure keeps calling for at least this long (the fastest call is
        kept), so that a busy machine has quiet moments to show.
    baseline : bool
        Also time each scene model with the path of before issue 20 (:data:`BASELINE_PATH`) beside
        the current one, in the same process: ``models[i]["baseline"]`` and ``speed_ratio_vs_baseline``.
    models : sequence of str
        Scene models (:data:`MODEL_OPTIONS`) timed back to back at
        ``study_level`` and scored against their own reference.

    Returns
    -------
    dict
        ``levels`` (one dict per level: ``fidelity``, ``knobs``,
        ``seconds_single``, ``seconds_per_scene_batched``,
        ``scenes_per_second``, ``compile_seconds``, ``rel_l1_error``,
        ``centroid_shift_bins`` and more), ``reference``, ``pruning``,
        ``arithmetic``, ``models`` (one dict per scene model:
        ``model``, ``options``, ``scenes_per_second``,
        ``speed_ratio_vs_retroreflective``, ``rel_l1_error``,
        ``centroid_shift_bins``, ``paths_per_scene``), ``machine`` and
        ``config``.
    """
    levels = check_levels(levels)
    models = _check_models(models)
    check_levels([study_level])
    positions = _check_positions(positions, "position")
    reference_positions = _check_positions(reference_positions, "reference position")
    missing = sorted(set(reference_positions) - set(positions))
    if missing:
        raise UserError(f"reference positions {missing} are not among the timed positions; "
                        "choose reference positions inside --positions")
    if str(dtype) not in ("float32", "float64"):
        raise UserError(f"dtype={dtype!r} is not supported; allowed: float32, float64")
    if isinstance(repeats, bool) or not isinstance(repeats, (int, np.integer)) or repeats < 1:
        raise UserError(f"repeats={repeats!r} must be an integer >= 1")
    sensor_cfg = resolve_sensor(sensor) if isinstance(sensor, str) else sensor
    if not isinstance(sensor_cfg, SensorConfig):
        raise UserError("sensor must be a preset name, a sensor file, or a SensorConfig")
    say = progress or (lambda _text: None)
    # compile times are measured here, not loaded from the on-disk compilation cache (nlosplan._jax)
    cached = jax.config.jax_enable_compilation_cache
    jax.config.update("jax_enable_compilation_cache", False)
    try:
        return _bench(levels, positions, reference_positions, objects, sizes, sensor_cfg, dtype, repeats, say,
                      study_level, matmul_n, min_seconds, models, baseline)
    finally:
        jax.config.update("jax_enable_compilation_cache", cached)


def _bench(levels, positions, reference_positions, objects, sizes, sensor_cfg, dtype, repeats, say, study_level,
           matmul_n, min_seconds, models, baseline) -> dict:
    """:func:`bench_simulate` on checked arguments."""
    machine = machine_facts()
    kernel_ok, kernel_why = compiled.status()
    t_start = time.perf_counter()

    objects, sizes = tuple(objects), tuple(sizes)
    scenes = [_scene(objects, sizes, p) for p in positions]
    index = {p: i for i, p in enumerate(positions)}
    single_position = reference_positions[0]
    rows: list[dict] = []
    level_objects: dict[str, dict] = {}
    for lv in levels:
        say(f"{lv}: batched over {len(scenes)} positions")
        sim, plan_s = _built(scenes, sensor_cfg, fidelity=lv, dtype=dtype)
        first, best = _warm_and_time(sim, repeats, min_seconds)
        obj_h = sim.expected(parts=True)["object"]
        level_objects[lv] = {p: obj_h[index[p]] for p in reference_positions}
        say(f"{lv}: one scene per call")
        one, plan1_s = _built(scenes[index[single_position]], sensor_cfg, fidelity=lv, dtype=dtype)
        first1, single = _warm_and_time(one, repeats, min_seconds)
        rows.append({
            "fidelity": lv,
            "knobs": FIDELITY_LEVELS[lv].to_dict(),
            "seconds_single": single,
            "seconds_per_scene_batched": best / len(scenes),
            "scenes_per_second": len(scenes) / best,
            "compile_seconds": max(first1 - single, 0.0),
            "rel_l1_error": math.nan,
            "centroid_shift_bins": math.nan,
            "compile_seconds_batched": max(first - best, 0.0),
            "plan_seconds_single": plan1_s,
            "plan_seconds_batched": plan_s,
            "paths_per_scene": sim.plan.paths,
            "paths_per_scene_single": one.plan.paths,
        })

    reference = _reference(scenes, index, reference_positions, sensor_cfg, say)
    for row in rows:
        err = errors(level_objects[row["fidelity"]], reference["_ref"])
        row.update(rel_l1_error=err["rel_l1_error"], centroid_shift_bins=err["centroid_shift_bins"],
                   errors_per_position=err["per_position"])
    model_rows = _models(models, objects, sizes, positions, index, reference_positions, reference["_ref"], sensor_cfg,
                         study_level, dtype, repeats, min_seconds, say, baseline)
    reference.pop("_ref")

    pruning, study_sim = _pruning(objects, sizes, positions, sensor_cfg, study_level, dtype, repeats, min_seconds, say)
    say("arithmetic: flop count and float32 matmul peak")
    arithmetic = _arithmetic(study_sim, pruning["prune_seconds"], repeats, matmul_n, min_seconds)
    machine["load_average_end"] = load_average()
    return {
        "levels": rows,
        "reference": reference,
        "pruning": pruning,
        "arithmetic": arithmetic,
        "models": model_rows,
        "machine": machine,
        "config": {
            "preset": "denali", "objects": list(objects), "sizes": list(sizes),
            "scenes": {str(p): f"{sc.meta['object']}_{sc.meta['size']}" for p, sc in zip(positions, scenes)
                       if p in reference_positions},
            "sensor": sensor_cfg.name, "dtype": str(dtype),
            "zones": f"{sensor_cfg.zones_rows}x{sensor_cfg.zones_cols}", "n_bins": sensor_cfg.n_bins,
            "lights": "off", "positions": list(positions), "reference_positions": list(reference_positions),
            "deposit": default_deposit(), "kernels": {"available": kernel_ok, "why": kernel_why},
            "threads": default_threads(),
            "single_position": single_position, "repeats": int(repeats), "min_seconds": float(min_seconds),
            "timing": "fastest call (at least repeats calls and min_seconds of calling), compile excluded",
            "error_of": "object part (expected - background, before pile-up and saturation)",
            "centroid_min_share": CENTROID_MIN_SHARE, "target_rel_l1": TARGET_REL_L1,
            "target_scenes_per_second": TARGET_SCENES_PER_SECOND,
            "stretch_scenes_per_second": STRETCH_SCENES_PER_SECOND,
            "total_seconds": time.perf_counter() - t_start,
        },
    }


def _reference(scenes, index, reference_positions, sensor, say) -> dict:
    ref_fid = FIDELITY_LEVELS["reference"]  # looked up now: tests may replace the level
    half_fid = Fidelity(**{**ref_fid.to_dict(), "object_samples": max(1, ref_fid.object_samples // 2)})
    ref, half, seconds, paths = {}, {}, [], []
    n = len(reference_positions)
    for k, p in enumerate(reference_positions):
        say(f"reference: position {p} ({k + 1}/{n}, float64)")
        t0 = time.perf_counter()
        sim = FastSimulator(scenes[index[p]], sensor, fidelity=ref_fid, dtype="float64")
        ref[p] = sim.expected(parts=True)["object"]
        seconds.append(time.perf_counter() - t0)
        paths.append(sim.plan.paths)
        del sim
        say(f"reference: position {p} with half the object samples ({k + 1}/{n})")
        half[p] = FastSimulator(scenes[index[p]], sensor, fidelity=half_fid, dtype="float64").expected(parts=True)["object"]
    self_err = errors(half, ref)
    return {
        "fidelity": "reference", "knobs": ref_fid.to_dict(), "dtype": "float64",
        "positions": list(reference_positions), "seconds_per_scene": seconds, "paths_per_scene": paths,
        "half_knobs": half_fid.to_dict(),
        "reference_self_error": self_err["rel_l1_error"],
        "reference_self_centroid_shift_bins": self_err["centroid_shift_bins"],
        "self_error_per_position": self_err["per_position"],
        "_ref": ref,
    }


def _scene(objects: Sequence[str], sizes: Sequence[str], position: int, lights: str = "off", **options):
    """The benchmark's scene at a gantry position: objects cycle, sizes change every len(objects) positions."""
    n = len(objects)
    return denali_scene(objects[position % n], sizes[(position // n) % len(sizes)], position, lights=lights,
                        **options)


def _model_reference(scene, sensor, retro_ref: np.ndarray, retro_albedo: float, say, label: str) -> np.ndarray:
    """The float64 reference of a model's scene, part by part (the transport is linear in the parts).

    The retroreflective lobe is the main reference (same scene, albedo ``retro_albedo``) scaled to the
    scene's albedo; every Lambertian part (the object's diffuse base, the mount, the plate) is its own
    one-object scene at the ``reference`` level with ``diffuse_samples`` surface samples (a Lambertian
    term with the reference's 16,384 samples needs ~16 GB).
    """
    ref_fid = FIDELITY_LEVELS["reference"]
    lamb_fid = Fidelity(**{**ref_fid.to_dict(), "object_samples": ref_fid.diffuse_samples,
                           "support_samples": ref_fid.diffuse_samples})
    obj = scene.objects[0]
    out = retro_ref * (obj.albedo / retro_albedo)
    parts = ([dataclasses.replace(obj, reflectance="lambertian", albedo=obj.diffuse_albedo, diffuse_albedo=0.0)]
             if obj.diffuse_albedo > 0 else []) + [o for o in scene.objects[1:] if not o.fixture]
    for part in parts:
        say(f"models: {label} reference, {part.name} ({part.reflectance})")
        out = out + FastSimulator(scene.replace(objects=(part,)), sensor, fidelity=lamb_fid,
                                  dtype="float64").expected(parts=True)["object"]
    return out


def _models(models, objects, sizes, positions, index, reference_positions, retro_ref, sensor, level, dtype, repeats,
            min_seconds, say, baseline: bool = False) -> list[dict]:
    """Each scene model timed batched at ``level``, back to back, and scored against its float64 reference.

    The retroreflective model reuses the main reference (the same scenes); the others are referenced part
    by part (:func:`_model_reference`).
    """
    rows = []
    for name in models:
        opts = MODEL_OPTIONS[name]
        scenes = [_scene(objects, sizes, p, **opts) for p in positions]
        say(f"models ({level}): {name}, batched over {len(scenes)} positions")
        sim = FastSimulator(scenes, sensor, fidelity=level, dtype=dtype)
        _, best = _warm_and_time(sim, repeats, min_seconds)
        obj = sim.expected(parts=True)["object"]
        got = {p: obj[index[p]] for p in reference_positions}
        if name == "retroreflective":
            ref = retro_ref
        else:
            base = _scene(objects, sizes, reference_positions[0]).objects[0].albedo
            ref = {p: _model_reference(scenes[index[p]], sensor, retro_ref[p], base, say, f"{name} at position {p}")
                   for p in reference_positions}
        err = errors(got, ref)
        rows.append({"model": name, "options": dict(opts), "level": level, "scenes_per_second": len(scenes) / best,
                     "seconds_per_scene_batched": best / len(scenes), "paths_per_scene": sim.plan.paths,
                     "rel_l1_error": err["rel_l1_error"], "centroid_shift_bins": err["centroid_shift_bins"],
                     "errors_per_position": err["per_position"]})
        if opts.get("mount"):
            rows[-1].update(_layout_rate(opts, objects, sizes, positions, sensor, level, dtype, repeats, min_seconds,
                                         say, name))
        if baseline:
            rows[-1].update(_against_baseline(scenes, sim, best, got, ref, index, reference_positions, sensor, level,
                                              dtype, repeats, min_seconds, say, name))
    base = next((r for r in rows if r["model"] == "retroreflective"), None)
    for r in rows:
        r["speed_ratio_vs_retroreflective"] = r["scenes_per_second"] / base["scenes_per_second"] if base else math.nan
    return rows


def _layout_rate(opts, objects, sizes, positions, sensor, level, dtype, repeats, min_seconds, say, name) -> dict:
    """A model with the mount timed as DENALI's captures come: every object and size at each of a few positions.

    The timed batch above has one object per position, so each scene computes its own mount; a dataset or a design
    reference has every object at each position, where the mount is computed once per position and shared
    (``FastSimulator(share=True)``). The same number of scenes: ``objects x sizes`` at the first positions.
    """
    per = len(objects) * len(sizes)
    at = list(positions)[: max(1, len(positions) // per)]
    scenes = [denali_scene(o, s, p, **opts) for p in at for o in objects for s in sizes]
    say(f"models ({level}): {name}, {len(scenes)} scenes as DENALI's layout ({per} objects and sizes at "
        f"{len(at)} positions)")
    _, best = _warm_and_time(FastSimulator(scenes, sensor, fidelity=level, dtype=dtype), repeats, min_seconds)
    return {"layout": {"scenes": len(scenes), "positions": len(at), "objects_and_sizes": per,
                       "scenes_per_second": len(scenes) / best}}


def _against_baseline(scenes, sim, best, got, ref, index, reference_positions, sensor, level, dtype, repeats,
                      min_seconds, say, name) -> dict:
    """The path of before issue 20 timed after the current one, and both single-call.

    The old path: two scalar scatter-adds (``deposit="scatter"``) and every call gathering each chunk's
    parameters from the device arrays (``cache_chunks=False``). The current path is ``sim``'s.
    """
    say(f"models ({level}): {name}, baseline (scatter deposit, chunks gathered per call)")
    old = FastSimulator(scenes, sensor, fidelity=level, dtype=dtype, **BASELINE_PATH)
    _, old_best = _warm_and_time(old, repeats, min_seconds)
    old_obj = old.expected(parts=True)["object"]
    old_got = {p: old_obj[index[p]] for p in reference_positions}
    new_path = {"deposit": sim.plan.static.deposit, "cache_chunks": sim.cache_chunks, "threads": sim.threads}
    single = {}
    for key, path in (("new", new_path), ("old", BASELINE_PATH)):
        one = FastSimulator(scenes[0], sensor, fidelity=level, dtype=dtype, **path)
        single[key] = _warm_and_time(one, max(repeats, 5), min_seconds)[1]
    old_err = errors(old_got, ref)
    return {"single_call_ms": 1e3 * single["new"],
            "baseline": {**BASELINE_PATH, "scenes_per_second": len(scenes) / old_best,
                         "single_call_ms": 1e3 * single["old"], "rel_l1_error": old_err["rel_l1_error"],
                         "max_rel_diff_vs_new": max_rel_diff(np.stack([got[p] for p in reference_positions]),
                                                            np.stack([old_got[p] for p in reference_positions]))},
            "speed_ratio_vs_baseline": old_best / best, "single_call_ratio_vs_baseline": single["old"] / single["new"]}


def _pruning(objects, sizes, positions, sensor, level, dtype, repeats, min_seconds, say) -> tuple[dict, FastSimulator]:
    """Pruned against full plans, the centre zone against all, lights off against on (batched).

    The pruned run has the same plan as the level's batched run, so its compiled code is reused.
    """
    off = [_scene(objects, sizes, p, "off") for p in positions]
    on = [_scene(objects, sizes, p, "on") for p in positions]
    n = len(positions)
    rc, cc = sensor.zones_rows // 2, sensor.zones_cols // 2
    kw = dict(fidelity=level, dtype=dtype)
    runs = {}
    for name, scenes, extra, text, parts in (
        ("pruned", off, {}, "pruned plan (lights off, all zones)", True),
        ("full", off, {"prune": False}, "full plan (prune=False)", True),
        ("centre", off, {"zones": [(rc, cc)]}, "centre zone only", True),
        ("lights_on", on, {}, "lights on", False),
    ):
        say(f"pruning ({level}): {text}")
        sim = FastSimulator(scenes, sensor, **kw, **extra)
        _, best = _warm_and_time(sim, repeats, min_seconds)
        runs[name] = (sim, best / n, sim.expected(parts=True) if parts else None)
    pr, full, centre, lon = (runs[k] for k in ("pruned", "full", "centre", "lights_on"))
    out = {
        "level": level,
        "positions": n,
        "prune_seconds": pr[1],
        "no_prune_seconds": full[1],
        "prune_speedup": full[1] / pr[1],
        "pruned_vs_full_max_rel_diff": max(max_rel_diff(pr[2]["counts"], full[2]["counts"]),
                                           max_rel_diff(pr[2]["object"], full[2]["object"])),
        "pruned_vs_full_max_rel_diff_counts": max_rel_diff(pr[2]["counts"], full[2]["counts"]),
        "pruned_vs_full_max_rel_diff_object": max_rel_diff(pr[2]["object"], full[2]["object"]),
        "paths_pruned": pr[0].plan.paths,
        "paths_full": full[0].plan.paths,
        "centre_zone": [rc, cc],
        "centre_zone_seconds": centre[1],
        "all_zones_seconds": pr[1],
        "centre_zone_speedup": pr[1] / centre[1],
        "centre_vs_all_max_rel_diff": max(
            max_rel_diff(centre[2]["counts"][:, 0], pr[2]["counts"][:, rc, cc]),
            max_rel_diff(centre[2]["object"][:, 0], pr[2]["object"][:, rc, cc])),
        "paths_centre_zone": centre[0].plan.paths,
        "lights_off_seconds": pr[1],
        "lights_on_seconds": lon[1],
        "lights_off_speedup": lon[1] / pr[1],
        "left_out_pruned": [t["name"] + ": " + t["reason"] for t in pr[0].plan.to_dict()["left_out"]],
    }
    return out, pr[0]


def _arithmetic(sim: FastSimulator, seconds_per_scene: float, repeats: int, matmul_n: int, min_seconds: float) -> dict:
    est = flop_estimate(sim.plan)
    xla = xla_cost(sim)
    peak = matmul_gflops(matmul_n, "float32", repeats, min_seconds)
    achieved = est["flops"] / seconds_per_scene / 1e9
    out = {
        "level": _level_name(sim.plan.fidelity),
        "paths_per_scene": sim.plan.paths,
        "flops_per_scene": est["flops"],
        "flops_breakdown": {k: v for k, v in est.items() if k != "flops"},
        "flops_per_path": {"far_coupling": FLOPS_FAR_COUPLING, "weight_and_time": FLOPS_RETRO_PATH,
                           "deposit": FLOPS_DEPOSIT, "near_field_polygon": FLOPS_POLYGON},
        "seconds_per_scene": seconds_per_scene,
        "achieved_gflops": achieved,
        "matmul_peak": peak,
        "fraction_of_peak": achieved / peak["gflops"],
        "xla_cost_analysis": xla,
    }
    if xla.get("available"):
        out["achieved_gflops_xla_count"] = xla["flops"] / seconds_per_scene / 1e9
    return out


def _level_name(fid: Fidelity) -> str:
    return next((k for k, v in FIDELITY_LEVELS.items() if v == fid), "custom")
