"""``nlosplan calibrate``: fit the sensor model to real captures of known geometry (sim-to-real)."""

from __future__ import annotations

import argparse
import time

from nlosplan.cli.common import emit, note
from nlosplan.errors import UserError

EXAMPLES = (
    "nlosplan calibrate ../shared/data/tmf882x_distance/distance_data_even.json --holdout 0.5 "
    "--out out/calibrated.toml --plot out/calibration.png",
    "nlosplan calibrate captures.json --steps scale,pulse --pulse gaussian --start bin_width_ps=95 --json",
)

DESCRIPTION = """\
Calibrate the sensor model against real histograms of known geometry: a flat
plane square-on at known distances (JSON entries with dist_to_plane, hists
(zones x bins) and reference_hist, as ../shared/data/tmf882x_distance). Each
capture's matching simulated scene is the plane at its distance.

Fitted with nlopt (BOBYQA) on normalized, bounded variables by Poisson maximum
likelihood: global photon scale, pulse width (a Gaussian broadening a
non-parametric pulse shape, or a Gaussian alone), bin width and time offset,
noise floor, crosstalk peak. DENALI's three calibration functions are steps
that stack: scale (global scaling), pulse (pulse-width and time-base
matching), noise (noise matching); a joint pass refines them together.
Uncertainties: Fisher information (statistical only; unidentifiable parameters
are flagged). Saturated zones and zones without signal are left out with a
message. With --holdout F a seeded part (1-F) is kept out of the fit and
scored: peak-bin error and the normalized L1 of the histogram shape.
Writes the calibrated sensor file (--out, .toml or .json: usable as --sensor
by every other command) and a residual plot (--plot). About 20 s."""


def _parse_start(text: str | None) -> dict:
    if not text:
        return {}
    out = {}
    for item in text.split(","):
        key, sep, value = item.partition("=")
        try:
            out[key.strip()] = float(value)
        except ValueError:
            sep = ""
        if not sep or not key.strip():
            raise UserError(f"--start {text!r}: give NAME=VALUE pairs, e.g. bin_width_ps=95,start_offset_ps=-1100")
    return out


