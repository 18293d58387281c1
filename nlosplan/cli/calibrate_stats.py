"""``nlosplan calibrate --stats FILE``: fit sensor, scene and protocol nuisances to a statistics file.

The workflow is :func:`nlosplan.calibration.stats_workflow.calibrate_stats`; this module checks the options, shows
progress, prints the fit and its row-by-row table and has the files written.
"""

from __future__ import annotations

import time
from contextlib import ExitStack

from nlosplan.cli.common import emit, note, progress_bar
from nlosplan.errors import UserError

#: Options of ``calibrate`` that fit plane or DENALI captures, not statistics.
NOT_FOR_STATS = ("captures", "score", "model", "terms", "folds", "where", "fidelity", "zones", "start", "lights",
                 "min_distance", "pulse", "trust_pickle")


def _free(text: str | None) -> tuple | None:
    """The names of ``--fit`` (None: the default set)."""
    if not text:
        return None
    return tuple(n.strip() for n in text.split(",") if n.strip())


def _check_options(args) -> None:
    """One line for an option that does not apply to ``--stats``."""
    for name in NOT_FOR_STATS:
        value = getattr(args, name, None)
        if value not in (None, False):
            raise UserError(f"--{name.replace('_', '-')} does not apply to --stats" if name != "captures" else
                            "give either CAPTURES or --stats FILE, not both")
    if args.holdout:
        raise UserError("--holdout does not apply to --stats (a statistics file has no captures to hold out)")
    if args.steps != "scale,pulse,noise":
        raise UserError("--steps does not apply to --stats (choose the fitted parameters with --fit)")


def _bars(args, stack: ExitStack):
    """``progress(stage, done, total)`` that shows one bar per stage (bootstrap, then model variants), one at a time."""
    titles = {"bootstrap": "bootstrap", "variants": "model variants"}
    current: dict = {}

    def progress(stage, done, total):
        if current.get("stage") != stage:
            if "stack" in current:
                current["stack"].close()  # the previous stage's bar ends before the next one starts
            current.update(stage=stage, stack=stack.enter_context(ExitStack()))
            current["bar"] = current["stack"].enter_context(progress_bar(args, total, titles[stage], "refit"))
        if current["bar"] is not None:
            current["bar"].update(1)

    return progress


def _text(cal, args) -> str:
    """The fit, its parameters with their intervals, the variants, the Table-2 rows and the files written."""
    from nlosplan.calibration.stats_variants import variant_summary
    from nlosplan.reports.realism_table import format_table2

    fit, iv = cal.fit, cal.intervals
    lines = [f"fitted {', '.join(fit.free)} of {cal.sensor.name} to {args.stats} ({30 * cal.positions} scenes per "
             f"size, noise seed {cal.seed}): objective {fit.objective:.4g} after {fit.evaluations} evaluations"
             + ("" if fit.converged else f"; NOT converged: {fit.message}")]
    for k in tuple(fit.free) + tuple(k for k in iv if k not in fit.free):
        p = iv.get(k)
        err = "" if p is None else f" +- {p['std']:.3g} (95 % {p['lo']:.4g} to {p['hi']:.4g})"
        lines.append(f"  {k:26s} {fit.values[k]:.5g}{err}")
    lines.append(f"uncertainty: {cal.method}")
    if cal.variants:
        lines += variant_summary(cal.variants)
    lines.append(format_table2(cal.score))
    srcs = [f"{r.source.split(':')[0]} (sha256 {r.sha256[:12]}...)" if r.sha256 else r.source.split(":")[0]
            for r in cal.fitted_to if r.use == "fitted"]
    lines.append(f"fitted to: {'; '.join(srcs)}" + ("; the sensor file records it with the values each gave "
                                                      "('nlosplan sensor show FILE')" if cal.files else ""))
    lines += [f"wrote {k}: {v}" for k, v in cal.files.items()]
    return "\n".join(lines)


def run_stats(args, t0: float) -> int:
    """Check the options, run the workflow, write the sensor file, its scene table and uncertainty, print the table."""
    from nlosplan.calibration.bootstrap import MIN_RESAMPLES
    from nlosplan.calibration.stats_workflow import DEFAULT_SENSOR, calibrate_stats, check_free
    from nlosplan.files import check_output_file

    _check_options(args)
    if 0 < args.bootstrap < MIN_RESAMPLES:
        raise UserError(f"bootstrap refits {args.bootstrap} < {MIN_RESAMPLES}: give at least {MIN_RESAMPLES} "
                        "(30 or more for a 95 % interval)")
    free = check_free(_free(args.fit))
    if args.out:  # before the fit, not after it
        check_output_file(args.out, "--out", suffixes=(".toml", ".json"))
    with ExitStack() as stack:
        cal = calibrate_stats(args.stats, sensor=args.sensor or DEFAULT_SENSOR, scene=args.scene, free=free,
                              positions=args.positions or 10, seed=args.seed, bootstraps=args.bootstrap,
                              variants=bool(args.variants), say=lambda text: note(args, text),
                              progress=_bars(args, stack))
    if args.out:
        cal.write(args.out)
    emit(args, {**cal.to_dict(), "seconds": time.perf_counter() - t0}, _text(cal, args))
    return 0
