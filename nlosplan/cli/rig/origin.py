"""Before a rig session moves: is the carriage where the gantry's counters start? (``--origin-confirmed``)."""

from __future__ import annotations

import sys
from contextlib import contextmanager

from nlosplan.errors import UserError

ORIGIN_HELP = ("the carriage stands at the gantry's origin now (its power-up position: origin_mm of a Telemetrix "
               "rig file, machine zero of a GRBL gantry without homing); needed when the store's last session did "
               "not end there, or a run resumes without a record (on a terminal you are asked instead)")


def _resuming(store, run_id: str) -> bool:
    if not store.count():
        return False
    return any(str(c).startswith(f"{run_id}/") for c in store.labels()["capture_id"])


def _ask(problem: str, origin, out=sys.stderr, answer=input) -> bool:
    print(f"{problem}.\nPositions count from where the carriage stands now. Is it at the origin "
          f"({origin[0]:g}, {origin[1]:g}) mm? [y/N] ", end="", file=out, flush=True)
    try:
        return answer().strip().lower() in ("y", "yes")
    except EOFError:
        return False


@contextmanager
def origin_session(args, rig, store, run_id: str):
    """Check the origin before anything moves, record the session, and record where it ended (after finalize).

    On a gantry whose counters restart where the carriage stands when the port opens (Telemetrix; GRBL not
    homed in this session and reset by the open), a problem (:func:`nlosplan.hardware.gantry_state.origin_problem`)
    needs ``--origin-confirmed``, or a ``y`` on a terminal; else one line, exit 2, nothing moved.
    """
    from nlosplan.hardware import gantry_state as gs

    gantry = rig.gantry
    emulated = "gantry" in rig.emulated
    sessions = gs.read_sessions(store.path)
    problem = gs.origin_problem(sessions, gantry=gantry, emulated=emulated, resuming=_resuming(store, run_id))
    confirmed = False
    if problem is not None:
        origin = gantry.origin_xy()
        if getattr(args, "origin_confirmed", False):
            confirmed = True
        elif sys.stdin.isatty() and not getattr(args, "json", False) and _ask(problem, origin):
            confirmed = True
        else:
            home = (" (or re-home it: --home)" if gantry.kind == "grbl"
                    and int(getattr(gantry, "settings", {}).get(22, 0)) else "")
            raise UserError(f"{problem}; this {gantry.kind} gantry counts from wherever the carriage stands when "
                            f"the port opens: move the carriage to the origin ({origin[0]:g}, {origin[1]:g}) mm and "
                            f"rerun with --origin-confirmed{home}; nothing moved")
    record = gs.begin_session(store.path, run_id=run_id, gantry=gantry, emulated=emulated,
                              origin_confirmed=confirmed)
    try:
        yield record
    finally:
        gs.end_session(store.path, record, gantry)
