"""The dataset build's shared simulations equal the one-group-at-a-time build of before.

The build simulates every object and lighting of a run of positions together (the mount once per position, an
object once for both lightings, one compiled program padded across batches); each group simulated alone (the
build before issue 38) must give the same expected counts within float32 rounding and the same stored captures.
"""

import numpy as np
import pytest

from nlosplan.data.build import build_dataset, draw_captures, scene_seed
from nlosplan.data.store import CaptureStore
from nlosplan.sensor_models import resolve_sensor
from nlosplan.simulators import denali_scene, expected_batch
from nlosplan.simulators.fast.plan import build_plan, pad_plan
from nlosplan.simulators.fast.simulator import FastSimulator
from nlosplan.simulators.presets.scene_model import DEFAULT_SENSOR, scene_model, scene_options

SENSOR = resolve_sensor(DEFAULT_SENSOR)  # the default world: mixed reflectance and the mount in the signal
pytestmark = pytest.mark.slow  # the default world's plans compile for 1-5 min on a loaded 2-core machine

OPTIONS = scene_options(scene_model(DEFAULT_SENSOR))
ARGS = dict(sensor=SENSOR, objects=["A", "S"], sizes=["4in", "8in"], positions=[5, 6, 40, 41], lights=["off", "on"],
            repeats=2, fidelity="draft", batch=2, scene_options=OPTIONS)


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    path = tmp_path_factory.mktemp("shared") / "sim.sqlite"
    with CaptureStore(path, synchronous="NORMAL") as st:
        summary = build_dataset(st, **ARGS)
    return path, summary


def test_shared_build_equals_one_group_at_a_time(built):
    path, summary = built
    assert summary["captures_added"] == 2 * 2 * 4 * 2 * 2 and summary["simulations"] == 2
    assert summary["scenes_simulated"] == 32 and summary["scenes_per_second"] > 0
    with CaptureStore(path) as st:
        stored = {(c.labels["object"], c.labels["size"], c.labels["lights"], c.labels["position"], c.labels["repeat"]):
                  c.histogram for c in st.iter_captures()}
    both = expected_batch([denali_scene(o, s, p, light, **OPTIONS) for o in ("A", "S") for s in ("4in", "8in")
                           for light in ("off", "on") for p in (40, 41)], SENSOR, fidelity="draft").expected
    for n, (obj, size, light) in enumerate((o, s, li) for o in ("A", "S") for s in ("4in", "8in") for li in ("off", "on")):
        for chunk in ([5, 6], [40, 41]):  # the build's batches of positions; before: one simulation per group
            mean = expected_batch([denali_scene(obj, size, p, light, **OPTIONS) for p in chunk], SENSOR,
                                  fidelity="draft").expected
            if chunk == [40, 41]:
                shared = both[2 * n: 2 * n + 2]
                assert np.allclose(shared, mean, rtol=1e-5, atol=1e-5 * mean.max())
            want = draw_captures(mean, [scene_seed(0, obj, size, p, light) for p in chunk], 2, SENSOR)
            for i, p in enumerate(chunk):
                for r in range(2):
                    assert np.array_equal(stored[(obj, size, light, p, r)], want[i, r]), (obj, size, light, p, r)


def test_resumed_shared_build_adds_only_what_is_missing(built, tmp_path):
    path, _ = built
    calls = []

    def stop(done, total, text):
        calls.append(done)
        if len(calls) == 4:  # "starting", then three groups of the first simulation
            raise KeyboardInterrupt

    resumed = tmp_path / "resumed.sqlite"
    with CaptureStore(resumed, synchronous="NORMAL") as st:
        with pytest.raises(KeyboardInterrupt):
            build_dataset(st, **ARGS, progress=stop)
        assert st.count() == 12
        s = build_dataset(st, **ARGS)
        assert (s["captures_added"], s["captures_skipped"]) == (52, 12)
        assert build_dataset(st, **ARGS)["simulations"] == 0
    with CaptureStore(path) as a, CaptureStore(resumed) as b:
        want = {c.key: c.histogram for c in a.iter_captures()}
        got = {c.key: c.histogram for c in b.iter_captures()}
    assert want.keys() == got.keys() and all(np.array_equal(want[k], got[k]) for k in want)


def test_padded_plans_share_one_structure_and_give_the_same_counts():
    scenes = {o: [denali_scene(o, "8in", p, "off", **OPTIONS) for p in (5, 60)] for o in ("A", "S")}
    a, s = (build_plan(scenes[o], SENSOR, "draft") for o in ("A", "S"))
    assert a.static != s.static  # the sizes of their object terms differ
    both = pad_plan(s, pad_plan(a, s))
    assert both.static == pad_plan(a, s).static  # after padding, one compiled program serves both
    plain = FastSimulator(scenes["A"], SENSOR, fidelity="draft").expected()
    padded = FastSimulator(scenes["A"], SENSOR, fidelity="draft", pad_to=s).expected()
    assert np.allclose(padded, plain, rtol=1e-5, atol=1e-5 * plain.max())
    assert pad_plan(a, None) is a


def test_mount_is_shared_across_objects_at_a_position():
    scenes = [denali_scene(o, "8in", p, "off", **OPTIONS) for o in ("A", "S", "O") for p in (5, 6)]
    sim = FastSimulator(scenes, SENSOR, fidelity="draft")
    classes = sim.shared_classes()
    assert len(classes) == 1  # the mount and its plate: 2 distinct poses among 6 scenes; objects are not repeated
    terms, first, group = classes[0]
    # scene objects 1 and 2 (object 0 is the letter: a retroreflective term and its diffuse base)
    assert [sim.plan.object_index[k] for k in terms] == [1, 2] and len(first) == 2
    assert group.tolist() == [0, 1, 0, 1, 0, 1]
    plain = FastSimulator(scenes, SENSOR, fidelity="draft", share=False).expected()
    assert np.allclose(sim.expected(), plain, rtol=1e-5, atol=1e-5 * plain.max())
