"""``nlosplan bench real``: every real-data check, printed against the targets of issue 16.

For now one check: real TMF882x captures of a plane at known distances, all
zones, cross-validated by distance (``calibrate``'s all-zone model: each
capture is predicted by the sensor file of a fit that did not see it).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from nlosplan.cli.common import emit, int_type, number_type, progress_bar
from nlosplan.errors import UserError

DEFAULT_PLANE = "../shared/data/tmf882x_distance/distance_data_even.json"
EXAMPLE = "nlosplan bench real --json"


def run_plane(path, sensor: str, folds: int, min_distance_m: float, progress=None) -> dict:
    """The plane check: cross-validated per-zone scores (``{"zones": [...], "summary", "targets", ...}``)."""
    from nlosplan.cli.calibrate_plane import plane_arrivals
    from nlosplan.reports.realism_table import plane_summary
    from nlosplan.sensor_models import resolve_sensor
    from nlosplan.calibration.plane_cv import cross_validate
    from nlosplan.calibration.plane_scores import TARGETS, tables_dict
    from nlosplan.calibration.tmf882x_fit import load_distance_captures

    if not Path(path).is_file():
        raise UserError(f"plane captures not found at {path}; give --plane PATH (the tmf882x_distance JSON)")
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


def _cmd(args) -> int:
    from nlosplan.reports.realism_table import format_plane_table

    with progress_bar(args, args.folds, "plane folds", "fit") as bar:
        plane = run_plane(args.plane, args.sensor, args.folds, args.min_distance,
                          progress=None if bar is None else (lambda done, total: bar.update(1)))
    text = format_plane_table(plane["zones"], plane["targets"],
                              title=f"plane captures ({plane['data']}), all zones, held out by distance "
                                    f"({plane['folds']} folds; {plane['seconds']:.0f} s):")
    if not plane["converged"]:
        text += "\nnote: a fold's fit stopped at its evaluation budget (see 'nlosplan calibrate' for its deviance)"
    emit(args, {"plane": plane}, text)
    return 0


def add_bench(bsub) -> None:
    """``nlosplan bench real``."""
    p = bsub.add_parser("real", help="realism against real data: plane captures, all zones, held out by distance",
                        description="Every real-data check the project ships, against the targets of issue 16. "
                                    "Plane captures at known distances (tmf882x_distance): the all-zone model of "
                                    "'nlosplan calibrate' cross-validated by distance, per zone: sub-bin peak error "
                                    "(<= 0.15 bin mean), normalized L1 of the shape (<= 8 % mean, <= 15 % max), "
                                    "amplitude predicted/measured (0.8-1.25). About 1 min per fold on 2 idle cores. "
                                    "JSON: {\"plane\": {\"zones\": [{\"zone\", \"subbin_err_mean\", \"l1_mean\", "
                                    "\"l1_max\", \"amp_ratio_min\", \"amp_ratio_max\"}...], \"summary\", ...}}.",
                        epilog=f"example:\n  {EXAMPLE}", formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--plane", default=DEFAULT_PLANE, help="plane captures JSON (default: %(default)s)")
    p.add_argument("--sensor", default="tmf8828-3x3-short", help="sensor to calibrate (default: %(default)s)")
    p.add_argument("--folds", type=int_type(2, 100), default=5, help="folds by distance (default: %(default)s)")
    p.add_argument("--min-distance", type=number_type(float, zero_ok=True), default=0.06, help="nearest capture scored, m (default: 0.06)")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(func=_cmd)
