"""``nlosplan study resolution|bins``: studies through the design planner (one report each)."""

from __future__ import annotations

import sys

from nlosplan.cli.common import emit, int_type, sub_parser


def _cmd(args) -> int:
    from nlosplan.experiments.design_studies import run_design_study
    from nlosplan.reports.design_report import requirements_table, write_design_report

    def progress(text, done, total):
        if not args.json and done is None:
            print(f"nlosplan study {args.study}: {text}", file=sys.stderr, flush=True)

    out = args.out or f"nlosplan-out/study_{args.study}"
    result = run_design_study(args.study, out, quick=args.quick, requirements=args.requirement, resume=args.resume,
                              workers=args.workers, progress=progress)
    result["report"] = write_design_report(result, out)["html"]
    from nlosplan.reports.tables import format_table

    text = (format_table(requirements_table(result).to_dict("records"))
            + f"\n\nreport: {result['report']} ({result['provenance']['wall_seconds']:.0f} s)")
    emit(args, {"study": args.study, "requirements": result["requirements"], "curves": result["curves"],
                "report": result["report"]}, text)
    return 0


def add_study(ssub) -> None:
    """``study resolution`` and ``study bins``."""
    from nlosplan.cli.design import requirement_type
    from nlosplan.experiments.design_studies import DESIGN_STUDIES

    for name, (_, what) in DESIGN_STUDIES.items():
        p = sub_parser(ssub, name, f"study {name}", f"{what}, through the design planner",
                       description=f"{what}.\n\nRuns the design planner (nlosplan design) on this study's axes only "
                                   "(TOML in nlosplan/experiments/) and writes its report: the metric of every task "
                                   "against the axis, the least hardware that meets each requirement, Pareto fronts.")
        p.add_argument("--quick", action="store_true", help="the quick run's scenes and grids (about a minute)")
        p.add_argument("--requirement", action="append", type=requirement_type, metavar="REQ",
                       help="as in nlosplan design, e.g. loc<=0.05 (replaces the defaults)")
        p.add_argument("--out", metavar="DIR", help=f"output folder (default: nlosplan-out/study_{name})")
        p.add_argument("--resume", action="store_true", help="continue from OUT's checkpoint")
        p.add_argument("--workers", type=int_type(1, 256), default=None, help="local worker processes")
        p.add_argument("--json", action="store_true", help="machine-readable output")
        p.set_defaults(func=_cmd, study=name)
