"""``nlosplan calibrate``: fit the sensor model to real captures of known geometry (sim-to-real)."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from nlosplan.cli.calibrate_plane import zone_list
from nlosplan.cli.common import emit, int_type, note, number_type, progress_bar, seed_type
from nlosplan.errors import UserError
from nlosplan.schema import parse_number

EXAMPLES = (
    "nlosplan calibrate ../shared/data/tmf882x_distance/distance_data_even.json --out out/calibrated.toml "
    "--plot out/calibration.png",
    "nlosplan calibrate --score ../shared/data/tmf882x_distance/distance_data_even.json --sensor out/calibrated.toml",
    "nlosplan calibrate captures.json --terms offsets,gains,pileup --folds 4 --json",
    "nlosplan calibrate captures.json --model global --holdout 0.5 --steps scale,pulse --pulse gaussian --json",
    "nlosplan calibrate denali-data/data --where zones=3x3,lights=off --holdout 0.3 --out out/denali3x3.toml",
    "nlosplan calibrate out/denali.sqlite --where 'zones=8x8,object=NOOBJECT|A' --sensor tmf8828-8x8-short --json",
)

DESCRIPTION = """\
Calibrate the sensor model against real histograms of known geometry. CAPTURES
is one of:

  a JSON file     a flat plane square-on at known distances (entries with
                  dist_to_plane, hists (zones x bins) and reference_hist, as
                  ../shared/data/tmf882x_distance); each capture's matching
                  simulated scene is the plane at its distance.
  a DENALI folder the folder holding <object>_<4inch|8inch>_<3x3|8x8>_
                  <lighton|lightoff>_NLOSdata/spad_histogram/NNN.npy
                  (repeats x H x W x 128, NNN the gantry position); each
                  capture's matching scene is the DENALI rig (relay wall,
                  tables) with its object at its position (NOOBJECT: none,
                  NOOBJECTMOUNT: the bare mount): first-bounce wall returns
                  plus the object's three-bounce light (fast simulator).
  a capture store a .sqlite file of 'nlosplan dataset import-denali' (or
                  'dataset build'): the same, from the store.

DENALI folders and stores take --where filters (e.g. zones=3x3,lights=off;
one zone mode at a time), fit every zone that sees the relay wall by default,
use the captures' stored sensor unless --sensor is given, hold out whole
gantry positions, and measure each zone's floor on the bins no simulated light
reaches, over the captures of one folder (the object's return may fall in the
last bins).

