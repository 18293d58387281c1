"""The floor of a capture session (issue 35): every capture of one object, size and lighting shares one floor draw."""

import json

import numpy as np
import pytest

from nlosplan.cli import main
from nlosplan.data.build import build_dataset, session_shift
from nlosplan.data.store import CaptureStore
from nlosplan.errors import UserError
from nlosplan.sensor_models import preset
from nlosplan.sensor_models.noise import floor_counts
from nlosplan.sensor_models.presets_denali import DENALI_NUISANCES_FIT, DENALI_SESSION_FLOOR_SD
from nlosplan.simulators.presets.scene_model import session_floor_sd

SENSOR = preset("tmf8828-3x3-short")
SMALL = dict(sensor=SENSOR, objects=["A", "7"], sizes=["8in"], positions=[0, 1], repeats=2, fidelity="draft",
             batch=2, lights=["on", "off"])


def test_the_session_shift_is_a_seeded_draw_of_the_given_spread():
    labels = [(o, s, l) for o in "ABCDEFGHIJKLMNOPQRSTUVWXYZ" for s in ("4in", "8in") for l in ("on", "off")]
    shifts = np.array([session_shift(0, *lab, 0.02) for lab in labels])
    assert 0.016 < shifts.std() < 0.024 and abs(shifts.mean()) < 0.005
    assert session_shift(0, "A", "8in", "on", 0.02) == session_shift(0, "A", "8in", "on", 0.02)
    assert session_shift(1, "A", "8in", "on", 0.02) != session_shift(0, "A", "8in", "on", 0.02)
    assert session_shift(0, "A", "8in", "on", 0.0) == 0.0


def test_denali_spread_is_the_rms_of_the_table2_background_offsets():
    on, off = DENALI_NUISANCES_FIT["background_offset_on"], DENALI_NUISANCES_FIT["background_offset_off"]
    assert DENALI_SESSION_FLOOR_SD == pytest.approx(((on ** 2 + off ** 2) / 2) ** 0.5, abs=1e-5)
    assert session_floor_sd("denali-tmf8828-3x3") == DENALI_SESSION_FLOOR_SD == pytest.approx(0.0173, abs=1e-4)
    assert session_floor_sd("") == 0.0
    with pytest.raises(UserError, match="unknown scene model"):
        session_floor_sd("nope")


@pytest.fixture(scope="module")
def pair(tmp_path_factory):
    """The same small build without and with a (large, to be seen through the noise) session floor spread."""
    path = tmp_path_factory.mktemp("sessions") / "s.sqlite"
    with CaptureStore(path, synchronous="NORMAL") as st:
        plain = build_dataset(st, **SMALL)
        varied = build_dataset(st, **SMALL, session_floor_sd=0.3)
        a = st.load(variant=plain["variant"])
        b = st.load(variant=varied["variant"])
    return plain, varied, a, b


def test_every_capture_of_a_session_has_its_floor_moved_by_one_draw(pair):
    plain, varied, a, b = pair
    assert plain["session_floor_sd"] == 0.0 and varied["session_floor_sd"] == 0.3
    assert plain["variant"] != varied["variant"] and varied["captures_added"] == plain["captures_added"] == 16
    key = ["object", "size", "lights", "position", "repeat"]
    ia = a.labels.sort_values(key).index.to_numpy()
    ib = b.labels.sort_values(key).index.to_numpy()
    la, lb = a.labels.loc[ia].reset_index(drop=True), b.labels.loc[ib].reset_index(drop=True)
    assert (la[key].to_numpy() == lb[key].to_numpy()).all()
    diff = b.histograms[ib].astype(float) - a.histograms[ia].astype(float)   # (16, 3, 3, 128)
    for (obj, size, light), rows in lb.groupby(["object", "size", "lights"]).groups.items():
        want = session_shift(0, obj, size, light, 0.3) * floor_counts(SENSOR, light == "on")
        got = diff[np.asarray(rows)].mean()        # 4 captures x 1,152 bins: the noise averages out
        floor = floor_counts(SENSOR, light == "on")
        noise = np.sqrt(2 * (floor + abs(want)) / (len(rows) * 9 * 128)) + 0.02 * floor
        assert abs(got - want) < 4 * noise + 1.0, (obj, light, got, want)


def test_bad_spreads_are_refused_before_any_work(tmp_path):
    with CaptureStore(tmp_path / "x.sqlite") as st:
        for bad in (-0.1, 0.6, float("nan"), True, "0.1"):
            with pytest.raises(UserError, match="session_floor_sd=.* must be a number from 0 to 0.5"):
                build_dataset(st, **SMALL, session_floor_sd=bad)
        assert st.count() == 0


@pytest.mark.parametrize("value, message", [("0.7", "out of range; allowed: up to 0.5"), ("-1", "must be >= 0"),
                                            ("nan", "not a finite number")])
def test_cli_refuses_a_bad_spread_in_one_line(tmp_path, capsys, value, message):
    store = tmp_path / "b.sqlite"
    assert main(["dataset", "build", "--positions", "0", "--repeats", "1", "--fidelity", "draft",
                 "--session-floor-sd", value, "--store", str(store)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--session-floor-sd" in err[0] and message in err[0]
    assert not store.exists()


def test_cli_default_is_the_scene_models_spread(tmp_path, capsys):
    args = ["dataset", "build", "--objects", "A", "--sizes", "8in", "--positions", "0", "--repeats", "1",
            "--fidelity", "draft", "--json"]
    assert main(args + ["--store", str(tmp_path / "d.sqlite")]) == 0
    assert json.loads(capsys.readouterr().out)["session_floor_sd"] == DENALI_SESSION_FLOOR_SD
    assert main(args + ["--sensor", "tmf8828-3x3-short", "--store", str(tmp_path / "s.sqlite")]) == 0
    assert json.loads(capsys.readouterr().out)["session_floor_sd"] == 0.0
    assert main(args + ["--session-floor-sd", "0", "--store", str(tmp_path / "z.sqlite")]) == 0
    assert json.loads(capsys.readouterr().out)["session_floor_sd"] == 0.0
