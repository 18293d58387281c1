"""``nlosplan calibrate`` on plane captures with the all-zone model, and ``--score`` (nothing fitted)."""

from __future__ import annotations

import time

from nlosplan.cli.common import emit, note, progress_bar
from nlosplan.errors import UserError
from nlosplan.schema import parse_int

#: Options that belong to the single-zone global model (``--model global``) only.
GLOBAL_ONLY = ("steps", "pulse", "start", "holdout", "bootstrap", "lights")


def check_global_only(args) -> None:
    """One line when an option of ``--model global`` is given to the all-zone model."""
    defaults = {"steps": "scale,pulse,noise", "holdout": 0.0, "bootstrap": 0}
    for name in GLOBAL_ONLY:
        value = getattr(args, name, None)
        if value is not None and value != defaults.get(name):
            raise UserError(f"--{name} applies to --model global (one global photon scale, zone 4 by default); "
                            "the all-zone model takes --terms and --folds")


def _value_lines(values: dict, errors: dict) -> list[str]:
    lines = []
    for name, v in values.items():
        if name == "pulse":
            lines.append(f"  {'pulse':22s} {len(v)} samples, peak {max(v):.3f} at sample {v.index(max(v))}")
            continue
        e = errors.get(name)
        if isinstance(v, list):
            fmt = ", ".join(f"{x:.4g}" + (f"±{ex:.2g}" if e else "") for x, ex in zip(v, e or [None] * len(v)))
            lines.append(f"  {name:22s} [{fmt}]")
        else:
            lines.append(f"  {name:22s} {v:.6g}" + (f" ± {e:.3g} (jackknife)" if e is not None else ""))
    return lines


