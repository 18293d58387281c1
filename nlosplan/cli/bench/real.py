"""``nlosplan bench real``: every real-data check, printed against the targets of issue 16.

Five checks (``--parts``): ``plane``, real TMF882x captures of a plane at known
distances, all zones, cross-validated by distance (``calibrate``'s all-zone
model: each capture is predicted by the sensor file of a fit that did not see
it); ``floor``, the same captures' floor noise against the noise model's
(:func:`nlosplan.calibration.floor_noise.floor_dispersion`); ``table2``, DENALI's Table 2 (the 3x3 rows and the ratios) from noisy
simulated captures of the DENALI preset with DENALI's processing, nothing fitted;
``checkpoints``, DENALI's networks trained on real captures run on simulated ones
(:func:`nlosplan.tasks.denali_bench.checkpoint_check`), with the breakdown of their
stored real test predictions (:func:`nlosplan.tasks.denali_breakdown.real_breakdown`); ``inversion`` (opt-in),
the mean capture fitted to those networks' BatchNorm statistics
(:func:`nlosplan.tasks.denali_inversion.invert_mean_capture`).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from nlosplan.cli.common import emit, int_type, number_type, progress_bar
from nlosplan.errors import UserError

DEFAULT_PLANE = "../shared/data/tmf882x_distance/distance_data_even.json"
EXAMPLE = "nlosplan bench real --json"
EXAMPLE_CHECKPOINTS = "nlosplan bench real --parts checkpoints --checkpoints denali/benchmark/main_table/checkpoints"


def run_plane(path, sensor: str, folds: int, min_distance_m: float, progress=None) -> dict:
    """The plane check: cross-validated per-zone scores (``{"zones": [...], "summary", "targets", ...}``)."""
    from nlosplan.calibration.workflow import plane_arrivals
    from nlosplan.reports.realism_table import plane_summary
    from nlosplan.sensor_models import resolve_sensor
    from nlosplan.calibration.plane_cv import cross_validate
    from nlosplan.calibration.plane_scores import TARGETS, tables_dict
    from nlosplan.calibration.tmf882x_fit import load_distance_captures

    _check_plane(path)
    base = resolve_sensor(sensor)
    caps = load_distance_captures(path)
    cv = cross_validate(caps, plane_arrivals(base), base, folds=folds, min_distance_m=min_distance_m,
                        progress=progress)
    rows = tables_dict(cv.rows)
    keys = ("zone", "subbin_err_mean", "l1_mean", "l1_max", "amp_ratio_min", "amp_ratio_max")
    return {"zones": [{k: r[k] for k in keys} | {"n": r["n"], "subbin_err_signed": r["subbin_err_signed"],
                                                 "peak_bin_err_mean": r["peak_bin_err_mean"], "meets": r["meets"]}
                      for r in rows],
            "summary": plane_summary(rows), "targets": TARGETS, "data": str(path), "sensor": base.name,
            "folds": cv.folds, "min_distance_m": min_distance_m, "converged": all(f["converged"] for f in cv.fold_fits),
            "fold_seconds": [f["seconds"] for f in cv.fold_fits], "seconds": cv.seconds}


PARTS = ("plane", "floor", "table2", "checkpoints", "inversion")


def run_floor(path) -> dict:
    """The floor part: the Fano factor of the plane captures' late bins beside the noise model's (Poisson)."""
    from nlosplan.calibration.floor_noise import floor_dispersion
    from nlosplan.calibration.tmf882x_fit import load_distance_captures

    _check_plane(path)
    d = floor_dispersion(load_distance_captures(path).hists)
    (lo, hi), (mlo, mhi) = d.real_interval, d.model_interval
    return d.to_dict() | {"data": str(path), "poisson": lo <= mhi and mlo <= hi}   # the two intervals overlap


def format_floor(f: dict) -> str:
    """The floor part as text."""
    lo, hi = f["real_interval"]
    mlo, mhi = f["model_interval"]
    return (f"floor noise ({f['data']}): bins {f['first_bin']}-{f['last_bin']} of {f['windows']} capture-zone windows, median "
            f"floor {f['level_counts']:.0f} counts per bin, trend of degree {f['degree']} removed\n"
            f"  Fano factor (residual variance / mean): real {f['real_median']:.3f} [{lo:.3f}, {hi:.3f}], "
            f"noise model (Poisson about the same means) {f['model_median']:.3f} [{mlo:.3f}, {mhi:.3f}] (95 %)\n"
            f"  {'the real floor scatters like Poisson counts' if f['poisson'] else 'the real floor is NOT Poisson'}"
            f" at this level; per zone: " + ", ".join(f"{z['zone']}: {z['median']:.2f}" for z in f["per_zone"]))
CHECKPOINTS_HINT = ("give --checkpoints DIR, DENALI's benchmark/main_table/checkpoints (github.com/NikhilBehari/"
                    "denali), to run its real-trained networks on simulated captures")


def run_checkpoints(folder, sensor: str, budget: str, checkpoints=None, progress=None) -> dict:
    """The checkpoints part: DENALI's real-trained networks on simulated captures, and their real breakdown."""
    from nlosplan.tasks.denali_bench import checkpoint_check
    from nlosplan.tasks.denali_breakdown import real_breakdown
    from nlosplan.tasks.denali_checkpoints import load_checkpoint_dir

    if folder is None:
        return {"checkpoints": [], "skipped": f"no --checkpoints given; {CHECKPOINTS_HINT}"}
    cks = checkpoints if checkpoints is not None else load_checkpoint_dir(folder)
    res = checkpoint_check(sensor, cks, budget=budget, progress=progress)
    return {**res, "folder": str(folder), "sensor": sensor, "budget": budget, "real_breakdown": real_breakdown(cks)}


