"""``nlosplan evaluate``: fast model-based evaluators of a sensor design (``crlb``, ``observer``).

Thin front ends over :func:`nlosplan.tasks.bounds.localization_crlb_batch`
and :func:`nlosplan.tasks.ideal_observer.ideal_observer`; no logic beyond
parsing, building the scenes and the sensor, and printing.
"""

from __future__ import annotations

import math

from nlosplan.cli.common import command_group, emit, int_type, note, number_type, progress_bar, seed_type, sub_parser
from nlosplan.cli.selections import choice_list, fidelity_level, object_list, position_list
from nlosplan.errors import UserError

DEFAULT_SENSOR = "tmf8828-3x3-short"
_NUISANCE_CHOICES = ("photon_scale", "ambient", "dark", "albedo", "none")
_MAX_SCENE_LINES = 20


# ----------------------------------------------------------------- shared
def _sensor(args):
    """The sensor of ``--sensor``, with ``--photon-scale`` and ``--jitter-ps`` applied (validated again)."""
    from nlosplan.sensor_models import resolve_sensor

    s = resolve_sensor(args.sensor)
    changes, parts = {}, []
    if args.photon_scale is not None:
        changes["photon_scale"] = args.photon_scale
        parts.append(f"photon scale {args.photon_scale:g}")
    if getattr(args, "jitter_ps", None) is not None:
        changes["jitter_fwhm_ps"] = args.jitter_ps
        parts.append(f"jitter {args.jitter_ps:g} ps")
    if not changes:
        return s
    return s.replace(name=f"{s.name} ({', '.join(parts)})", **changes)


def _finite(value: float) -> float | None:
    """``None`` (JSON null) for an infinite or NaN bound, the float otherwise."""
    return float(value) if math.isfinite(value) else None


def _mm(value: float) -> str:
    return f"{1e3 * value:.3g}" if math.isfinite(value) else "NOT IDENTIFIABLE"


# ----------------------------------------------------------------- crlb
def _nuisance(names: list[str]) -> tuple[str, ...]:
    if "none" in names:
        if len(names) > 1:
            raise UserError("--nuisance none cannot be combined with other nuisance parameters")
        return ()
    return tuple(names)


def _crlb_table(rows: list[dict]) -> str:
    """Per object and size: RMS bound, known-nuisance RMS bound, worst scene, unidentifiable count (mm)."""
    import numpy as np
    import pandas as pd

    def rms(v):
        v = np.asarray(v, dtype=float)
        return float(np.sqrt(np.mean(v ** 2))) if np.all(np.isfinite(v)) else math.inf

    df = pd.DataFrame(rows)
    out = []
    for (obj, size), g in df.groupby(["object", "size"], sort=False):
        b, k = g["bound"].to_numpy(float), g["known"].to_numpy(float)
        out.append({"object": obj, "size": size, "scenes": len(g), "RMS bound mm": _mm(rms(b)),
                    "known-nuisance mm": _mm(rms(k)), "worst mm": _mm(float(np.max(b))),
                    "unidentifiable": int((~np.isfinite(b)).sum())})
    return pd.DataFrame(out).to_string(index=False)


