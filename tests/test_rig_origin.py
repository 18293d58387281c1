"""The origin check: which sessions leave the next one unsure where the carriage is, and the operator's answer."""

import io
import json
from types import SimpleNamespace

import pytest

from nlosplan.cli.rig.origin import _ask
from nlosplan.errors import UserError
from nlosplan.hardware import gantry_state as gs
from nlosplan.hardware.gantry import GantryPosition
from nlosplan.hardware.rig import park_target


class Gantry(SimpleNamespace):
    """A stand-in driver: kind, port, referenced, origin, limits and a reported position."""

    def origin_xy(self):
        return self.origin

    def where(self):
        if self.at is None:
            raise OSError("serial link lost")
        return GantryPosition(self.at, {}, self.state)


def _gantry(**kw):
    base = dict(kind="telemetrix", port_name="/dev/ttyACM1", referenced=False, origin=(0.0, 0.0), at=(0.0, 0.0),
                state="Idle", limits_mm=((0.0, 320.0), (0.0, 320.0)))
    return Gantry(**{**base, **kw})


def test_sessions_decide_whether_the_origin_is_known(tmp_path):
    store = tmp_path / "runs.db"
    g = _gantry()
    assert gs.read_sessions(store) == []
    assert gs.origin_problem([], gantry=g, emulated=False, resuming=False) is None        # first session: as documented
    assert "this run resumes, and no session on this store recorded" in gs.origin_problem(
        [], gantry=g, emulated=False, resuming=True)
    rec = gs.begin_session(store, run_id="r1", gantry=g, emulated=False)
    problem = gs.origin_problem(gs.read_sessions(store), gantry=g, emulated=False, resuming=False)
    assert problem.startswith("the last session on this store (run r1, opened ") and "did not end (killed?)" in problem
    assert gs.origin_problem(gs.read_sessions(store), gantry=g, emulated=True, resuming=False) is None  # other rig
    g.at = (35.5551, 0.0)
    end = gs.end_session(store, rec, g)
    assert (end["at_origin"], end["end_xy"]) == (False, [35.5551, 0.0])
    assert gs.origin_problem(gs.read_sessions(store), gantry=g, emulated=False, resuming=False).endswith(
        "left the carriage at (35.5551, 0) mm, not at the origin (0, 0) mm")
    assert gs.origin_problem(gs.read_sessions(store), gantry=_gantry(referenced=True), emulated=False,
                             resuming=True) is None                                     # homed: counts from switches
    g.at = (0.0, 0.004)
    gs.end_session(store, gs.begin_session(store, run_id="r2", gantry=g, emulated=False), g)
    assert gs.origin_problem(gs.read_sessions(store), gantry=g, emulated=False, resuming=True) is None
    g.at = None                                                                         # the link died at the end
    gs.end_session(store, gs.begin_session(store, run_id="r3", gantry=g, emulated=False), g)
    assert "ended with the carriage's position unknown (position unknown at the end (serial link lost))" in \
        gs.origin_problem(gs.read_sessions(store), gantry=g, emulated=False, resuming=False)
    g.at, g.state = (0.0, 0.0), "Run"                                                    # GRBL still moving there
    assert gs.end_session(store, gs.begin_session(store, run_id="r4", gantry=g, emulated=False), g)["at_origin"] is False
    assert [s["run_id"] for s in gs.read_sessions(store)] == ["r1", "r2", "r3", "r4"]
    assert gs.last_session(gs.read_sessions(store), run_id="r2")["end_xy"] == [0.0, 0.004]


def test_a_broken_session_file_is_one_line(tmp_path):
    store = tmp_path / "runs.db"
    gs.state_path(store).write_text("{not json")
    with pytest.raises(UserError, match=r"gantry session file .*runs.db.gantry.json cannot be read .*; move it away"):
        gs.read_sessions(store)
    gs.state_path(store).write_text(json.dumps({"sessions": [1, 2]}))
    with pytest.raises(UserError, match="'sessions' is not a list of objects"):
        gs.read_sessions(store)


def test_the_operator_answers_on_a_terminal():
    out = io.StringIO()
    assert _ask("the last session left the carriage at (1, 2) mm", (0.0, 0.0), out=out, answer=lambda: "y")
    assert "Is it at the origin (0, 0) mm? [y/N]" in out.getvalue()
    assert not _ask("x", (0.0, 0.0), out=io.StringIO(), answer=lambda: "")
    assert not _ask("x", (0.0, 0.0), out=io.StringIO(), answer=lambda: (_ for _ in ()).throw(EOFError()))


def test_a_gantry_that_counts_from_the_open_parks_at_its_origin():
    assert park_target(_gantry(origin=(10.0, 5.0)), (0.0, 0.0)) == (10.0, 5.0)
    assert park_target(_gantry(origin=(400.0, 5.0)), (0.0, 0.0)) == (0.0, 0.0)     # outside the limits: the minimum
    assert park_target(_gantry(referenced=True, origin=(10.0, 5.0)), (0.0, 0.0)) == (0.0, 0.0)
    assert park_target(_gantry(), None) is None                                    # --no-park


def test_grbl_counts_from_the_open_unless_it_kept_running_or_homed():
    from nlosplan.hardware.emulators import EmulatedGrbl
    from nlosplan.hardware.grbl import Grbl

    with EmulatedGrbl(time_scale=100.0) as emu:                      # an Arduino: the open resets it (banner)
        g = Grbl(emu.port)
        g.prepare()
        assert (g.connected_by, g.referenced, g.origin_xy()) == ("banner", False, (0.0, 0.0))
        g.close()
    with EmulatedGrbl(time_scale=100.0, reset_on_open=False) as emu:  # kept running: it counts as before
        g = Grbl(emu.port)
        g.prepare()
        assert (g.connected_by, g.referenced) == ("status", True)
        g.close()
    with EmulatedGrbl(time_scale=500.0, settings={22: 1, 130: 320, 131: 320}, switches="XYZ") as emu:
        g = Grbl(emu.port)
        g.prepare(home=True)                                          # homed: referenced to its switches
        assert g.referenced and g.origin_xy() == (320.0, 320.0)      # machine zero is the homing corner
        g.close()
