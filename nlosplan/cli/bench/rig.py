"""``nlosplan bench rig``: host time per frame (parse + store) and parser throughput against the line rate."""

from __future__ import annotations

import argparse

from nlosplan.cli.common import emit, int_type, number_type

EXAMPLE = "nlosplan bench rig --json"


def _text(res: dict) -> str:
    from nlosplan.reports.tables import format_table

    rows = [{**r, **{k: round(v, 3) for k, v in r.items() if isinstance(v, float)}} for r in res["per_frame"]]
    lines = ["host time per frame (parse + store, one SQLite transaction each):",
             format_table(rows, ["zones", "frames", "synchronous", "parse_ms_median", "store_ms_median",
                                 "total_ms_median", "total_ms_p95", "line_time_ms"]),
             "", "parser throughput (2 Mbaud = 200,000 bytes/s at 8N1):"]
    prow = [{"zones": p["zones"], "MB/s": round(p["bytes_per_second"] / 1e6, 2),
             "frames/s": round(p["frames_per_second"], 1), "x line rate": round(p["times_line_rate"], 1)}
            for p in res["parser"]]
    if "end_to_end" in res:
        e = res["end_to_end"]
        prow.append({"zones": "3x3 driver over pty", "MB/s": round(e["bytes_per_second"] / 1e6, 2),
                     "frames/s": round(e["frames_per_second"], 1), "x line rate": round(e["times_line_rate"], 1)})
    lines.append(format_table(prow, ["zones", "MB/s", "frames/s", "x line rate"]))
    t = res["targets"]
    lines.append(f"\ntargets: <= 5 ms per 3x3 frame: {'met' if t['met_3x3'] else 'NOT met'}; "
                 f"parser >= 10x line rate: {'met' if t['met_parser'] else 'NOT met'} "
                 f"(load {res['host']['load_1min']:.1f} on {res['host']['cpus']} CPUs)")
    return "\n".join(lines)


def _cmd(args) -> int:
    from nlosplan.hardware.bench import bench_rig

    res = bench_rig(frames_3x3=args.frames, frames_8x8=max(args.frames // 5, 5), seconds=args.seconds,
                    synchronous=args.synchronous, end_to_end=not args.no_pty)
    emit(args, res, _text(res))
    return 0


def add_bench(bsub) -> None:
    """``nlosplan bench rig``."""
    p = bsub.add_parser("rig", help="rig host cost: ms per 3x3/8x8 frame (parse + store), parser vs 2 Mbaud",
                        description="Host time per TMF8828 frame (assembling its firmware lines, then storing it "
                                    "in one CaptureStore transaction) for 3x3 and 8x8, and the parser's "
                                    "throughput as a multiple of the 2 Mbaud line rate (also through the driver "
                                    "over a pty from the emulated sensor). Targets: <= 5 ms per 3x3 frame, "
                                    "parser >= 10x the line rate.",
                        epilog=f"example:\n  {EXAMPLE}", formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--frames", type=int_type(10, 100000), default=300, help="3x3 frames timed (8x8: a fifth)")
    p.add_argument("--seconds", type=number_type(float), default=1.0, help="timed seconds per throughput figure")
    p.add_argument("--synchronous", default="FULL", choices=["FULL", "NORMAL"],
                   help="store durability (the rig uses FULL, an fsync per capture)")
    p.add_argument("--no-pty", action="store_true", help="skip the driver-over-pty figure")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(func=_cmd)
