"""Simulated DENALI datasets: labels, seeds, resumed builds identical to uninterrupted ones.

Every build uses ``fidelity="draft"`` and batches of two positions: JAX compiles
once per plan shape, and the builds below share their shapes.
"""

import time

import numpy as np
import pytest

from nlosplan.errors import UserError
from nlosplan.sensor_models import preset
from nlosplan.simulators import denali_scene
from nlosplan.simulators.fast.simulator import FastSimulator
from nlosplan.denali import positions_xy
from nlosplan.data.build import build_dataset, draw_captures, scene_seed
from nlosplan.data.store import CaptureStore

SENSOR = preset("tmf8828-3x3-short")
SMALL = dict(sensor=SENSOR, objects=["A", "circle", "7"], sizes=["4in", "8in"], positions=[0, 1, 2, 3], repeats=2,
             fidelity="draft", batch=2)


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    path = tmp_path_factory.mktemp("build") / "sim.sqlite"
    t0 = time.perf_counter()
    with CaptureStore(path, synchronous="NORMAL") as st:
        summary = build_dataset(st, **SMALL)
    return path, summary, time.perf_counter() - t0


def _by_key(path):
    with CaptureStore(path) as st:
        return {c.key: c.histogram for c in st.iter_captures()}


def test_small_build_is_quick_and_complete(built):
    path, s, seconds = built
    assert seconds < 60, f"3 objects x 2 sizes x 4 positions x 2 repeats took {seconds:.1f} s"
    assert (s["captures_total"], s["captures_added"], s["captures_skipped"]) == (48, 48, 0)
    assert s["groups"] == 6 and s["groups_skipped"] == 0 and s["zones"] == "3x3"
    with CaptureStore(path) as st:
        assert st.count() == 48 and st.count(object="circle", size="8in") == 8


def test_labels_match_the_denali_presets(built):
    path, s, _ = built
    with CaptureStore(path) as st:
        ds = st.load(lights="off")
    lab = ds.labels
    assert len(ds) == 48 and ds.bin_width_ps == SENSOR.bin_width_ps
    groups = {"A": "letters", "circle": "shapes", "7": "numbers"}
    assert all(lab.class_group == lab.object.map(groups))
    xy = positions_xy()
    assert np.array_equal(lab[["x", "y"]].to_numpy(), xy[lab.position.to_numpy()])
    assert set(lab.zones) == {"3x3"} and set(lab.source) == {"sim:fast"} and set(lab.repeat) == {0, 1}
    assert set(lab.seed) == {0} and set(lab.variant) == {s["variant"]}
    with CaptureStore(path) as st:
        cap = next(st.iter_captures(object="7", size="4in", position=2, repeat=1))
    assert cap.histogram.dtype == np.int64
    assert cap.meta["scene_seed"] == scene_seed(0, "7", "4in", 2, "off") and cap.meta["scene_meta"]["position"] == 2
    assert cap.meta["fidelity"] == "draft" and cap.meta["fidelity_knobs"]["object_samples"] == 64


def test_counts_are_poisson_draws_with_the_scene_seeds(built):
    path, _, _ = built
    scenes = [denali_scene("circle", "8in", p, "off") for p in (2, 3)]  # the build's batch of positions 2, 3
    mean = FastSimulator(scenes, SENSOR, fidelity="draft").expected()
    seeds = [scene_seed(0, "circle", "8in", p, "off") for p in (2, 3)]
    want = draw_captures(mean, seeds, 2, SENSOR)
    with CaptureStore(path) as st:
        got = st.load(object="circle", size="8in", position=[2, 3])
    order = np.lexsort((got.labels.repeat, got.labels.position))
    assert np.array_equal(got.histograms[order].reshape(want.shape), want.astype(np.float32))
    # noise is independent between repeats and scenes, and its size is Poisson's
    assert not np.array_equal(want[0, 0], want[0, 1]) and not np.array_equal(want[0], want[1])
    bright = mean > 1000
    z = (want[:, 0] - mean)[bright] / np.sqrt(mean[bright])
    assert 0.7 < z.std() < 1.3 and abs(z.mean()) < 0.2


def test_resumed_build_equals_uninterrupted_build(built, tmp_path):
    path, _, _ = built
    calls = []

    def stop_midway(done, total, text):
        calls.append((done, total, text))
        if len(calls) == 6:  # "starting", then 5 batches: in the middle of the third group (two batches each)
            raise KeyboardInterrupt

    resumed = tmp_path / "resumed.sqlite"
    with CaptureStore(resumed, synchronous="NORMAL") as st:
        with pytest.raises(KeyboardInterrupt):
            build_dataset(st, **SMALL, progress=stop_midway)
        assert st.count() == 20 and calls[-1][:2] == (20, 48)
        s = build_dataset(st, **SMALL)
        # the batches run position run after position run: no group was complete when it stopped
        assert (s["captures_added"], s["captures_skipped"], s["groups_skipped"]) == (28, 20, 0)
        again = build_dataset(st, **SMALL)
        assert (again["captures_added"], again["groups_skipped"]) == (0, 6)
    want, got = _by_key(path), _by_key(resumed)
    assert want.keys() == got.keys()
    assert all(np.array_equal(want[k], got[k]) for k in want)


def test_another_seed_gives_other_counts_beside_the_first(built, tmp_path):
    path, _, _ = built
    other = dict(SMALL, objects=["A"], sizes=["4in"], positions=[0, 1], seed=1)
    with CaptureStore(tmp_path / "s.sqlite") as st:
        s = build_dataset(st, **other)
        assert s["captures_added"] == 4
        seed1 = st.load().histograms
    with CaptureStore(path) as st:
        seed0 = st.load(object="A", size="4in", position=[0, 1]).histograms
    assert not np.array_equal(seed0, seed1)
    s0, s1 = float(seed0.sum()), float(seed1.sum())
    assert abs(s0 - s1) < 5 * np.sqrt(s0 + s1)  # same scenes, other Poisson noise


@pytest.mark.parametrize("kw, msg", [
    (dict(objects=["A", "mug"]), "objects.*'mug'.*allowed: 0, 1"),
    (dict(sizes=["6in"]), "sizes.*allowed: 4in, 8in"),
    (dict(lights=["dim"]), "lights.*allowed: on, off"),
    (dict(positions=[3, 100]), "position 100 is not allowed"),
    (dict(repeats=0), "repeats=0"),
    (dict(scene="corner"), "unknown scene 'corner'"),
    (dict(fidelity="ultra"), "unknown fidelity"),
    (dict(scene_options={"albedo": 2.0}), "albedo"),
])
def test_bad_arguments_are_one_line_errors(tmp_path, kw, msg):
    with CaptureStore(tmp_path / "s.sqlite") as st:
        with pytest.raises(UserError, match=msg) as e:
            build_dataset(st, **{**SMALL, **kw})
        assert "\n" not in str(e.value) and st.count() == 0