def run_inversion(sensor: str, checkpoints, progress=None) -> dict:
    """The inversion part: the mean capture fitted to the 1D CNNs' BatchNorm statistics, and the networks on the
    quick budget's simulated captures moved to it (:func:`nlosplan.tasks.denali_inversion.invert_mean_capture`)."""
    import numpy as np

    from nlosplan.tasks.denali_bench import load_protocol_captures, protocol_for
    from nlosplan.tasks.denali_checkpoints import evaluate_checkpoints
    from nlosplan.tasks.denali_inversion import invert_mean_capture

    hist, labels, _ = load_protocol_captures(sensor, protocol_for("quick"), progress=progress)
    if progress is not None:
        progress.stage("fitting the mean capture to the BatchNorm statistics", 1, "fit")
    res = invert_mean_capture(checkpoints, hist)
    if progress is not None:
        progress.update(1)
    shift = (np.asarray(res["mean_real"]) - np.asarray(res["mean_model"])).reshape(3, 3, 128)
    moved = np.asarray(hist, np.float64) + shift
    scores = evaluate_checkpoints([c for c in checkpoints if c.model == "cnn1d"], moved.astype(np.float32), labels)
    res["scores"] = [{k: c[k] for k in ("name", "task", "metric", "simulated", "real", "chance")} for c in scores]
    return res


def _check_plane(path) -> None:
    if not Path(path).is_file():
        raise UserError(f"plane captures not found at {path}; give --plane PATH (the tmf882x_distance JSON)")


def run_table2(stats_path: str, sensor: str, n_positions: int, scene_file=None) -> dict:
    """The Table-2 check: per-row statistics of ``sensor`` (with its scene table) against the statistics file."""
    import time

    from nlosplan.calibration.stats_file import load_stats
    from nlosplan.calibration.stats_score import scene_for, score_stats
    from nlosplan.sensor_models import resolve_sensor

    t0 = time.perf_counter()
    stats = load_stats(stats_path)
    base = resolve_sensor(sensor)
    scene, nuis, source = scene_for(sensor, base, scene_file)
    res = score_stats(stats, base, scene, nuis, n_positions=n_positions)
    keys = ("light", "size", "total", "centroid", "spread", "skew", "real")
    return {"rows": [{k: r[k] for k in keys} | {"meets": r["meets"], "mc_std": r["mc_std"]} for r in res["rows"]],
            "ratios": res["ratios"], "levels": res["levels"], "meets": res["meets"], "targets": res["targets"],
            "data": str(stats.path), "sensor": base.name, "scene_source": source, "n_scenes": res["n_scenes"],
            "seeds": res["seeds"], "seconds": time.perf_counter() - t0}


def _parts(text: str) -> list[str]:
    parts = [p.strip() for p in text.split(",") if p.strip()]
    bad = [p for p in parts if p not in PARTS]
    if bad or not parts:
        raise UserError(f"unknown part(s) {', '.join(bad) or '(none)'} in --parts; allowed: {', '.join(PARTS)}")
    return parts


def _check_checkpoints(args):
    """The checkpoints part's inputs, before any work: DENALI's four files (read, checked) and a 3x3 sensor."""
    if args.checkpoints is None:
        return None
    from nlosplan.sensor_models import resolve_sensor
    from nlosplan.tasks.denali_checkpoints import load_checkpoint_dir

    cks = load_checkpoint_dir(args.checkpoints)   # small files: every refusal is one line
    sensor = resolve_sensor(args.denali_sensor)
    if (sensor.zones_rows, sensor.zones_cols, sensor.n_bins) != (3, 3, 128):
        raise UserError(f"--denali-sensor {args.denali_sensor}: DENALI's networks take 3x3 zones and 128 bins")
    return cks


