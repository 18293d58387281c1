"""``nlosplan bench``: benchmarks that print figures.

``histogram`` and ``simulate`` (histogram formation, the fast simulator) are
here; ``rig`` (:mod:`.rig`), ``live`` (:mod:`.live`), ``fidelity``/``crossval`` (:mod:`.fidelity`),
``real`` (:mod:`.real`) and ``denali`` (:mod:`.denali`) in their own modules.
"""

from __future__ import annotations

import argparse
from typing import Sequence

from nlosplan.cli.bench import fidelity as fidelity_bench, live as live_bench, real as real_bench, rig as rig_bench
from nlosplan.cli.bench import denali as denali_bench

from nlosplan.cli.selections import choice_list, object_list
from nlosplan.cli.common import command_group, emit, int_type, number_type, progress_bar, sub_parser
from nlosplan.errors import UserError
from nlosplan.schema import parse_int
from nlosplan.simulators.bench import (
    DEFAULT_LEVELS,
    DEFAULT_OBJECTS,
    DEFAULT_PLOT,
    DEFAULT_SIZES,
    DEFAULT_REFERENCE_POSITIONS,
    Progress,
    check_levels,
    bench_simulate,
    bench_steps,
)
from nlosplan.denali import N_POSITIONS

#: Peak bytes per frame of ``bench histogram``'s batched call (8x8 zones x 128 bins: arrivals, rates, float64 and
#: float32 histograms, Poisson draws and their JAX buffers).
_BYTES_PER_FRAME = 64 * 128 * 8 * 8


def _cmd_bench_histogram(args) -> int:
    from nlosplan.reports.tables import format_table
    from nlosplan.resources import check_memory
    from nlosplan.sensor_models.bench import bench_histogram

    check_memory(1e9 + args.batch * (_BYTES_PER_FRAME + 64 * args.arrivals * 8 * 4), f"--batch {args.batch}",
                 "use a smaller --batch (256 is the default)")

    res = bench_histogram(batch=args.batch, min_seconds=args.seconds, arrivals_per_zone=args.arrivals)
    cols = ["zones", "dtype", "mode", "frames_per_second", "zone_histograms_per_second", "compile_seconds", "speedup_vs_numpy"]
    emit(args, res, format_table(res["rows"], cols) + f"\n({res['config']['terms']}; "
          f"{res['config']['arrivals_per_zone']} arrivals per zone; devices {res['config']['jax_devices']})")
    return 0