def zone_list(text: str, n: int) -> list[int]:
    """Flat zone indices from ``--zones`` text like ``"0,4"`` (each in 0..n-1)."""
    try:
        zones = [parse_int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        zones = []
    if not zones or any(not 0 <= z < n for z in zones):
        raise UserError(f"--zones {text!r} must be flat zone indices 0..{n - 1} separated by commas, e.g. 4")
    return zones


def run_zones(args, t0: float) -> int:
    """Fit the all-zone plane model; cross-validate by distance with --folds; write the sensor file and plot."""
    import numpy as np

    from nlosplan.reports.realism_table import format_plane_table
    from nlosplan.sensor_models import resolve_sensor
    from nlosplan.calibration.plane_cv import REPORTED, cross_validate
    from nlosplan.calibration.plane_fit import fit_plane_zones, zone_sensor
    from nlosplan.calibration.plane_model import TERMS, check_terms
    from nlosplan.calibration.plane_scores import TARGETS, predict_plane, tables_dict
    from nlosplan.calibration.tmf882x_fit import load_distance_captures
    from nlosplan.calibration.workflow import plane_arrivals

    check_global_only(args)
    terms = check_terms((args.terms or ",".join(TERMS)).split(","))
    min_d = 0.06 if args.min_distance is None else args.min_distance
    base = resolve_sensor(args.sensor or "tmf8828-3x3-short")
    captures = load_distance_captures(args.captures)
    n_zones = captures.hists.shape[1]
    if n_zones != base.n_zones:
        raise UserError(f"the captures have {n_zones} zones but sensor {base.name} has {base.n_zones}; "
                        "give a matching --sensor")
    zones = zone_list(args.zones, n_zones) if args.zones else list(range(n_zones))
    n_usable = int(np.sum(captures.distance_m >= min_d))
    if args.folds and not 2 <= args.folds <= n_usable // 2:
        raise UserError(f"--folds {args.folds} must be between 2 and {max(n_usable // 2, 2)} (half the {n_usable} "
                        f"captures at d >= {min_d} m), or 0 for none")
    arrivals = plane_arrivals(base)
    note(args, f"calibrating {base.name} on {captures.distance_m.size} captures, zones {zones}, terms {terms} ...")
    fit = fit_plane_zones(captures, arrivals, base, zones=zones, terms=terms, min_distance_m=min_d)
    idx = np.flatnonzero(captures.distance_m >= min_d)
    sensor = zone_sensor(base, fit, floor_counts=float(np.median(captures.hists[idx][..., :8])))
    cv = None
    if args.folds:
        note(args, f"cross-validating by distance: {args.folds} folds ...")
        with progress_bar(args, args.folds, "folds", "fit") as bar:
            cv = cross_validate(captures, arrivals, base, folds=args.folds, terms=terms, zones=zones,
                                min_distance_m=min_d, progress=None if bar is None else (lambda d, t: bar.update(1)))
    errs = cv.errors if cv is not None else {}
    notes = (f"Calibrated by nlosplan calibrate (all-zone plane model, terms {','.join(terms)}) on "
             f"{fit.n_captures} captures of {args.captures} at d >= {min_d} m"
             + (f"; held out by distance ({cv.folds} folds): " + _summary(cv) if cv is not None else "")
             + (f"; jackknife errors {', '.join(f'{k} ±{errs[k]:.3g}' for k in REPORTED if isinstance(errs.get(k), float))}"
                if errs else "") + ".")
    sensor = sensor.replace(notes=f"{base.notes} {notes}")
    files = {}
    if args.out:
        from nlosplan.sensor_models import sensor_base

        sensor.save(args.out, base=sensor_base(args.sensor or "tmf8828-3x3-short"))
        files["sensor"] = str(args.out)
    if args.plot:
        from nlosplan.reports.calibration_plot import plot_calibration
        from nlosplan.calibration.plane_fit import floor_bins, plane_data

        data = plane_data(captures, arrivals, range(n_zones), idx, floor_bins(sensor))
        pred = predict_plane(sensor, data.times_ps, data.weights, data.floor)[:, zones]
        path = plot_calibration(data.counts[:, zones].reshape(-1, data.counts.shape[-1]),
                                pred.reshape(-1, pred.shape[-1]),
                                [f"{lab} z{z}" for lab in data.labels for z in zones], args.plot,
                                title=f"{base.name}, all-zone model, on {args.captures}")
        files["plot"] = str(path)
    data = {"sensor": sensor.name, "base": base.name, "model": "zones", "fit": fit.to_dict(),
            "cross_validation": None if cv is None else cv.to_dict(), "files": files,
            "seconds": time.perf_counter() - t0}
    lines = [f"calibrated {base.name} on {args.captures} (all-zone model: {', '.join(terms)}; zones "
             f"{','.join(map(str, zones))}; {fit.n_captures} captures at d >= {min_d} m; {fit.evaluations} "
             f"evaluations, {fit.seconds:.0f} s)"]
    lines += _value_lines(fit.values, errs)
    lines.append(f"  mean Poisson deviance per bin {fit.deviance:.4g}")
    lines += [f"  note: {m}" for m in fit.messages[:12]]
    if cv is not None:
        lines.append(format_plane_table(tables_dict(cv.rows), TARGETS,
                                        title=f"held out by distance ({cv.folds} folds, each capture predicted by "
                                              f"the sensor file of a fit that did not see it):"))
        lines += [f"  note: {m}" for m in cv.messages]
    lines += [f"wrote {k}: {v}" for k, v in files.items()]
    emit(args, data, "\n".join(lines))
    return 0


def _summary(cv) -> str:
    from nlosplan.reports.realism_table import plane_summary
    from nlosplan.calibration.plane_scores import tables_dict

    s = plane_summary(tables_dict(cv.rows))
    return (f"sub-bin peak error {s['subbin_err_mean']:.3f} bin, L1 {100 * s['l1_mean']:.1f} % mean / "
            f"{100 * s['l1_max']:.1f} % max, amplitude pred/meas {s['amp_ratio_min']:.2f}-{s['amp_ratio_max']:.2f}")


def run_score(args, t0: float) -> int:
    """``--score DATA --sensor FILE``: the held-out table of a sensor file, nothing fitted."""
    from nlosplan.reports.realism_table import format_plane_table
    from nlosplan.sensor_models import resolve_sensor
    from nlosplan.calibration.score import score_input
    from nlosplan.calibration.workflow import plane_arrivals

    if args.captures:
        raise UserError("give either CAPTURES (to fit) or --score DATA (to score a sensor without fitting), not both")
    if not args.sensor:
        raise UserError("--score needs --sensor: the preset or sensor file to score")
    for name in GLOBAL_ONLY + ("terms", "where", "fidelity", "zones"):
        value = getattr(args, name, None)
        if value not in (None, False, 0, 0.0, "scale,pulse,noise"):
            raise UserError(f"--{name.replace('_', '-')} does not apply to --score (nothing is fitted)")
    if args.folds not in (None, 5):
        raise UserError("--folds does not apply to --score (nothing is fitted)")
    sensor = resolve_sensor(args.sensor)
    res = score_input(args.score, sensor, plane_arrivals=plane_arrivals,
                      min_distance_m=0.06 if args.min_distance is None else args.min_distance,
                      sensor_spec=args.sensor, scene_file=getattr(args, "scene", None),
                      n_positions=getattr(args, "positions", None) or 10)
    res["seconds"] = time.perf_counter() - t0
    if res["kind"] == "statistics":
        from nlosplan.reports.realism_table import format_table2

        text = format_table2(res, title=f"{sensor.name} on {args.score} (statistics; scene table: "
                                        f"{res['scene_source']}; nothing fitted):")
        emit(args, res, text)
        return 0
    text = format_plane_table(res["zones"], res["targets"],
                              title=f"{sensor.name} on {args.score} ({res['kind']}; nothing fitted):")
    emit(args, {k: v for k, v in res.items() if k != "rows"}, text)
    return 0