def _cmd_crlb(args) -> int:
    from nlosplan.simulators import denali_scene
    from nlosplan.tasks.bounds import localization_crlb_batch

    sensor = _sensor(args)
    nuisance = _nuisance(args.nuisance)
    scenes = [denali_scene(o, s, p, args.lights) for o in args.objects for s in args.sizes for p in args.positions]
    note(args, f"Cramer-Rao bounds of {len(scenes)} scenes, {sensor.name}, fidelity {args.fidelity} ...")
    with progress_bar(args, len(scenes), "evaluate crlb", "scene") as bar:
        batch = localization_crlb_batch(scenes, sensor, fidelity=args.fidelity, repeats=args.repeats,
                                        nuisance=nuisance, progress=lambda done, total: bar.set(done, total))
    per_scene, rows, bad_lines = [], [], []
    for r in batch.results:
        m = r.meta
        per_scene.append({"object": m.get("object"), "size": m.get("size"), "position": m.get("position"),
                          "rmse_bound_m": _finite(r.rmse_bound_m), "rmse_bound_known_m": _finite(r.rmse_bound_known_m),
                          "loc_rmse_bound_m": _finite(r.loc_rmse_bound_m),
                          "std_m": [_finite(float(v)) for v in r.std_m],
                          "identifiable": bool(r.position_identifiable), "reason": r.reason,
                          "notes": list(r.notes)})
        rows.append({"object": m.get("object"), "size": m.get("size"), "bound": r.rmse_bound_m,
                     "known": r.rmse_bound_known_m})
        if not math.isfinite(r.rmse_bound_m):
            bad_lines.append(f"  {m.get('object')} {m.get('size')} position {m.get('position')}: NOT IDENTIFIABLE"
                             f" ({r.reason or 'no information on the position'})")
    data = {"rms_bound_m": _finite(batch.rms_bound_m), "rms_bound_known_m": _finite(batch.rms_bound_known_m),
            "loc_rmse_bound_m": _finite(batch.loc_rmse_bound_m),
            "unidentifiable": [per_scene[i] | {"index": i} for i in batch.unidentifiable],
            "seconds": batch.seconds, "fidelity": batch.fidelity, "knobs": batch.knobs,
            "sensor": sensor.name, "lights": args.lights, "repeats": args.repeats, "nuisance": list(nuisance),
            "scenes": per_scene}
    head = (f"{sensor.name}, lights {args.lights}, {args.repeats} capture(s) per scene, nuisance "
            f"{', '.join(nuisance) or 'none'} estimated")
    lines = [head, "", _crlb_table(rows), ""]
    if bad_lines:
        lines += [f"{len(bad_lines)} scene(s) where the position is NOT IDENTIFIABLE:"] + bad_lines[:_MAX_SCENE_LINES]
        if len(bad_lines) > _MAX_SCENE_LINES:
            lines.append(f"  ... and {len(bad_lines) - _MAX_SCENE_LINES} more (--json lists them all)")
        lines.append("")
    notes = sorted({n for r in batch.results for n in r.notes})
    lines += [f"note: {n}" for n in notes] + [batch.summary()]
    if math.isfinite(batch.loc_rmse_bound_m):  # the figure to set beside a model's loc_rmse (benchmark, design)
        lines.append(f"bound on DENALI's loc_rmse (x and y pooled: the 2-D bound / sqrt 2): "
                     f"{1e3 * batch.loc_rmse_bound_m:.3g} mm")
    emit(args, data, "\n".join(lines))
    return 0


# ----------------------------------------------------------------- observer
#: Peak bytes per noisy capture of the observer's draw plan (truths, positions, decisions and the permutations
#: they come from, int64), beside its fixed log-likelihood chunks and the simulation.
_BYTES_PER_DRAW = 48


def _check_observer_memory(args, sensor) -> None:
    """Refuse --draws the machine cannot hold, before the simulation (one line)."""
    from nlosplan.resources import check_memory

    classes = len(args.objects) if args.task == "shape" else 2
    scenes = len(args.positions) * (len(args.objects) if args.task == "shape" else 2 * len(args.objects))
    means = scenes * sensor.n_zones * sensor.n_bins * 8 * 3  # float64 means, their logs, a draw block
    check_memory(1.5e9 + means + args.draws * classes * _BYTES_PER_DRAW, f"--draws {args.draws}",
                 "use fewer --draws (the interval narrows as 1/sqrt(draws): 1,000 draws give about +-3 %)")


