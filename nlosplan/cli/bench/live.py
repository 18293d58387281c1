"""``nlosplan bench live``: what ``--live`` costs a run (an emulated rig capture with and without the page)."""

from __future__ import annotations

import argparse

from nlosplan.cli.common import emit, int_type

EXAMPLE = "nlosplan bench live --rounds 3 --pages 2 --json"


def _text(res: dict) -> str:
    from nlosplan.reports.tables import format_table

    rows = [{"round": k + 1, "first": r["first"], "plain s": round(r["plain_s"], 2), "live s": round(r["live_s"], 2),
             "live / plain": round(r["ratio"], 3), "pages": r["pages"]} for k, r in enumerate(res["rounds"])]
    return (f"emulated rig capture, positions {res['positions']} x {res['repeats']} repeats ({res['captures']} "
            f"captures), executor seconds without and with --live ({res['pages']} page(s) open):\n"
            + format_table(rows, ["round", "first", "plain s", "live s", "live / plain", "pages"])
            + f"\nmedian live / plain: {res['median_ratio']:.3f} (load {res['load_1min'][0]:.1f} -> "
              f"{res['load_1min'][1]:.1f} on {res['cpus']} CPUs; other jobs on the machine count too)")


def _cmd(args) -> int:
    import tempfile

    from nlosplan.reports.live.bench import bench_live

    with tempfile.TemporaryDirectory(prefix="nlosplan-bench-live-") as tmp:
        res = bench_live(tmp, rounds=args.rounds, positions=args.positions, repeats=args.repeats, pages=args.pages)
    emit(args, res, _text(res))
    return 0


def add_bench(bsub) -> None:
    """``nlosplan bench live``."""
    p = bsub.add_parser("live", help="the live page's cost to a run: emulated rig capture with and without --live",
                        description="Runs the same short emulated 'rig capture' without and with --live (and "
                                    "sessions open on its page, each pushed every change), in alternating order, "
                                    "and prints the executor's run time of each and their ratio per round.",
                        epilog=f"example:\n  {EXAMPLE}", formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--rounds", type=int_type(1, 20), default=3, help="rounds of (plain, live) runs (default: 3)")
    p.add_argument("--positions", default="0-9", help="raster grid indices of each capture (default: 0-9)")
    p.add_argument("--repeats", type=int_type(1, 20), default=3, help="captures per position (default: 3)")
    p.add_argument("--pages", type=int_type(0, 10), default=1, help="sessions open on the live page (default: 1)")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(func=_cmd)
