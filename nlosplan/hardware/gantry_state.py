"""Where each rig session left the gantry, kept beside the capture store, and whether the next may trust its origin.

A Telemetrix gantry (and a GRBL gantry without homing) counts its position
from wherever the carriage stood when the port opened: opening the port
resets the board and its step counters. A session that ends without parking
at that origin (a ``--no-park`` run, a failure, a kill) leaves the carriage
elsewhere, and the next session would count from there: every position
shifted, every label wrong, silently.

So each session is recorded in ``<store>.gantry.json`` (written atomically):
when it opened, on which gantry, and at its end where the gantry reported
itself and whether that is the origin. :func:`origin_problem` says what is
wrong before a session on a gantry whose counters restart (not
``referenced``) may move: the store's last session on this kind of gantry
did not end at the origin, or did not end at all; or this run resumes and no
session was recorded. The CLI then asks the operator to confirm the
carriage stands at the origin (or, on GRBL with homing, to re-home).
"""

from __future__ import annotations

import json
import math
from datetime import datetime, timezone
from pathlib import Path

from nlosplan.errors import UserError
from nlosplan.files import write_json

__all__ = ["STATE_SUFFIX", "begin_session", "end_session", "last_session", "origin_problem", "read_sessions",
           "state_path"]

STATE_SUFFIX = ".gantry.json"
_KEEP = 200          # sessions kept in the file
_AT_ORIGIN_MM = 0.01


def _utc() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="seconds")


def state_path(store_path) -> Path:
    """The session file of a capture store: ``<store>.gantry.json``."""
    return Path(str(store_path) + STATE_SUFFIX)


def read_sessions(store_path) -> list[dict]:
    """The recorded sessions of a store, oldest first (empty when none were recorded).

    Raises
    ------
    UserError
        The file exists but is not a session file (one line: what to do).
    """
    path = state_path(store_path)
    if not path.exists():
        return []
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
        sessions = data["sessions"]
        if not isinstance(sessions, list) or not all(isinstance(s, dict) for s in sessions):
            raise ValueError("'sessions' is not a list of objects")
    except (OSError, UnicodeDecodeError, ValueError, KeyError, TypeError) as exc:
        raise UserError(f"gantry session file {path} cannot be read ({exc}); move it away (the next run then asks "
                        "to confirm that the carriage stands at the origin)") from None
    return sessions


def _write(store_path, sessions: list[dict]) -> None:
    write_json(state_path(store_path), {"about": "nlosplan rig sessions: where each left the gantry",
                                        "sessions": sessions[-_KEEP:]}, indent=1)


def _xy(v) -> list | None:
    return None if v is None else [round(float(v[0]), 4), round(float(v[1]), 4)]


def begin_session(store_path, *, run_id: str, gantry, emulated: bool, origin_confirmed: bool = False) -> dict:
    """Record a session that opened (not ended yet: a kill leaves it so); returns the record."""
    record = {"run_id": run_id, "opened_utc": _utc(), "ended_utc": None, "kind": gantry.kind,
              "port": str(gantry.port_name), "emulated": bool(emulated), "referenced": bool(gantry.referenced),
              "origin_xy": _xy(gantry.origin_xy()), "origin_confirmed": bool(origin_confirmed),
              "end_xy": None, "at_origin": None, "end_note": "session did not end (killed, or still running)"}
    sessions = read_sessions(store_path)
    sessions.append(record)
    _write(store_path, sessions)
    return record


def end_session(store_path, record: dict, gantry) -> dict:
    """Record where the gantry reports itself now (after the run's finalize) and whether that is the origin."""
    out = dict(record, ended_utc=_utc())
    try:
        pos = gantry.where()
        xy = tuple(pos.xy_mm)
        idle = getattr(pos, "state", "Idle") == "Idle"
        ox, oy = gantry.origin_xy()
        at = idle and math.hypot(xy[0] - ox, xy[1] - oy) <= _AT_ORIGIN_MM
        out.update(end_xy=_xy(xy), at_origin=bool(at),
                   end_note=("at the origin" if at else f"{'moving' if not idle else 'stopped'} away from the origin"))
    except Exception as exc:  # noqa: BLE001 - the link may be gone: then where it is is unknown
        out.update(end_xy=None, at_origin=None, end_note=f"position unknown at the end ({exc})")
    sessions = read_sessions(store_path)
    for i in range(len(sessions) - 1, -1, -1):
        if sessions[i].get("opened_utc") == record["opened_utc"] and sessions[i].get("run_id") == record["run_id"]:
            sessions[i] = out
            break
    else:
        sessions.append(out)
    _write(store_path, sessions)
    return out


def last_session(sessions: list[dict], *, run_id: str | None = None, kind: str | None = None,
                 emulated: bool | None = None) -> dict | None:
    """The newest recorded session matching the given run id, gantry kind and emulated flag."""
    for s in reversed(sessions):
        if ((run_id is None or s.get("run_id") == run_id) and (kind is None or s.get("kind") == kind)
                and (emulated is None or bool(s.get("emulated")) == emulated)):
            return s
    return None


def _mm(xy) -> str:
    return f"({xy[0]:g}, {xy[1]:g}) mm"


def origin_problem(sessions: list[dict], *, gantry, emulated: bool, resuming: bool) -> str | None:
    """Why this session cannot trust that the carriage stands at the origin, or None.

    Parameters
    ----------
    sessions : list of dict
        :func:`read_sessions` of the store.
    gantry : GantryDriver
        The opened gantry (``kind``, ``referenced``, ``origin_xy()``).
    emulated : bool
        Whether the gantry is an emulator (its sessions are told apart from a real gantry's).
    resuming : bool
        The run already has captures in the store.

    Returns
    -------
    str or None
        One clause naming the last session and where it left the carriage; None when the gantry is
        referenced (homed, or a controller that kept counting), or the store's last session on this kind
        of gantry ended at the origin, or nothing is known and the run is new.
    """
    if gantry.referenced:
        return None
    last = last_session(sessions, kind=gantry.kind, emulated=emulated)
    origin = _mm(gantry.origin_xy())
    if last is None:
        if not resuming:
            return None
        return f"this run resumes, and no session on this store recorded where it left the {gantry.kind} gantry"
    run = f"the last session on this store (run {last.get('run_id')}, opened {last.get('opened_utc')})"
    if last.get("ended_utc") is None:
        return f"{run} did not end (killed?): where it left the carriage is unknown"
    if last.get("at_origin"):
        return None
    if last.get("end_xy") is None:
        return f"{run} ended with the carriage's position unknown ({last.get('end_note')})"
    return f"{run} left the carriage at {_mm(last['end_xy'])}, not at the origin {origin}"
