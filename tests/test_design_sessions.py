"""The design's simulated captures come in capture sessions: each object, size and lighting has its own floor."""

import numpy as np
import pandas as pd
import pytest

from nlosplan.data.build import session_shift
from nlosplan.errors import UserError
from nlosplan.planner.design.data import ReferenceData, SceneSet, load_reference
from nlosplan.sensor_models import resolve_sensor
from nlosplan.sensor_models.noise import floor_counts

SD = 0.01732   # DENALI_SESSION_FLOOR_SD


def reference(sd=SD, lights="off"):
    """Two objects x two sizes x three positions of a flat floor on DENALI's unit, 3x3 zones x 128 bins."""
    sensor = resolve_sensor("denali-tmf8828-3x3")
    rows = [(o, s, p) for o in ("A", "S") for s in ("4in", "8in") for p in (0, 1, 2)]
    labels = pd.DataFrame({"object": [r[0] for r in rows], "size": [r[1] for r in rows],
                           "position": [r[2] for r in rows], "lights": lights})
    floor = floor_counts(sensor, lights == "on")
    means = np.full((len(rows), 3, 3, sensor.n_bins), floor, np.float32)
    return ReferenceData(sensor, labels, means=means, session_floor_sd=sd), floor


def test_every_position_of_a_session_shares_its_floor_and_sessions_differ():
    ref, floor = reference()
    off = ref.session_offsets(seed=4)
    assert off.shape == (12,)
    sessions = off.reshape(4, 3)   # (object, size) x positions
    assert np.all(sessions == sessions[:, :1])
    assert len(set(sessions[:, 0])) == 4
    # the dataset build's draw, in counts of the reference sensor's floor
    assert off[0] == pytest.approx(session_shift(4, "A", "4in", "off", SD) * floor)
    assert off[3] == pytest.approx(session_shift(4, "A", "8in", "off", SD) * floor)
    # a 1.73 % spread of a ~1,200-count floor: tens of counts, not thousands
    assert 0 < np.abs(off).max() < 0.1 * floor
    # another seed meets other sessions; no spread, no offsets
    assert not np.allclose(ref.session_offsets(seed=5), off)
    assert np.array_equal(reference(sd=0.0)[0].session_offsets(seed=4), np.zeros(12))


