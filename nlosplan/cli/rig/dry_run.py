"""``nlosplan rig dry-run``: a plan's moves (and each motor's steps), limits and direct view, before anything moves."""

from __future__ import annotations

import argparse

from nlosplan.cli.common import emit
from nlosplan.errors import UserError

EXAMPLES = (
    "nlosplan rig dry-run --plan raster --repeats 3",
    "nlosplan rig dry-run --plan positions.csv --limits 0:320,0:320 --json",
    "nlosplan rig dry-run --gantry-kind telemetrix --plan raster --positions 0-1 --json   # steps per motor",
)

DESCRIPTION = """\
Walk a capture plan without hardware (no port is opened): every move, the
travel and the time; every target inside --limits; on the DENALI geometry no
position with the object in the LiDAR's direct view. With --gantry-kind
telemetrix each move also shows the step target of each motor (motor 0 = x on
the rig file's x pins, DENALI's 2/5; motor 1 = y), and limits or targets
beyond what Telemetrix4Arduino's 16-bit arithmetic represents (+-32,767 steps)
are refused. The raster follows DENALI's capture order: x is the slow axis,
y runs up and back, so position p is DENALI's capture p. A plan with a
problem exits 2 with the first one."""


def _controller(args):
    """``steps(x, y) -> {"x": ..., "y": ...}`` for a Telemetrix gantry (None for GRBL) and what describes it."""
    if args.gantry_kind != "telemetrix":
        if args.rig_file:
            raise UserError("--rig-file describes a Telemetrix gantry; add --gantry-kind telemetrix")
        return None, {"kind": "grbl"}
    from nlosplan.hardware.telemetrix_config import TelemetrixConfig, load_rig_file

    cfg = load_rig_file(args.rig_file) if args.rig_file else TelemetrixConfig()
    cfg.check_reach(args.limits)

    def steps(x: float, y: float) -> dict:
        sx, sy = cfg.checked_steps(x, y)
        return {"x": sx, "y": sy}

    motors = {name: {"motor": i, "step_pin": ax.step_pin, "dir_pin": ax.dir_pin, "steps_per_mm": ax.steps_per_mm,
                     "flip": ax.flip} for i, (name, ax) in enumerate(zip("xy", cfg.axes()))}
    return steps, {"kind": "telemetrix", "rig_file": cfg.source, "origin_mm": list(cfg.origin_mm), "motors": motors}


def _cmd_dry_run(args) -> int:
    from nlosplan.cli.rig.capture import _build_plan, _dry, _sensor_config

    steps, gantry = _controller(args)
    args.sensor_config = None if args.no_view_check else _sensor_config(args)
    factory, desc, spec, total = _build_plan(args)
    rep = _dry(args, factory, controller=steps)
    data = {"plan": desc, "gantry": gantry, **rep.to_dict()}
    lines = [f"plan: {desc}", f"{len(rep.moves)} moves, {rep.captures} captures, travel {rep.travel_mm:.0f} mm, "
             f"about {rep.seconds / 60:.1f} min at {args.feed:g} mm/min"]
    for i, (x, y, s) in enumerate(rep.moves[:20]):
        st = rep.steps[i] if rep.steps else None
        motors = "" if not st else f"; steps x {st['x']}, y {st['y']}"
        lines.append(f"  move {i + 1:3d}: ({x:7.2f}, {y:7.2f}) mm, settle {s:g} s{motors}")
    if len(rep.moves) > 20:
        lines.append(f"  ... {len(rep.moves) - 20} more moves")
    lines += [f"problem: {p}" for p in rep.problems] or ["checks: every target within the limits"
                                                         + ("" if steps is None else
                                                            " and Telemetrix4Arduino's 16-bit step range")
                                                         + ("" if args.no_view_check else
                                                            ", object never in the LiDAR's direct view")]
    emit(args, data, "\n".join(lines))
    if rep.problems:
        raise UserError(f"the plan has {len(rep.problems)} problem(s); first: {rep.problems[0]}")
    return 0


def add_rig(rsub) -> None:
    """Register ``nlosplan rig dry-run``."""
    from nlosplan.cli.rig.capture import _plan_options

    d = rsub.add_parser("dry-run", help="list a plan's moves (and motor steps), check limits and direct view before "
                                        "anything moves", description=DESCRIPTION,
                        formatter_class=argparse.RawDescriptionHelpFormatter,
                        epilog="examples:\n" + "\n".join(f"  {e}" for e in EXAMPLES))
    _plan_options(d)
    d.add_argument("--no-view-check", action="store_true", help="skip the direct-view check")
    d.add_argument("--gantry-kind", default="grbl", choices=["grbl", "telemetrix"],
                   help="the gantry the plan is for: with telemetrix each move lists its step targets per motor "
                        "and the firmware's 16-bit step range is checked (default: grbl)")
    d.add_argument("--rig-file", default=None, metavar="TOML",
                   help="Telemetrix rig file (pins, steps/mm, origin; default: DENALI's values)")
    d.set_defaults(func=_cmd_dry_run)
