"""``nlosplan rig status``: what each rig run in a store captured, what is left, and where it left the gantry."""

from __future__ import annotations

import argparse

from nlosplan.cli.common import emit

EXAMPLES = ("nlosplan rig status --store runs.db", "nlosplan rig status --store runs.db --run RUN_ID --json")

DESCRIPTION = """\
Per run in the store: captures stored against the plan, the first missing
steps, and where its last session left the gantry: parked at the origin
(where a Telemetrix gantry, or a GRBL gantry without homing, counts from
after the port reopens), or elsewhere -- then the next run asks to confirm
that the carriage stands at the origin (--origin-confirmed). Sessions are
read from <store>.gantry.json, beside the store."""


def _where(end: dict | None) -> str:
    if end is None:
        return "gantry: no session recorded"
    origin = end.get("origin_xy") or [0.0, 0.0]
    o = f"({origin[0]:g}, {origin[1]:g}) mm"
    if end.get("ended_utc") is None:
        return f"gantry: its last session (opened {end.get('opened_utc')}) did not end (killed?): position unknown"
    if end.get("at_origin"):
        return f"gantry: parked at the origin {o} when its last session ended ({end['ended_utc']})"
    if end.get("end_xy") is None:
        return f"gantry: position unknown when its last session ended ({end.get('end_note')})"
    xy = end["end_xy"]
    return (f"gantry: left at ({xy[0]:g}, {xy[1]:g}) mm, not at the origin {o}, when its last session ended "
            f"({end['ended_utc']}); a {end.get('kind')} gantry that does not count from its switches asks "
            "--origin-confirmed next time")


def _cmd_status(args) -> int:
    from nlosplan.data.store import CaptureStore
    from nlosplan.hardware.gantry_state import last_session, read_sessions
    from nlosplan.hardware.status import run_status

    with CaptureStore(args.store, readonly=True) as store:
        rows = run_status(store, args.run)
    sessions = read_sessions(args.store)
    lines = []
    for r in rows:
        end = last_session(sessions, run_id=r["run_id"])
        r["gantry_session"] = end
        r["parked_at_origin"] = None if end is None or end.get("ended_utc") is None else bool(end.get("at_origin"))
        planned = "?" if r["planned"] is None else r["planned"]
        left = "?" if r["left"] is None else r["left"]
        lines.append(f"{r['run_id']}: {r['captured']}/{planned} captured, {left} left ({r['plan']}; "
                     f"{r['object']}, lights {'/'.join(r['lights'])}, {r['source']}; last {r['last_utc']})")
        lines.append(f"  {_where(end)}")
        lines += [f"  missing step {m['step']}: ({m['x_mm']}, {m['y_mm']}) mm repeat {m['repeat']}"
                  for m in r["missing"]]
    emit(args, {"store": str(args.store), "runs": rows}, "\n".join(lines) or f"no rig runs in {args.store}")
    return 0


def add_rig(rsub) -> None:
    """Register ``nlosplan rig status``."""
    s = rsub.add_parser("status", help="what each rig run in a store has captured, what is left, where the gantry is",
                        description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter,
                        epilog="examples:\n" + "\n".join(f"  {e}" for e in EXAMPLES))
    s.add_argument("--store", required=True, help="capture store")
    s.add_argument("--run", default=None, help="one run id (default: every run)")
    s.add_argument("--json", action="store_true", help="machine-readable output")
    s.set_defaults(func=_cmd_status)