def test_noisy_design_captures_carry_their_session_floor():
    ref, floor = reference()
    deg, why = ref.degradation(ref.sensor)
    assert deg is not None, why
    with_sessions = ref.design_mean_capture(deg, 1, 3, session_seed=4)
    plain = ref.design_mean_capture(deg, 1, 3)   # no session seed: one floor for every session
    off = ref.session_offsets(seed=4)
    # averaged over a capture's 1,152 bins the Poisson noise is about 1 count: the session's shift stands out
    assert np.allclose(with_sessions.mean(axis=(1, 2, 3)), floor + off, atol=4.0)
    assert np.allclose(plain.mean(axis=(1, 2, 3)), floor, atol=4.0)
    # rows drawn again keep their own session's floor
    again = ref.design_mean_capture(deg, 2, 3, rows=[3, 3, 0], session_seed=4)
    assert np.allclose(again.mean(axis=(1, 2, 3)), floor + off[[3, 3, 0]], atol=4.0)
    # a design with a tenth of the photons sees a tenth of the shift (the floor is thinned with the signal)
    tenth = ref.degradation(ref.sensor.replace(iterations=ref.sensor.iterations // 10))[0]
    if tenth is not None and tenth.photon_fraction < 1:
        low = ref.design_mean_capture(tenth, 1, 3, session_seed=4)
        assert np.allclose(low.mean(axis=(1, 2, 3)), (floor + off) * tenth.photon_fraction, atol=2.0)


def test_the_observer_s_expected_counts_carry_the_same_sessions():
    """The ideal observer's templates are the means the learners' captures are drawn from: sessions included."""
    ref, floor = reference()
    deg, _ = ref.degradation(ref.sensor)
    off = ref.session_offsets(seed=4)
    means = ref.design_means(deg, session_seed=4)
    np.testing.assert_allclose(means.mean(axis=(1, 2, 3)), floor + off, rtol=1e-6)
    np.testing.assert_allclose(ref.design_means(deg).mean(axis=(1, 2, 3)), floor, rtol=1e-6)
    # the noisy captures scatter around exactly these means
    many = np.mean([ref.design_mean_capture(deg, r, 1, session_seed=4) for r in range(20)], axis=0)
    assert np.abs(many.mean(axis=(1, 2, 3)) - means.mean(axis=(1, 2, 3))).max() < 1.0


def test_a_session_aware_observer_tells_sessions_apart_where_a_plain_one_cannot():
    """Identical objects in different sessions: only their floors differ; the observer with sessions reads them."""
    from nlosplan.planner.design.evaluators import _observer

    ref, _ = reference()
    deg, _ = ref.degradation(ref.sensor)
    fid = {"draws": 400, "looks": 1}
    with_sessions = _observer(ref, deg, "shape", fid, 4, None)[0]
    plain = _observer(reference(sd=0.0)[0], deg, "shape", fid, 4, None)[0]
    assert plain == pytest.approx(0.5, abs=0.08)       # two identical classes: chance
    assert with_sessions > 0.9                          # a floor tens of counts apart over 1,152 bins


def test_a_reference_file_keeps_its_session_spread(tmp_path):
    ref, _ = reference(sd=0.02)
    loaded = load_reference(ref.save(tmp_path / "ref.npz"))
    assert loaded.session_floor_sd == 0.02
    assert np.array_equal(loaded.session_offsets(seed=9), ref.session_offsets(seed=9))


def test_scene_set_takes_the_model_spread_and_keys_it():
    model = SceneSet(objects=("A",), model="denali-tmf8828-3x3")
    assert model.session_sd() == pytest.approx(SD)
    assert SceneSet(objects=("A",)).session_sd() == 0.0
    ablated = SceneSet(objects=("A",), model="denali-tmf8828-3x3", session_floor_sd=0)
    assert ablated.session_sd() == 0.0
    sensor = resolve_sensor("denali-tmf8828-3x3")
    assert model.key(sensor) != ablated.key(sensor)
    # without a spread the key is the one a scene set had before sessions existed
    assert "session_floor_sd" not in SceneSet(objects=("A",)).to_dict()
    for s in (model, ablated, SceneSet(objects=("A",), session_floor_sd=0.05)):
        back = SceneSet.from_dict(s.to_dict())
        assert back.session_sd() == s.session_sd() and back.key(sensor) == s.key(sensor)


@pytest.mark.parametrize("bad", [-0.01, 0.9, "x", True])
def test_a_bad_session_spread_is_refused(bad):
    with pytest.raises(UserError, match="session_floor_sd=.* must be a number from 0 to 0.5"):
        SceneSet(objects=("A",), session_floor_sd=bad)


def test_a_design_file_sets_or_refuses_the_session_spread(tmp_path):
    from nlosplan.planner.design.config import load_config, quick_config

    base = quick_config()
    assert base.scenes.session_floor_sd is None   # the scene model's, resolved per run
    good = tmp_path / "ablate.toml"
    good.write_text("[scenes]\nsession_floor_sd = 0\n")
    assert load_config(good, base).scenes.session_sd() == 0.0
    bad = tmp_path / "bad.toml"
    bad.write_text("[scenes]\nsession_floor_sd = 2\n")
    with pytest.raises(UserError, match=r"\[scenes\]: session_floor_sd = 2 must be a number"):
        load_config(bad, base)


def test_the_result_names_the_session_spread_of_its_world():
    from dataclasses import replace

    from nlosplan.planner.design.config import quick_config
    from nlosplan.planner.design.run import _world_model
    from nlosplan.simulators.presets.scene_model import describe_scene_options

    cfg = quick_config()
    model = _world_model(cfg, describe_scene_options)
    assert model["session_floor_sd"] == pytest.approx(SD)
    assert model["scene"].endswith("; capture sessions' floor spread 1.73 %")
    ablated = _world_model(replace(cfg, scenes=replace(cfg.scenes, session_floor_sd=0.0)), describe_scene_options)
    assert ablated["session_floor_sd"] == 0.0
    assert ablated["scene"].endswith("; one floor for every capture session")