Plane captures (JSON), default model 'zones': every zone is fitted by
Poisson maximum likelihood (L-BFGS with exact JAX gradients on normalized,
bounded variables) with the terms the real plane data asks for (--terms):
per-zone time offsets and time scales (TDC delay and rate), per-zone gains,
per-zone near-field overlap r^2/(r^2+d0^2), pile-up (first photon per zone;
the captures' iterations are fitted from it), an exponential pulse tail after
32 free pulse samples; the floor of each capture zone is measured on its bins
before any return (the room light on the plane). --folds K cross-validates by
distance: each capture is predicted by the sensor file of a fit that did not
see it, and the per-zone table (sub-bin peak error, L1 of the shape, amplitude
ratio) is printed against the targets; the K refits give jackknife errors.
About 1 min per fit on 2 idle cores (5 folds: 5-6 min). --score DATA --sensor
FILE prints that table for any sensor file without fitting anything.

Model 'global' and DENALI inputs: fitted with nlopt (BOBYQA) on normalized,
bounded variables by Poisson maximum likelihood: global photon scale, pulse width (a Gaussian broadening a
non-parametric pulse shape, or a Gaussian alone), bin width and time offset,
noise floor, crosstalk peak. DENALI's three calibration functions are steps
that stack: scale (global scaling), pulse (pulse-width and time-base
matching), noise (noise matching); a joint pass refines them together.
Uncertainties: Fisher information (statistical only; unidentifiable parameters
are flagged) and, with --bootstrap N, the spread of N refits on the fitted
captures resampled with replacement (it includes the model's own error). Saturated zones and zones without signal are left out with a
message. With --holdout F a seeded part F is kept out of the fit (captures, or
gantry positions for DENALI) and scored: peak-bin error, the normalized L1 of
the histogram shape and the amplitude ratio. Writes the calibrated sensor file
(--out, .toml or .json: usable as --sensor by every other command) and a
residual plot (--plot). About 20 s on the plane JSON; a DENALI folder of 10
positions x 2 repeats takes 20-30 s (the three-bounce simulation and the fit)."""


def _parse_start(text: str | None) -> dict:
    if not text:
        return {}
    out = {}
    for item in text.split(","):
        key, sep, value = item.partition("=")
        try:
            out[key.strip()] = parse_number(value)
        except ValueError:
            sep = ""
        if not sep or not key.strip():
            raise UserError(f"--start {text!r}: give NAME=VALUE pairs, e.g. bin_width_ps=95,start_offset_ps=-1100")
    return out


def _steps(text: str) -> list[str]:
    return [s.strip() for s in text.split(",") if s.strip()]


def _bootstrap(args, cal):
    """Bootstrap errors of the calibration when --bootstrap asks for them (None otherwise)."""
    if not args.bootstrap:
        return None
    note(args, f"bootstrap: refitting on {args.bootstrap} resamples of {len(cal.fit_captures.labels)} captures ...")
    with progress_bar(args, args.bootstrap, "bootstrap", "refit") as bar:
        return cal.bootstrap(args.bootstrap, args.seed,
                             progress=None if bar is None else (lambda done, total: bar.update(1)))


def _write(args, cal) -> dict:
    """The calibrated sensor file (--out) and the residual plot (--plot), as {kind: path}."""
    files = {}
    if args.out:  # written atomically, naming the preset it refines (base) when there is one
        from nlosplan.sensor_models import sensor_base

        cal.sensor.save(args.out, base=sensor_base(args.sensor))
        files["sensor"] = str(args.out)
    if args.plot:
        from nlosplan.reports.calibration_plot import plot_calibration

        cs, pred = cal.captures, cal.predicted()
        path = plot_calibration(cs.counts.reshape(-1, cs.counts.shape[-1]), pred.reshape(-1, pred.shape[-1]),
                                [f"{lab} z{z}" for lab in cs.labels for z in cal.zones], args.plot,
                                title=f"{cal.base.name} calibrated on {args.captures}")
        files["plot"] = str(path)
    return files


def _parameter_lines(fit, boot) -> list[str]:
    """One line per fitted parameter: value, Fisher error and (with --bootstrap) the bootstrap spread."""
    lines = []
    for name in fit.fitted:
        err = fit.errors.get(name)
        shown = "unidentifiable" if err is None else f"+- {err:.3g}"
        if boot is not None:
            lo, hi = boot.intervals[name]
            shown += f" (Fisher); bootstrap +- {boot.errors[name]:.3g}, 95 % [{lo:.6g}, {hi:.6g}]"
        lines.append(f"  {name:16s} {fit.values[name]:.6g} {shown}")
    lines.append(f"  mean Poisson deviance per bin {fit.deviance:.4g} on {int(fit.used.sum())} capture zones")
    if boot is not None:
        lines.append(f"  bootstrap: {boot.resamples} refits on captures resampled with replacement (seed {boot.seed})")
    return lines


def _scores_text(s) -> str:
    """Held-out peak-bin error, shape L1 and amplitude ratio of a PlaneHoldout or ZoneScores, one line."""
    return (f"peak-bin error mean |.| {s.peak_bin_error_mean_abs:.3f}, max {s.peak_bin_error_max_abs} bins; "
            f"shape L1 mean {100 * s.shape_l1_mean:.2f} %, max {100 * s.shape_l1_max:.2f} %; "
            f"amplitude pred/meas median {s.amplitude_ratio_median:.3f}")


def _cmd_calibrate(args) -> int:
    from nlosplan.calibration.bootstrap import MIN_RESAMPLES
    from nlosplan.calibration.denali_data import is_capture_store

    from nlosplan.cli import calibrate_plane

    t0 = time.perf_counter()
    if args.stats:
        from nlosplan.cli.calibrate_stats import run_stats

        return run_stats(args, t0)
    if args.fit is not None or args.variants or (args.positions is not None and not args.score):
        raise UserError("--fit, --variants and --positions apply to --stats (and --positions to --score of a "
                        "statistics file)")
    if args.score:
        return calibrate_plane.run_score(args, t0)
    from nlosplan.files import check_output_file, check_plot_path

    if args.out:  # before the fit (minutes), not after it
        check_output_file(args.out, "--out", suffixes=(".toml", ".json"))
    if args.plot:
        check_plot_path(args.plot)
    if not args.captures:
        raise UserError("give CAPTURES to fit, or --score DATA --sensor FILE to score a sensor without fitting")
    if 0 < args.bootstrap < MIN_RESAMPLES:  # before the fit, not after it
        raise UserError(f"bootstrap resamples {args.bootstrap} < {MIN_RESAMPLES}: give at least {MIN_RESAMPLES} "
                        "(30 or more for a 95 % interval)")
    if Path(args.captures).is_dir() or is_capture_store(args.captures):
        for flag, value in (("--model", args.model), ("--terms", args.terms), ("--folds", args.folds)):
            if value is not None:
                raise UserError(f"{flag} applies to JSON plane captures, not to a DENALI folder or a capture store")
        return _calibrate_denali(args, t0)
    for flag, value in (("--where", args.where), ("--fidelity", args.fidelity), ("--trust-pickle", args.trust_pickle)):
        if value not in (None, False):
            raise UserError(f"{flag} applies to a DENALI folder or a capture store, not to JSON plane captures")
    if (args.model or "zones") == "zones":
        if args.folds is None:
            args.folds = 5
        return calibrate_plane.run_zones(args, t0)
    for flag, value in (("--terms", args.terms), ("--folds", args.folds)):
        if value is not None:
            raise UserError(f"{flag} applies to --model zones (the all-zone model), not to --model global")
    return _calibrate_plane(args, t0)


def _calibrate_plane(args, t0: float) -> int:
    from nlosplan.calibration.plane import holdout_dict
    from nlosplan.calibration.workflow import calibrate_plane, load_plane

    args.sensor = args.sensor or "tmf8828-3x3-short"
    args.zones = args.zones or "4"
    args.pulse = args.pulse or "shape"
    args.lights = args.lights or "on"
    args.min_distance = 0.06 if args.min_distance is None else args.min_distance
    captures, base = load_plane(args.captures, args.sensor)
    zones = zone_list(args.zones, captures.hists.shape[1])
    steps = _steps(args.steps)
    if not 0 <= args.holdout < 1:
        raise UserError(f"--holdout {args.holdout} must be >= 0 and < 1 (the held-out fraction)")
    start = _parse_start(args.start)
    note(args, f"calibrating {base.name} on {captures.distance_m.size} captures ({', '.join(steps)}) ...")
    cal = calibrate_plane(captures, base, zones=zones, steps=steps, pulse=args.pulse, noise=args.noise,
                          min_distance_m=args.min_distance, start=start, holdout=args.holdout, seed=args.seed,
                          lights=args.lights)
    fit, holdout = cal.fit, cal.holdout
    boot = _bootstrap(args, cal)
    files = _write(args, cal)
    data = {"sensor": cal.sensor.name, "base": base.name, "fit": fit.to_dict(),
            "bootstrap": None if boot is None else boot.to_dict(),
            "holdout": None if holdout is None else holdout_dict(holdout), "files": files,
            "seconds": time.perf_counter() - t0}
    lines = [f"calibrated {base.name} on {args.captures} ({', '.join(steps)}; pulse {args.pulse}, noise {args.noise})"]
    lines += _parameter_lines(fit, boot)
    lines += [f"  note: {m}" for m in fit.messages]
    if holdout is not None:
        lines.append(f"held out {holdout.n_holdout} captures (fit on {holdout.n_fit}, seed {args.seed}): "
                     + _scores_text(holdout))
    lines += [f"wrote {k}: {v}" for k, v in files.items()]
    emit(args, data, "\n".join(lines))
    return 0


def _calibrate_denali(args, t0: float) -> int:
    from nlosplan.calibration import STEPS
    from nlosplan.calibration.workflow import calibrate_denali, load_denali
    from nlosplan.cli.common import parse_where

    for flag, value in (("--lights", args.lights), ("--min-distance", args.min_distance)):
        if value is not None:
            raise UserError(f"{flag} applies to JSON plane captures only; DENALI captures carry their lights label "
                            "and fixed geometry (filter them with --where)")
    steps = _steps(args.steps)
    bad = [s for s in steps if s not in STEPS]
    if bad or not steps:
        raise UserError(f"unknown calibration step(s) {', '.join(bad) or '(none)'}; allowed: {', '.join(STEPS)}")
    if not 0 <= args.holdout < 1:
        raise UserError(f"--holdout {args.holdout} must be >= 0 and < 1 (the held-out fraction)")
    start = _parse_start(args.start)
    fidelity = args.fidelity or "default"
    caps, base = load_denali(args.captures, parse_where(args.where), sensor=args.sensor,
                             trust_pickle=args.trust_pickle, fidelity=fidelity, noise=args.noise)
    zones = zone_list(args.zones, base.n_zones) if args.zones else None
    where = "DENALI folder" if Path(args.captures).is_dir() else "capture store"
    cal = calibrate_denali(
        caps, base, steps=steps, zones=zones, pulse=args.pulse, noise=args.noise, start=start,
        holdout=args.holdout, seed=args.seed, fidelity=fidelity,
        on_start=lambda: note(args, f"calibrating {base.name} on {len(caps)} captures of {args.captures} "
                                    f"({where}; {', '.join(steps)}) ..."))
    fit, holdout, zones, pulse = cal.fit, cal.holdout, cal.zones, cal.pulse
    boot = _bootstrap(args, cal)
    files = _write(args, cal)
    info = {**caps.describe(), "kind": where, "where": parse_where(args.where), "zones_fitted": zones,
            "pulse": pulse, "noise": args.noise, "fidelity": fidelity}
    data = {"sensor": cal.sensor.name, "base": base.name, "input": info, "fit": fit.to_dict(),
            "bootstrap": None if boot is None else boot.to_dict(), "holdout": None if holdout is None else holdout.to_dict(), "files": files,
            "seconds": time.perf_counter() - t0}
    lines = [f"calibrated {base.name} on {args.captures} ({where}: {len(caps)} captures at {info['positions']} "
             f"positions, {', '.join(info['objects'])}, lights {'/'.join(info['lights'])}; zones "
             f"{','.join(map(str, zones))}; {', '.join(steps)}; pulse {pulse}, noise {args.noise})"]
    lines += _parameter_lines(fit, boot)
    lines += [f"  note: {m}" for m in fit.messages]
    if holdout is not None:
        h = holdout.scores
        lines.append(f"held out {len(holdout.positions_holdout)} positions ({holdout.n_holdout} captures, "
                     f"{len(h.peak_bin_error)} capture zones; fit on {len(holdout.positions_fit)} positions, "
                     f"{holdout.n_fit} captures, seed {args.seed}): " + _scores_text(h))
    lines += [f"wrote {k}: {v}" for k, v in files.items()]
    emit(args, data, "\n".join(lines))
    return 0


def add(sub) -> None:
    """The ``calibrate`` subcommand."""
    p = sub.add_parser("calibrate", help="fit the sensor model to real captures of known geometry (sim-to-real)",
                       description=DESCRIPTION, epilog="examples:\n" + "\n".join(f"  {e}" for e in EXAMPLES),
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("captures", nargs="?", help="JSON captures of a plane at known distances (tmf882x_distance "
                                               "layout), a DENALI-layout folder, or a capture store (.sqlite)")
    p.add_argument("--score", metavar="DATA",
                   help="score --sensor on DATA without fitting anything: the per-zone table (plane captures) or the "
                        "per-row table (a statistics file, e.g. the shipped DENALI Table 2)")
    p.add_argument("--stats", metavar="FILE",
                   help="fit to a statistics file (e.g. denali-table2, the shipped DENALI Table 2): sensor photon "
                        "scale and floor, object albedo and the file's protocol nuisances, from noisy simulated "
                        "captures with DENALI's processing (common random numbers, nlopt); writes --out, its "
                        "<stem>.scene.toml and <stem>.uncertainty.json (--bootstrap N: refits within the SEMs)")
    p.add_argument("--fit", metavar="NAME,...",
                   help="--stats: parameters to fit (default: photon_scale, dark_rate_hz, albedo and the nuisances)")
    p.add_argument("--variants", action="store_true",
                   help="--stats: also refit under the 80 model variants Table 2 cannot decide (repeat-mean or "
                        "single captures, the checkpoint levels read 3 %% low or high, object diffuse base 0-0.3, "
                        "mount in or out of the background); their spread joins the uncertainty")
    p.add_argument("--positions", type=int_type(1, 100), metavar="N",
                   help="--stats/--score of a statistics file: gantry positions per object simulated (default: 10; "
                        "fewer are a coarser sample of the gantry grid)")
    p.add_argument("--scene", metavar="FILE",
                   help="statistics files: the scene table ([scene], [nuisances] TOML) to score or start from "
                        "(default: the sensor file's <stem>.scene.toml, or a denali-tmf8828-* preset's own fit)")
    p.add_argument("--model", choices=["zones", "global"],
                   help="JSON plane captures: 'zones' fits every zone with the per-zone terms, amplitude law, pile-up "
                        "and pulse tail; 'global' the single-zone model with one photon scale (zone 4 by default) "
                        "(default: zones)")
    p.add_argument("--terms", metavar="T,...",
                   help="--model zones: physics terms to fit, from offsets, scales, gains, overlap, pileup, tail "
                        "(default: all; leave some out for an ablation)")
    p.add_argument("--folds", type=int_type(0, 1000), metavar="K",
                   help="--model zones: cross-validate by distance with K folds, 0 for none (default: 5)")
    p.add_argument("--sensor", help="sensor to calibrate: preset or file (default: tmf8828-3x3-short for JSON; "
                                    "the captures' stored sensor for a DENALI folder or a store)")
    p.add_argument("--steps", default="scale,pulse,noise",
                   help="calibration functions in order, from scale, pulse, noise (default: %(default)s)")
    p.add_argument("--pulse", choices=["shape", "gaussian"],
                   help="non-parametric pulse shape broadened by a Gaussian, or a Gaussian alone; the shape is "
                        "fitted on the fitting part (JSON) or the sensor's measured one (DENALI) (default: shape; "
                        "DENALI: gaussian when the sensor has no pulse shape)")
    p.add_argument("--noise", choices=["measured", "global"], default="measured",
                   help="noise floor: each capture zone's own (JSON: median of its last 30 bins; DENALI: mean of "
                        "the bins no simulated light reaches, per folder) or one fitted level (default: measured)")
    p.add_argument("--zones", help="flat zone indices to fit, e.g. 4 (centre of 3x3) or 0,1,2,3,4 "
                                   "(default: every zone for JSON with --model zones, 4 with --model global; every "
                                   "zone that sees the relay wall for DENALI)")
    p.add_argument("--min-distance", type=number_type(float, zero_ok=True),
                   help="JSON only: leave out captures closer than this, metres, from the fit and the scores "
                        "(default: 0.06)")
    p.add_argument("--start", metavar="NAME=V,...", help="start values, e.g. bin_width_ps=95,start_offset_ps=-1100 "
                                                        "(default: from leading edges and sums of the data)")
    p.add_argument("--holdout", type=float, default=0.0,
                   help="fraction of captures kept out of the fit and scored (default: 0, fit on all)")
    p.add_argument("--seed", type=seed_type(), default=0, help="seed of the holdout split and the bootstrap (default: 0)")
    p.add_argument("--bootstrap", type=int_type(0, 1000), default=0, metavar="N",
                   help="also refit on N resamples of the fitted captures (with replacement) and report the spread: "
                        "uncertainties that include model error, unlike Fisher's; 1-4 s per refit (default: off)")
    p.add_argument("--lights", choices=["on", "off"],
                   help="JSON only: the captures' room lights: the noise floor becomes the ambient (on) or dark (off) "
                        "rate (default: on; DENALI captures are labelled, lights-off floors give the dark rate "
                        "and lights-on floors the ambient rate)")
    p.add_argument("--where", metavar="COL=V,...",
                   help="DENALI folder or store: filter of the captures, e.g. zones=3x3,lights=off,object=A|NOOBJECT "
                        "(columns of 'nlosplan dataset info'; alternatives a|b)")
    p.add_argument("--fidelity", help="DENALI folder or store: fast-simulator quadrature of the matching scenes, "
                                      "draft, low, default, high or reference (default: default)")
    p.add_argument("--trust-pickle", action="store_true",
                   help="DENALI folder: allow capture files that need pickle (they may run code when loaded)")
    p.add_argument("--out", default="nlosplan-out/calibrated_sensor.toml",
                   help="calibrated sensor file, .toml or .json ('' for none; default: %(default)s)")
    p.add_argument("--plot", default="nlosplan-out/calibration.png", help="residual plot PNG ('' for none)")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(func=_cmd_calibrate)