# ----------------------------------------------------------------- bench simulate
def _int_list(text: str) -> list[int]:
    try:
        out = [parse_int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a comma-separated list of integers") from None
    if not out:
        raise argparse.ArgumentTypeError("give at least one integer")
    return out


def _position_list(text: str) -> list[int]:
    out = _int_list(text)
    bad = [p for p in out if not 0 <= p < N_POSITIONS]
    if bad:
        raise argparse.ArgumentTypeError(f"{', '.join(map(str, bad))} out of range; allowed: positions 0 to "
                                         f"{N_POSITIONS - 1}")
    return out


def _level_list(text: str) -> list[str]:
    out = [v.strip() for v in text.split(",") if v.strip()]
    try:
        check_levels(out)
    except UserError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return out


def add_arguments(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Add the options of ``nlosplan bench simulate`` to ``parser``."""
    parser.add_argument("--levels", type=_level_list, default=list(DEFAULT_LEVELS),
                        help=f"comma-separated fidelity levels (default: {','.join(DEFAULT_LEVELS)})")
    parser.add_argument("--positions", type=int_type(1, N_POSITIONS), default=N_POSITIONS, metavar="N",
                        help=f"batch over the first N of the {N_POSITIONS} DENALI positions (default: %(default)s)")
    parser.add_argument("--reference-positions", type=_position_list, default=None, metavar="P,P,...",
                        help="positions of the float64 reference (~10-20 s each; default: "
                             f"{','.join(map(str, DEFAULT_REFERENCE_POSITIONS))}, those among the first N)")
    parser.add_argument("--objects", type=object_list, default=list(DEFAULT_OBJECTS), metavar="A,S,...",
                        help="DENALI objects of the mixed batch; position p holds object p mod their number "
                             f"(default: {','.join(DEFAULT_OBJECTS)})")
    parser.add_argument("--sizes", type=choice_list(("4in", "8in")), default=list(DEFAULT_SIZES), metavar="8in,4in",
                        help=f"sizes, changing every len(objects) positions (default: {','.join(DEFAULT_SIZES)})")
    parser.add_argument("--sensor", default="tmf8828-3x3-short", help="preset name or sensor file (default: %(default)s)")
    parser.add_argument("--dtype", default="float32", choices=["float32", "float64"],
                        help="precision of the timed levels (default: %(default)s; the reference is float64)")
    parser.add_argument("--repeats", type=int_type(1), default=3, help="timed calls per figure, best kept (default: 3)")
    parser.add_argument("--plot", nargs="?", const=DEFAULT_PLOT, default=None, metavar="PATH",
                        help=f"also plot error against run time: {DEFAULT_PLOT}, or PATH (.png, .pdf, .svg, ...)")
    parser.add_argument("--baseline", action="store_true",
                        help="also time each scene model with the path of before issue 20 (two scalar "
                             "scatter-adds, chunk parameters gathered on every call, chunks one after the other) "
                             "beside the current one in the same run; prints the ratios")
    parser.add_argument("--json", action="store_true", help="machine-readable output")
    return parser


def reference_positions_for(n_positions: int, given: Sequence[int] | None) -> tuple[int, ...]:
    """The reference positions of a run over the first ``n_positions`` (defaults that fit, else 0)."""
    if given is not None:
        return tuple(given)
    fit = tuple(p for p in DEFAULT_REFERENCE_POSITIONS if p < n_positions)
    return fit or (0,)


def run_from_args(args: argparse.Namespace, progress: Progress | None = None, **options) -> tuple[dict, str]:
    """Run the benchmark from parsed options and write the plot.

    Parameters
    ----------
    args : argparse.Namespace
        From a parser prepared by :func:`add_arguments`.
    progress : callable, optional
        Called with a short text per step (:func:`bench_steps` of them).
    **options
        Further keywords of :func:`bench_simulate` (``study_level``, ``matmul_n``).

    Returns
    -------
    result : dict
        As :func:`bench_simulate`, with ``plot`` (the PNG path) when one was written.
    text : str
        :func:`format_bench_simulate` and the plot path.
    """
    positions = range(args.positions)
    result = bench_simulate(levels=tuple(args.levels), positions=positions,
                            reference_positions=reference_positions_for(args.positions, args.reference_positions),
                            objects=tuple(args.objects), sizes=tuple(args.sizes), sensor=args.sensor, dtype=args.dtype,
                            repeats=args.repeats, progress=progress, baseline=getattr(args, "baseline", False),
                            **options)
    from nlosplan.reports.bench_text import format_bench_simulate

    text = format_bench_simulate(result)
    if args.plot:
        from nlosplan.reports.error_runtime_plot import plot_error_runtime

        cfg = result["config"]
        path = plot_error_runtime(
            result["levels"], args.plot,
            title=f"fast simulator: DENALI mixed objects, {cfg['zones']}x{cfg['n_bins']}, {cfg['dtype']}",
            reference_self_error=result["reference"]["reference_self_error"])
        result["plot"] = str(path)
        text += f"\nplot: {path}"
    return result, text




def check_arguments(args: argparse.Namespace) -> None:
    """What ``bench simulate`` checks before any work: the sensor and the plot path (one line each)."""
    from nlosplan.files import check_plot_path
    from nlosplan.sensor_models import resolve_sensor

    resolve_sensor(args.sensor)
    if args.plot:
        check_plot_path(args.plot, "--plot")


def _cmd_bench_simulate(args) -> int:
    check_arguments(args)
    steps = bench_steps(args.levels, reference_positions_for(args.positions, args.reference_positions),
                        baseline=args.baseline)
    with progress_bar(args, steps, "bench simulate", "step") as bar:
        def progress(text: str) -> None:
            bar.update(1, text[:60])

        result, text = run_from_args(args, progress)
    emit(args, result, text)
    return 0


def add(sub) -> None:
    """The ``bench`` subcommand with ``histogram`` and ``simulate``."""
    bsub = command_group(sub, "bench", "benchmarks that print figures",
                         "Benchmarks that print figures.",
                         metavar="BENCHMARK")
    bh = sub_parser(bsub, "histogram", "bench histogram",
                    "histograms per second: 3x3x128 and 8x8x128, jitter + ambient + Poisson, single and vmap-batched")
    bh.add_argument("--batch", type=int_type(1), default=256, help="frames per batched call (default: %(default)s)")
    bh.add_argument("--seconds", type=number_type(float, hi=600), default=1.0,
                    help="minimum timed seconds per figure, > 0 (default: %(default)s)")
    bh.add_argument("--arrivals", type=int_type(1, 4096), default=16, help="arrival impulses per zone (default: %(default)s)")
    bh.add_argument("--json", action="store_true", help="machine-readable output")
    bh.set_defaults(func=_cmd_bench_histogram)
    bs = sub_parser(bsub, "simulate", "bench simulate",
                    "error against run time of the fast simulator on DENALI 3x3: every fidelity level single and "
                    "batched over the 100 positions, its error against a converged reference, what pruning saves",
                    description=BENCH_SIMULATE_DESCRIPTION)
    add_arguments(bs)
    bs.set_defaults(func=_cmd_bench_simulate)
    rig_bench.add_bench(bsub)
    fidelity_bench.add_bench(bsub)
    live_bench.add_bench(bsub)
    real_bench.add_bench(bsub)
    denali_bench.add_bench(bsub)


BENCH_SIMULATE_DESCRIPTION = """\
Error against run time of the fast simulator (DENALI rig, 3x3 zones, 128 bins).

For each fidelity level: seconds per scene one at a time and batched over the
gantry positions (JAX compile time apart), histograms per second, and the error
of the three-bounce histogram (expected minus the no-object background) against
a converged float64 reference: relative L1 and centroid shift in bins. Also the
reference's own error, what pruning saves (pruned vs prune=False, the centre
zone alone, lights off vs on), the arithmetic rate against a float32 matrix
product measured in the same process, and the scene models timed back to back
at the default level, each against its own reference: retroreflective (the
preset), mixed (retroreflective 0.36 on a Lambertian base of 0.2, DENALI's
Table-2 fit) and mixed+mount (with the mount and plate in the signal; also
timed as DENALI's captures come, every object and size at each position, where
the mount is computed once per position). Takes several minutes (the
references).
JSON: {"levels": [{"fidelity", "scenes_per_second", "rel_l1_error",
"centroid_shift_bins", ...}...], "reference", "pruning", "arithmetic",
"models": [{"model", "scenes_per_second", "speed_ratio_vs_retroreflective",
"rel_l1_error", "centroid_shift_bins", "layout" (mount models: {"scenes",
"positions", "objects_and_sizes", "scenes_per_second"}), ...}...], ...}."""