def _checkpoints_part(args, cks, out: dict, texts: list) -> None:
    """Run the checkpoints part into ``out`` (``checkpoints``, ``real_breakdown``, ...) and ``texts``."""
    from nlosplan.cli.bench.denali import checkpoints_text

    with progress_bar(args, None, "bench real", "step") as bar:
        ck = run_checkpoints(args.checkpoints, args.denali_sensor, args.checkpoint_budget, cks,
                             progress=None if args.checkpoints is None else bar)
    out["checkpoints"] = ck.pop("checkpoints")
    if ck.get("skipped"):
        out["checkpoints_skipped"] = ck["skipped"]
    else:
        out["real_breakdown"] = ck.pop("real_breakdown")
        out["checkpoints_run"] = ck
    texts.append(checkpoints_text({"checkpoints": out["checkpoints"], **ck,
                                   "real_breakdown": out.get("real_breakdown")}))


def _inversion_part(args, cks, out: dict, texts: list) -> None:
    from nlosplan.cli.bench.denali import inversion_text

    if cks is None:
        out["inversion"] = {"skipped": f"no --checkpoints given; {CHECKPOINTS_HINT}"}
    else:
        with progress_bar(args, None, "bench real", "step") as bar:
            out["inversion"] = run_inversion(args.denali_sensor, cks, progress=bar)
    texts.append(inversion_text(out["inversion"]))


def _cmd(args) -> int:
    from nlosplan.calibration.stats_file import load_stats
    from nlosplan.reports.realism_table import format_plane_table, format_table2

    parts = _parts(args.parts)
    if "plane" in parts or "floor" in parts:   # every input is checked before the first (minute-long) part runs
        _check_plane(args.plane)
    if "table2" in parts:
        load_stats(args.stats)   # a small file, read again by the part: its errors are one line before any work
    cks = _check_checkpoints(args) if {"checkpoints", "inversion"} & set(parts) else None
    out, texts = {}, []
    if "floor" in parts:
        out["floor"] = run_floor(args.plane)
        texts.append(format_floor(out["floor"]))
    if "table2" in parts:
        t2 = run_table2(args.stats, args.denali_sensor, args.positions)
        out["table2"] = t2
        texts.append(format_table2({**t2, "rows": [dict(r, zones="3x3") for r in t2["rows"]]},
                                   title=f"DENALI Table 2 ({t2['data']}), {t2['sensor']} with {t2['scene_source']}, "
                                         f"noisy simulated captures, DENALI's processing ({t2['seconds']:.0f} s):"))
    if "checkpoints" in parts:
        _checkpoints_part(args, cks, out, texts)
    if "inversion" in parts:
        _inversion_part(args, cks, out, texts)
    if "plane" not in parts:
        emit(args, out, "\n\n".join(texts))
        return 0
    with progress_bar(args, args.folds, "plane folds", "fit") as bar:
        plane = run_plane(args.plane, args.sensor, args.folds, args.min_distance,
                          progress=None if bar is None else (lambda done, total: bar.update(1)))
    text = format_plane_table(plane["zones"], plane["targets"],
                              title=f"plane captures ({plane['data']}), all zones, held out by distance "
                                    f"({plane['folds']} folds; {plane['seconds']:.0f} s):")
    if not plane["converged"]:
        text += "\nnote: a fold's fit stopped at its evaluation budget (see 'nlosplan calibrate' for its deviance)"
    out = {"plane": plane, **out}
    emit(args, out, "\n\n".join([text] + texts))
    return 0


