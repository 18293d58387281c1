"""``nlosplan study active-vs-raster``: capture strategies against DENALI's raster on a simulated rig."""

from __future__ import annotations

import argparse
import sys
import time

from nlosplan.cli.common import emit, int_type, names_type, number_type
from nlosplan.errors import UserError
from nlosplan.schema import parse_int, parse_number

DEFAULT_OUT = "nlosplan-out/active"
EXAMPLES = (
    "nlosplan study active-vs-raster --out out/active",
    "nlosplan study active-vs-raster --strategies raster,active,doptimal --seeds 0,1 --budget 60 --json",
    "nlosplan study active-vs-raster --config nlosplan/experiments/active_vs_raster.toml --target-rmse 0.025",
)

DESCRIPTION = """\
Capture planning against DENALI's raster, on a simulated rig. The DENALI
gantry with one hidden object (letter A, 8 in, lights off, TMF8828 3x3)
offers a GRID x GRID lattice of candidate positions over its 0-320 mm
travel (19 x 19: DENALI's 10 x 10 and the points between them), screened
by the keep-out rules (gantry limits, object in the LiDAR's direct view).
The rig's truth differs from the planner's nominal simulator by a
registration offset (3, -2 mm), photon scale (+10 %) and albedo (-14 %).

Each strategy runs the ask/tell loop in batches (route-ordered by
nearest neighbour + 2-opt; gantry time from a feed/acceleration model with
0.5 s settle and 1 s capture per stop) until both targets are reached or
the budget is spent, once per seed. After every batch: the localization
RMSE (DENALI's loc_rmse, x and y errors pooled) of the planner's ensemble
localizer on fixed noisy test captures at
positions off the grid, and the calibration error (largest parameter
error in units of 0.5 mm, 0.5 mm, 1 %, 1 %).

Strategies: raster (DENALI's snake), random, active (ensemble-spread
mutual information, joint batch), doptimal (D-optimal calibration design,
relaxed weights by casadi/IPOPT, rounded with exchanges), and the -motion
variants (information per second of gantry time, batch chosen jointly).

Writes into --out: active_vs_raster.json (every curve and setting),
active_vs_raster.md (the table) and active_vs_raster.png (--plot moves it).
Table: captures and gantry seconds to each target (the localization target
and --more-targets, read from the same runs: a run stops once the tightest
localization target and the calibration target are both reached), median
[min-max] over seeds; n/r: not reached within the budget.

Cost, measured on 2 shared CPU cores: about 25 s to simulate the 361
candidates and 40 test positions (draft fidelity), then 2-25 s per
strategy and seed (the default 6 strategies x 3 seeds: about 5 min)."""


def _seeds(text: str) -> list[int]:
    try:
        out = [parse_int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: seeds are comma-separated integers, e.g. 0,1,2") from None
    if not out:
        raise argparse.ArgumentTypeError("give at least one seed")
    return list(dict.fromkeys(out))


def _targets(text: str) -> list[float]:
    try:
        out = [parse_number(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: targets are comma-separated metres, e.g. 0.04,0.05") from None
    if not out or any(not 0 < v < float("inf") for v in out):
        raise argparse.ArgumentTypeError(f"{text!r}: give targets > 0 m, e.g. 0.04,0.05")
    return out


def _study(args):
    from nlosplan.experiments.active_vs_raster import ActiveStudy

    settings = {}
    if args.config:
        from nlosplan.schema import load_table

        settings = load_table(args.config, "study config", suffixes=(".toml",)).get("study", {})
        if not isinstance(settings, dict):
            raise UserError(f"study config {args.config}: [study] must be a table, not {type(settings).__name__}")
    for key, value in (("strategies", args.strategies), ("seeds", args.seeds), ("budget", args.budget),
                       ("batch_size", args.batch), ("grid", args.grid), ("test_points", args.test_points),
                       ("target_rmse_m", args.target_rmse), ("more_targets_m", args.more_targets),
                       ("target_calibration", args.target_calibration),
                       ("obj", args.object)):
        if value is not None:
            settings[key] = value
    return ActiveStudy.from_dict(settings)


def _cmd(args) -> int:
    from nlosplan.experiments.active_vs_raster import run_active_study
    from nlosplan.reports.active_study_plot import active_text, write_active

    study = _study(args)
    started = time.perf_counter()

    def progress(event: dict) -> None:
        if args.quiet or args.json:
            return
        if event["event"] == "world":
            line = f"[active] simulated {event['candidates']} candidates and the test set in {event['seconds']:.1f} s"
        else:
            line = (f"[active] {event['strategy']} seed {event['seed']} ({event['index']}/{event['total']}) in "
                    f"{event['seconds']:.1f} s, {time.perf_counter() - started:.0f} s so far")
        print(line, file=sys.stderr, flush=True)

    result = run_active_study(study, progress=progress)
    files = write_active(result, args.out, plot=args.plot)
    result["files"] = files
    data = {k: v for k, v in result.items() if k != "runs"} if args.json else result
    emit(args, data, active_text(result) + "\n\n" + "\n".join(f"wrote {k}: {v}" for k, v in files.items()))
    return 0


def add_study(ssub) -> None:
    """Register ``nlosplan study active-vs-raster``."""
    from nlosplan.planner.capture import STRATEGIES

    p = ssub.add_parser("active-vs-raster", help="capture strategies against DENALI's raster (simulated rig)",
                        description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter,
                        epilog="examples:\n" + "\n".join(f"  {e}" for e in EXAMPLES))
    g = p.add_argument_group("study")
    g.add_argument("--config", metavar="TOML", help="study settings ([study] table; options below override it)")
    g.add_argument("--strategies", type=names_type("strategy", STRATEGIES), metavar="S,S",
                   help=f"strategies (default: all: {','.join(STRATEGIES)})")
    g.add_argument("--seeds", type=_seeds, metavar="N,N", help="seeds (default: 0,1,2)")
    g.add_argument("--budget", type=int_type(1, 361), metavar="N", help="most captures per run (default: 100)")
    g.add_argument("--batch", type=int_type(1, 50), metavar="N", help="positions per batch (default: 5)")
    g.add_argument("--grid", type=int_type(2, 41), metavar="N", help="candidate lattice N x N (default: 19)")
    g.add_argument("--test-points", type=int_type(2, 1000), metavar="N",
                   help="localization test positions (default: 40)")
    g.add_argument("--target-rmse", type=number_type(float), metavar="M",
                   help="localization target RMSE, metres (default: 0.05, as nlosplan design's requirement)")
    g.add_argument("--more-targets", type=_targets, metavar="M,M",
                   help="further localization targets reported from the same runs, metres (default: 0.03,0.04)")
    g.add_argument("--target-calibration", type=number_type(float), metavar="X",
                   help="calibration target, largest error in tolerances (default: 1)")
    g.add_argument("--object", metavar="NAME", help="DENALI object (default: A)")
    o = p.add_argument_group("output")
    o.add_argument("--out", default=DEFAULT_OUT, metavar="DIR", help="output folder (default: %(default)s)")
    o.add_argument("--plot", metavar="PATH", help="figure path (default: OUT/active_vs_raster.png)")
    o.add_argument("--json", action="store_true", help="print the result as JSON (without the per-batch curves)")
    o.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    p.set_defaults(func=_cmd)