def _cmd_observer(args) -> int:
    from nlosplan.tasks.ideal_observer import ideal_observer

    if args.shape_known and args.task != "size":
        raise UserError("--shape-known only applies to the size task")
    sensor = _sensor(args)
    _check_observer_memory(args, sensor)
    note(args, f"ideal observer ({args.task}), {len(args.objects)} objects x {len(args.positions)} positions, "
               f"{args.draws} draws/class, fidelity {args.fidelity} ...")
    with progress_bar(args, None, "evaluate observer", "capture") as bar:
        def progress(stage, done, total):
            bar.stage(stage)
            bar.set(done, total)

        res = ideal_observer(args.task, sensor, objects=args.objects, size=args.size, positions=args.positions,
                             lights=args.lights, position_known=args.position_known, rule=args.rule,
                             shape_known=args.shape_known, draws=args.draws, seed=args.seed, fidelity=args.fidelity,
                             progress=progress)
    data = res.to_dict()
    data["chance"] = res.chance
    data["ci"] = list(res.ci)
    lo, hi = res.ci
    pos = "known" if res.position_known else f"unknown ({res.rule})"
    text = "\n".join([
        f"{sensor.name}, lights {args.lights}, task {res.task}: {len(res.classes)} classes, position {pos}"
        + (f", size {args.size}" if res.task == "shape" else ""),
        f"accuracy {res.accuracy:.3f}  [{lo:.3f}, {hi:.3f}] ({100 * res.confidence:.0f} % {res.ci_method} interval)",
        f"chance   {res.chance:.3f}",
        f"n {res.n} ({res.draws} draws/class), {res.seconds:.3g} s (simulation {res.seconds_simulation:.3g} s), "
        f"fidelity {res.fidelity}, seed {res.seed}",
    ])
    emit(args, data, text)
    return 0


# ----------------------------------------------------------------- parsers
CRLB_DESCRIPTION = """\
Cramer-Rao lower bound (CRLB) on hidden-object localization, from the fast
simulator's expected counts and their derivatives (forward-mode autodiff).
Each capture is treated as independent Poisson counts per zone and bin;
the Fisher information of --repeats captures is inverted, with the
--nuisance parameters (relative photon scale, ambient rate, dark rate,
object albedo) estimated alongside the 2D position (world x, y). The
"known-nuisance" column is the bound with them known.

Reading it: no UNBIASED estimator of the position can have an RMS error
below the bound; the table gives, per object and size, the RMS of the
per-scene bounds (the bound on a model's RMSE over those scenes), the
same with nuisances known, and the worst scene. Caveats: a biased model,
or one that knows the discrete gantry positions (a prior: DENALI has only
100), may beat it; it says nothing about how hard reaching it is.
A scene whose position has no information (e.g. --photon-scale 0) prints
NOT IDENTIFIABLE with the reason, never a number (null in --json).

Cost: one compiled batch. Measured on 2 CPU cores (1 busy), 3x3 sensor,
--fidelity default: 100 scenes (one object, positions 0-99) 16 s, about
0.1 s per scene plus ~5 s of compilation and start-up; all 30 objects x
2 sizes x 100 positions (6,000 scenes) about 10 min (extrapolated). More nuisances cost
little; --fidelity draft is cheaper (explore with it, report with default)."""

OBSERVER_DESCRIPTION = """\
Ideal-observer accuracy for DENALI shape or size classification (Monte
Carlo). The observer knows the forward model exactly: for each noisy
(Poisson) capture it picks the class with the largest likelihood, with
the unknown position (and, for the size task, shape) marginalised with a
uniform prior (--rule marginal, Bayes-optimal here) or maximised (--rule
max). --position-known tells it the true position.

Reading it: the accuracy is the Bayes-optimal CEILING for any classifier
trained and tested on data from the SAME model (same simulator, sensor,
positions); real captures differ from the model, so it is an optimistic
reference, not a prediction. The interval is the Monte-Carlo uncertainty
(95 % Wilson) of --draws noisy captures per class; chance is 1/classes.

Cost: one batch of expected histograms (hypotheses x positions scenes),
then draws x classes likelihoods against all of them. Measured on 2 CPU
cores (1 busy), 3x3 sensor, --fidelity default: 30 shapes x 20 positions,
100 draws/class 12 s; the simulation dominates and grows with the
scenes (30 x 100 positions: about a minute; the size task simulates
both sizes). Fewer positions or --fidelity draft are much faster."""