def add_bench(bsub) -> None:
    """``nlosplan bench real``."""
    p = bsub.add_parser("real", help="realism against real data: plane captures held out by distance; DENALI Table 2; DENALI's "
                             "real-trained networks",
                        description="Every real-data check the project ships, against the targets of issue 16. "
                                    "Plane captures at known distances (tmf882x_distance): the all-zone model of "
                                    "'nlosplan calibrate' cross-validated by distance, per zone: sub-bin peak error "
                                    "(<= 0.15 bin mean), normalized L1 of the shape (<= 8 % mean, <= 15 % max), "
                                    "amplitude predicted/measured (0.8-1.25). About 1 min per fold on 2 idle cores. "
                                    "Floor: the same captures' late bins (96-127, trend removed), their Fano factor "
                                    "(variance / mean) beside the noise model's on the same means: is the floor "
                                    "Poisson? (under a second). "
                                    "JSON: {\"floor\": {\"real_median\", \"real_interval\", \"model_median\", "
                                    "\"model_interval\", \"poisson\", \"per_zone\", ...}, \"plane\": {\"zones\": [{\"zone\", \"subbin_err_mean\", \"l1_mean\", "
                                    "\"l1_max\", \"amp_ratio_min\", \"amp_ratio_max\"}...], \"summary\", ...}, "
                                    "\"table2\": {\"rows\": [{\"light\", \"size\", \"total\", \"centroid\", "
                                    "\"spread\", \"skew\", \"real\": {...}}...], \"ratios\": {...}}}. Table 2: DENALI's "
                                    "3x3 rows from noisy simulated captures of the DENALI preset (centroid within 1 "
                                    "bin, spread within 15 %, total within 20 %, skew sign; ratios within 20 %); "
                                    "about 1 min (the fast simulator's 1,300 scenes). Checkpoints (--checkpoints "
                                    "DIR, else skipped): DENALI's four networks trained on real captures (1D CNN "
                                    "loc/shape/size, shape MLP) run on DENALI's protocol simulated for "
                                    "--denali-sensor, their scores beside their real test scores, and per "
                                    "BatchNorm layer of the 1D CNNs the distance of its simulated input from the "
                                    "real running statistics (median |z| of the channel means, mean and rms "
                                    "log-ratio of the variances); plus their stored REAL test predictions broken "
                                    "down by lighting, size, near/far half, quadrant and capture folder. About 20 s "
                                    "with the quick budget (7,200 captures) and 30 s with the full one (36,000) on "
                                    "2 idle cores, most of it simulating the captures (cached for the next run). "
                                    "JSON adds "
                                    "\"checkpoints\": [{\"name\", \"task\", \"metric\", \"simulated\", "
                                    "\"real\", \"bn\": {\"bn1\": {\"median_abs_z\", \"mean_log_var_ratio\", "
                                    "\"rms_log_var_ratio\", ...}...}}...], \"real_breakdown\": {...}. "
                                    "Inversion (--parts inversion, with --checkpoints; not in the default parts: "
                                    "about 3-4 min on 2 cores): the mean capture (9 zones x 128 bins) that brings "
                                    "the three 1D CNNs' BatchNorm inputs to their real running statistics, with "
                                    "the simulated captures' own variation kept (400 of the quick budget's), its "
                                    "zones' relative timing and levels beside the model's, and the networks on "
                                    "the simulated captures moved to it. JSON adds \"inversion\": {\"mean_real\", "
                                    "\"mean_model\", \"zones_real\", \"zones_model\", \"bn_before\", \"bn_after\", "
                                    "\"scores\", ...}.",
                        epilog=f"examples:\n  {EXAMPLE}\n  {EXAMPLE_CHECKPOINTS}",
                        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--plane", default=DEFAULT_PLANE, help="plane and floor: plane captures JSON (default: %(default)s)")
    p.add_argument("--sensor", default="tmf8828-3x3-short", help="sensor to calibrate (default: %(default)s)")
    p.add_argument("--folds", type=int_type(2, 100), default=5, help="folds by distance (default: %(default)s)")
    p.add_argument("--min-distance", type=number_type(float, zero_ok=True), default=0.06, help="nearest capture scored, m (default: 0.06)")
    p.add_argument("--parts", default="plane,floor,table2,checkpoints",
                   help="checks to run, from plane, floor, table2, checkpoints, inversion (default: %(default)s)")
    p.add_argument("--stats", default="denali-table2",
                   help="table2: statistics file (default: %(default)s, the shipped DENALI Table 2)")
    p.add_argument("--denali-sensor", default="denali-tmf8828-3x3",
                   help="table2 and checkpoints: sensor preset or file scored, with its scene table (default: "
                        "%(default)s)")
    p.add_argument("--checkpoints", default=None, metavar="DIR",
                   help="checkpoints: DENALI's benchmark/main_table/checkpoints (reg_1dcnn, obj_1dcnn, size_1dcnn, "
                        "obj_mlp .pth; read without unpickling code); without it the part is skipped")
    p.add_argument("--checkpoint-budget", default="quick", choices=["quick", "full"],
                   help="checkpoints: quick = 7,200 simulated captures (every fifth position), each network scored "
                        "on all; full = DENALI's 36,000, each scored on its real test split's scenes (default: "
                        "%(default)s; the captures are cached and shared with 'bench denali')")
    p.add_argument("--positions", type=int_type(1, 100), default=10,
                   help="table2: gantry positions per object (30 objects), the Monte-Carlo sample (default: 10; "
                        "the shipped scores used 10)")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(func=_cmd)