def _zones(text: str, n: int) -> list[int]:
    try:
        zones = [int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        zones = []
    if not zones or any(not 0 <= z < n for z in zones):
        raise UserError(f"--zones {text!r} must be flat zone indices 0..{n - 1} separated by commas, e.g. 4")
    return zones


def _cmd_calibrate(args) -> int:
    import numpy as np

    from nlosplan.sensor_models import resolve_sensor
    from nlosplan.sensor_models.calibration import calibrated_sensor, capture_set, fit_plane, plane_holdout, predict
    from nlosplan.sensor_models.calibration.plane import holdout_dict
    from nlosplan.sensor_models.tmf882x_fit import load_distance_captures
    from nlosplan.simulators import WallScene, wall_arrivals

    t0 = time.perf_counter()
    base = resolve_sensor(args.sensor)
    captures = load_distance_captures(args.captures)
    n_zones = captures.hists.shape[1]
    if n_zones != base.n_zones:
        raise UserError(f"the captures have {n_zones} zones but sensor {base.name} has {base.n_zones}; "
                        "give a matching --sensor")
    zones = _zones(args.zones, n_zones)
    steps = [s.strip() for s in args.steps.split(",") if s.strip()]
    if not 0 <= args.holdout < 1:
        raise UserError(f"--holdout {args.holdout} must be >= 0 and < 1 (the held-out fraction)")

    def arrivals(d):
        t, w = wall_arrivals(WallScene(distance_m=d, albedo=1.0), base)
        return t.reshape(n_zones, -1), w.reshape(n_zones, -1)

    kw = dict(zones=zones, iterations=base.iterations, steps=steps, pulse=args.pulse, noise=args.noise,
              min_distance_m=args.min_distance, start=_parse_start(args.start))
    note(args, f"calibrating {base.name} on {captures.distance_m.size} captures ({', '.join(steps)}) ...")
    holdout = None
    if args.holdout > 0:
        fit, holdout = plane_holdout(captures, arrivals, fit_fraction=1 - args.holdout, seed=args.seed, **kw)
    else:
        fit, _ = fit_plane(captures, arrivals, **kw)
    cs_all = capture_set(captures, arrivals, zones, base.iterations,
                         np.flatnonzero(captures.distance_m >= args.min_distance))
    floor = float(np.median(cs_all.counts[..., -30:])) if args.noise == "measured" else None
    sensor = calibrated_sensor(base, fit, floor, lights_on=args.lights == "on")
    files = {}
    if args.out:
        sensor.save(args.out)
        files["sensor"] = str(args.out)
    if args.plot:
        from nlosplan.reports.calibration_plot import plot_calibration

        pred = predict(fit, cs_all, args.noise)
        path = plot_calibration(cs_all.counts.reshape(-1, cs_all.counts.shape[-1]),
                                pred.reshape(-1, pred.shape[-1]),
                                [f"{lab} z{z}" for lab in cs_all.labels for z in zones], args.plot,
                                title=f"{base.name} calibrated on {args.captures}")
        files["plot"] = str(path)
    data = {"sensor": sensor.name, "base": base.name, "fit": fit.to_dict(),
            "holdout": None if holdout is None else holdout_dict(holdout), "files": files,
            "seconds": time.perf_counter() - t0}
    lines = [f"calibrated {base.name} on {args.captures} ({', '.join(steps)}; pulse {args.pulse}, noise {args.noise})"]
    for name in fit.fitted:
        err = fit.errors.get(name)
        shown = "unidentifiable" if err is None else f"+- {err:.3g}"
        lines.append(f"  {name:16s} {fit.values[name]:.6g} {shown}")
    lines.append(f"  mean Poisson deviance per bin {fit.deviance:.4g} on {int(fit.used.sum())} capture zones")
    lines += [f"  note: {m}" for m in fit.messages]
    if holdout is not None:
        lines.append(f"held out {holdout.n_holdout} captures (fit on {holdout.n_fit}, seed {args.seed}): peak-bin error "
                     f"mean |.| {holdout.peak_bin_error_mean_abs:.3f}, max {holdout.peak_bin_error_max_abs} bins; "
                     f"shape L1 mean {100 * holdout.shape_l1_mean:.2f} %, max {100 * holdout.shape_l1_max:.2f} %; "
                     f"amplitude pred/meas median {holdout.amplitude_ratio_median:.3f}")
    lines += [f"wrote {k}: {v}" for k, v in files.items()]
    emit(args, data, "\n".join(lines))
    return 0


def add(sub) -> None:
    """The ``calibrate`` subcommand."""
    p = sub.add_parser("calibrate", help="fit the sensor model to real captures of known geometry (sim-to-real)",
                       description=DESCRIPTION, epilog="examples:\n" + "\n".join(f"  {e}" for e in EXAMPLES),
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("captures", help="JSON captures of a plane at known distances (tmf882x_distance layout)")
    p.add_argument("--sensor", default="tmf8828-3x3-short", help="sensor to calibrate: preset or file (default: %(default)s)")
    p.add_argument("--steps", default="scale,pulse,noise",
                   help="calibration functions in order, from scale, pulse, noise (default: %(default)s)")
    p.add_argument("--pulse", choices=["shape", "gaussian"], default="shape",
                   help="non-parametric pulse shape (fitted on the fitting part) broadened by a Gaussian, "
                        "or a Gaussian alone (default: shape)")
    p.add_argument("--noise", choices=["measured", "global"], default="measured",
                   help="noise floor: each capture's own (median of its last 30 bins) or one fitted level "
                        "(default: measured)")
    p.add_argument("--zones", default="4", help="flat zone indices to fit, e.g. 4 (centre of 3x3) or 0,1,2,3,4 "
                                                "(default: %(default)s)")
    p.add_argument("--min-distance", type=float, default=0.06,
                   help="leave out captures closer than this, metres (near field, crosstalk overlap; default: 0.06)")
    p.add_argument("--start", metavar="NAME=V,...", help="start values, e.g. bin_width_ps=95,start_offset_ps=-1100 "
                                                        "(default: from leading edges and sums of the data)")
    p.add_argument("--holdout", type=float, default=0.0,
                   help="fraction of captures kept out of the fit and scored (default: 0, fit on all)")
    p.add_argument("--seed", type=int, default=0, help="seed of the holdout split (default: 0)")
    p.add_argument("--lights", choices=["on", "off"], default="on",
                   help="the captures' room lights: the noise floor becomes the ambient (on) or dark (off) rate")
    p.add_argument("--out", default="nlosplan-out/calibrated_sensor.toml",
                   help="calibrated sensor file, .toml or .json ('' for none; default: %(default)s)")
    p.add_argument("--plot", default="nlosplan-out/calibration.png", help="residual plot PNG ('' for none)")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(func=_cmd_calibrate)