def _common(p, *, jitter: bool) -> None:
    """--sensor, --objects, --positions, --lights, --fidelity, --photon-scale (and --jitter-ps), --json."""
    p.add_argument("--sensor", default=DEFAULT_SENSOR, help="preset name or sensor file (default: %(default)s)")
    p.add_argument("--objects", type=object_list, default=object_list("all"), metavar="A,S,...",
                   help="objects, class groups (numbers, letters, shapes) or 'all' (default: all 30)")
    p.add_argument("--positions", type=position_list, default=position_list("0-99"), metavar="0-99",
                   help="gantry positions, e.g. 0-99, 0,5,9 or 0-9,50-59 (default: 0-99)")
    p.add_argument("--lights", choices=("on", "off"), default="off", help="room lights (default: off)")
    p.add_argument("--fidelity", type=fidelity_level, default="default",
                   help="simulator level: draft, low, default, high, reference (default: default)")
    p.add_argument("--photon-scale", type=number_type(float, zero_ok=True), metavar="F",
                   help="replace the sensor's photon scale (detected photons per unit response; >= 0)")
    if jitter:
        p.add_argument("--jitter-ps", type=number_type(float, zero_ok=True), metavar="J",
                       help="replace the sensor's timing-jitter FWHM, ps (>= 0)")
    p.add_argument("--json", action="store_true", help="machine-readable output")


def add(sub) -> None:
    """The ``evaluate`` subcommand with ``crlb`` and ``observer``."""
    esub = command_group(sub, "evaluate", "fast model-based evaluators of a sensor design (crlb, observer)",
                         "Fast model-based evaluators of a sensor design on DENALI scenes: the Cramer-Rao bound on "
                         "localization and the ideal observer's classification accuracy. Both assume the simulator is the "
                         "truth.",
                         metavar="EVALUATOR")

    c = sub_parser(esub, "crlb", "evaluate crlb",
                   "Cramer-Rao lower bound on localization RMSE (unbiased estimators), per object and size",
                   description=CRLB_DESCRIPTION)
    _common(c, jitter=True)
    c.add_argument("--sizes", type=choice_list(("4in", "8in")), default=["8in"], metavar="4in,8in",
                   help="object sizes (default: 8in)")
    c.add_argument("--repeats", type=int_type(1, 1_000_000), default=1,
                   help="independent captures per scene, 1 to 1,000,000 (default: 1; the bound scales as "
                        "1/sqrt(repeats))")
    c.add_argument("--nuisance", type=choice_list(_NUISANCE_CHOICES), default=["photon_scale"], metavar="N,N",
                   help="nuisance parameters estimated with the position, among photon_scale, ambient, dark, "
                        "albedo, or 'none' (default: photon_scale)")
    c.set_defaults(func=_cmd_crlb)

    o = sub_parser(esub, "observer", "evaluate observer",
                   "ideal-observer (Bayes-optimal) accuracy for shape or size classification",
                   description=OBSERVER_DESCRIPTION)
    o.add_argument("task", choices=("shape", "size"), help="shape: which object (at --size); size: 4in or 8in")
    _common(o, jitter=False)
    o.add_argument("--size", choices=("4in", "8in"), default="8in", help="object size of the shape task "
                                                                         "(default: 8in)")
    o.add_argument("--draws", type=int_type(1), default=100,
                   help="noisy captures per class (Monte-Carlo precision; default: 100)")
    o.add_argument("--seed", type=seed_type(), default=0, help="seed of the draws, 0 to 2**32-1 (default: 0)")
    o.add_argument("--position-known", action="store_true", help="tell the observer the true position")
    o.add_argument("--shape-known", action="store_true", help="size task: tell the observer the object's shape")
    o.add_argument("--rule", choices=("marginal", "max"), default="marginal",
                   help="unknown position/shape: marginalise (Bayes-optimal) or maximise (default: marginal)")
    o.set_defaults(func=_cmd_observer)
