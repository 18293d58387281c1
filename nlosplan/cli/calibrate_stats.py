"""``nlosplan calibrate --stats FILE``: fit sensor, scene and protocol nuisances to a statistics file."""

from __future__ import annotations

import json
import time
from pathlib import Path

from nlosplan.cli.common import emit, note, progress_bar
from nlosplan.errors import UserError

#: Options of ``calibrate`` that fit plane or DENALI captures, not statistics.
NOT_FOR_STATS = ("captures", "score", "model", "terms", "folds", "where", "fidelity", "zones", "start", "lights",
                 "min_distance", "pulse", "trust_pickle")


def _free(text: str | None) -> tuple:
    from nlosplan.calibration.stats_fit import DEFAULT_FREE, FITTABLE

    if not text:
        return DEFAULT_FREE
    names = tuple(n.strip() for n in text.split(",") if n.strip())
    bad = [n for n in names if n not in FITTABLE]
    if bad or not names:
        raise UserError(f"unknown parameter(s) {', '.join(bad) or '(none)'} in --fit; allowed: {', '.join(FITTABLE)}")
    return names


def run_stats(args, t0: float) -> int:
    """Fit, bootstrap, write the sensor file, its scene table and its uncertainty JSON, print the per-row table."""
    from nlosplan.calibration.bootstrap import MIN_RESAMPLES
    from nlosplan.calibration.stats_file import load_stats
    from nlosplan.files import check_output_file, write_text
    from nlosplan.calibration.stats_fit import bootstrap, fit_stats, intervals, split, uncertainty_dict
    from nlosplan.calibration.stats_variants import MODEL_VARIANTS, variant_fits, variant_samples, variant_summary
    from nlosplan.calibration.stats_model import SENSOR_PARAMS, components
    from nlosplan.calibration.stats_score import scene_for, scene_table_path, scene_table_toml, score_stats
    from nlosplan.reports.realism_table import format_table2
    from nlosplan.sensor_models import resolve_sensor, sensor_base

    for name in NOT_FOR_STATS:
        value = getattr(args, name, None)
        if value not in (None, False):
            raise UserError(f"--{name.replace('_', '-')} does not apply to --stats" if name != "captures" else
                            "give either CAPTURES or --stats FILE, not both")
    if args.holdout:
        raise UserError("--holdout does not apply to --stats (a statistics file has no captures to hold out)")
    if args.steps != "scale,pulse,noise":
        raise UserError("--steps does not apply to --stats (choose the fitted parameters with --fit)")
    if 0 < args.bootstrap < MIN_RESAMPLES:
        raise UserError(f"bootstrap refits {args.bootstrap} < {MIN_RESAMPLES}: give at least {MIN_RESAMPLES} "
                        "(30 or more for a 95 % interval)")
    free = _free(args.fit)
    if args.out:  # before the fit, not after it
        check_output_file(args.out, "--out", suffixes=(".toml", ".json"))
    args.positions = args.positions or 10
    stats = load_stats(args.stats)
    spec = args.sensor or "denali-tmf8828-3x3"
    sensor = resolve_sensor(spec)
    zones = f"{sensor.zones_rows}x{sensor.zones_cols}"
    if zones not in stats.processing or not stats.rows_for(zones):
        raise UserError(f"{args.stats} has no rows for a {zones} sensor ({sensor.name})")
    scene, nuis, source = scene_for(spec, sensor, args.scene)
    note(args, f"simulating {30 * args.positions} scenes per size for {sensor.name} ...")
    comp = components(sensor, stats.processing[zones].zone, n_positions=args.positions)
    start = {k: v for k, v in scene.items() if k != "mount"} | nuis
    note(args, f"fitting {', '.join(free)} (start: {source}) ...")
    fit = fit_stats(stats, comp, sensor, start, free, seed=args.seed)
    samples = []
    if args.bootstrap:
        with progress_bar(args, args.bootstrap, "bootstrap", "refit") as bar:
            samples = bootstrap(stats, comp, sensor, fit, args.bootstrap, seed=args.seed,
                                progress=None if bar is None else (lambda done, total: bar.update(1)))
    variants = []
    if args.variants:
        with progress_bar(args, len(MODEL_VARIANTS), "model variants", "refit") as bar:
            variants = variant_fits(stats, comp, sensor, fit, seed=args.seed,
                                    progress=None if bar is None else (lambda done, total: bar.update(1)))
        samples = samples + variant_samples(fit, variants)
    fitted, fscene, fnuis = split(fit.values, sensor)
    fscene["mount"] = bool(scene.get("mount", True))
    res = score_stats(stats, fitted, fscene, fnuis, comp=comp)
    iv = intervals(fit, samples)
    unc = uncertainty_dict(sensor.name, fit, samples)
    parts = []
    if args.bootstrap:
        parts.append(f"{args.bootstrap} bootstrap refits (the statistics redrawn within their SEMs, a new noise seed "
                     "each; scene sample and model held fixed)")
    if variants:
        parts.append(f"{len(variants)} model-variant refits (repeat-mean or single captures x 5 readings of the "
                     "checkpoint levels x diffuse base 0-0.3 x mount in/out of the background)")
    method = "spread of " + " and ".join(parts) if parts else "none (no --bootstrap, no --variants)"
    files = {}
    if args.out:
        out = Path(args.out)
        fitted = fitted.replace(notes=(sensor.notes + f" Refitted by 'nlosplan calibrate --stats {args.stats}' "
                                       f"(objective {fit.objective:.4g}; {res['meets']['statistics']} of "
                                       f"{res['meets']['statistics_of']} row statistics, {res['meets']['ratios']} of "
                                       f"{res['meets']['ratios_of']} ratios within target).").strip())
        base = sensor_base(spec)  # the refined preset, so that later model fields come from it
        write_text(out, fitted.to_toml(base=base) if out.suffix == ".toml" else fitted.to_json(base=base))
        files["sensor"] = str(out)
        st = scene_table_path(out)
        write_text(st, scene_table_toml(fscene, fnuis, {"statistics": str(args.stats), "objective": fit.objective,
                                                       "converged": fit.converged, "uncertainty": method},
                                        {k: v for k, v in iv.items() if k not in SENSOR_PARAMS}))
        files["scene"] = str(st)
        if unc is not None:
            uj = out.with_name(out.stem + ".uncertainty.json")
            write_text(uj, json.dumps(unc, indent=1))
            files["uncertainty"] = str(uj)
    data = {"sensor": sensor.name, "statistics": str(args.stats), "fit": {
        "values": fit.values, "free": list(fit.free), "objective": fit.objective, "converged": fit.converged,
        "evaluations": fit.evaluations, "seconds": fit.seconds, "message": fit.message},
        "variants": [{**v.as_dict(), "objective": r.objective, "converged": r.converged,
                      "values": {k: r.values[k] for k in fit.free}} for v, r in zip(MODEL_VARIANTS, variants)],
        "uncertainty": unc, "intervals": iv, "uncertainty_method": method, "score": res, "files": files, "seconds": time.perf_counter() - t0}
    lines = [f"fitted {', '.join(fit.free)} of {sensor.name} to {args.stats} ({30 * args.positions} scenes per size, "
             f"noise seed {args.seed}): objective {fit.objective:.4g} after {fit.evaluations} evaluations"
             + ("" if fit.converged else f"; NOT converged: {fit.message}")]
    for k in tuple(fit.free) + tuple(k for k in iv if k not in fit.free):
        p = iv.get(k)
        err = "" if p is None else f" +- {p['std']:.3g} (95 % {p['lo']:.4g} to {p['hi']:.4g})"
        lines.append(f"  {k:26s} {fit.values[k]:.5g}{err}")
    lines.append(f"uncertainty: {method}")
    if variants:
        lines += variant_summary(variants)
    lines.append(format_table2(res))
    lines += [f"wrote {k}: {v}" for k, v in files.items()]
    emit(args, data, "\n".join(lines))
    return 0
