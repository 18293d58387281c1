"""A design run's world references are planned for the largest world sigma: one compiled program per layout."""

import numpy as np
import pytest

from nlosplan.planner.design import run as design_run
from nlosplan.planner.design.config import full_config
from nlosplan.simulators.fast.plan import support_sigma_ps


def test_every_world_reference_is_planned_for_the_widest_world_jitter(tmp_path, monkeypatch):
    cfg = full_config()
    plan = design_run._world_plan(cfg)
    seen = []
    monkeypatch.setattr(design_run, "_simulate", lambda executor, jobs, say, what, cache: seen.extend(jobs))
    need = [(w, layout) for w in plan.worlds for layout in ("1x1", "3x3")]
    paths = design_run._world_references(cfg, tmp_path, plan, need, None, lambda *a: None)
    assert len(seen) == len(need) == len(paths)
    own = [j.sensor.impulse_sigma_ps for j in seen]
    # the main job's worlds round to more than one support on their own (world 0 has no jitter at all) ...
    assert len({support_sigma_ps(s) for s in own if s > 0}) > 1 and min(own) == 0.0
    # ... and every job carries the widest, world 0 included, so their plans share one support
    assert {j.min_support_sigma_ps for j in seen} == {max(own)} == {design_run._support_sigma(cfg, plan, "fast")}
    assert all(j.to_dict()["min_support_sigma_ps"] == max(own) for j in seen)
    # the worlds take every second position: each pads its plan to the nominal scenes'
    assert plan.scenes.positions == cfg.scenes.positions[::2]
    assert all(j.pad_scenes == cfg.scenes and j.to_dict()["pad_scenes"] == cfg.scenes.to_dict() for j in seen)


def test_a_worlds_reference_padded_to_the_nominal_plan_runs_its_program_and_keeps_its_histograms(monkeypatch):
    from dataclasses import replace

    from nlosplan.planner.design import data
    from nlosplan.planner.design.data import SceneSet, simulate_reference
    from nlosplan.sensor_models.presets import preset
    from nlosplan.simulators import plan_batch

    nominal = SceneSet(objects=("A", "circle"), sizes=("8in",), positions=tuple(range(0, 100, 9)), repeats=1,
                       crlb_objects=(), fidelity="draft", scene_kwargs={"albedo": 0.36, "diffuse_albedo": 0.2,
                                                                         "mount": True, "mount_in_background": False})
    world = replace(nominal, positions=nominal.positions[::2], scene_kwargs={**dict(nominal.scene_kwargs),
                                                                             "albedo": 0.4})
    sensor = preset("tmf8828-3x3-short")
    seen = []
    real = data.simulate_reference.__globals__["_nominal_plan"]
    monkeypatch.setattr(data, "_NOMINAL_PLAN", {})
    monkeypatch.setattr(data, "_nominal_plan", lambda *a: seen.append(real(*a)) or seen[-1])
    own = simulate_reference(sensor, world)
    padded = simulate_reference(sensor, world, pad_scenes=nominal)
    again = simulate_reference(sensor, world, pad_scenes=nominal)
    assert len(seen) == 2 and seen[0] is seen[1]  # the nominal plan is built once per process and layout
    np.testing.assert_allclose(padded.means, own.means, rtol=1e-4, atol=1e-6 * own.means.max())
    np.testing.assert_array_equal(again.means, padded.means)
    kw = world.options()
    scenes = [data_scene(o, s, p, kw) for o in world.objects for s in world.sizes for p in world.positions]
    from nlosplan.simulators.fast.plan import pad_plan

    alone = plan_batch(scenes, sensor, fidelity="draft")
    assert alone.static != seen[0].static  # every second position alone: smaller time ranges, another program
    assert pad_plan(alone, seen[0]).static == seen[0].static


def data_scene(obj, size, position, kw):
    from nlosplan.simulators import denali_scene

    return denali_scene(obj, size, position, **kw)


def test_the_nominal_references_are_planned_as_the_worlds_are(tmp_path, monkeypatch):
    # so each layout's worlds run the program the references stage compiled; no worlds (a run on real captures):
    # the sensor's own plan
    cfg = full_config()
    plan = design_run._world_plan(cfg)
    seen = []
    monkeypatch.setattr(design_run, "_simulate",
                        lambda executor, jobs, say, what, cache, catalog=False: seen.extend(jobs) or ({}, None))

    class NotSimulated(Exception):
        """What the references stage does after its jobs (loading their files) is not this test's."""

    def load(path):
        raise NotSimulated(path)

    monkeypatch.setattr("nlosplan.planner.design.data.load_reference", load)  # what follows the jobs: not here
    for worlds, want in ((plan, design_run._support_sigma(cfg, plan, "fast")), (None, 0.0)):
        seen.clear()
        with pytest.raises(NotSimulated):
            design_run._references(cfg, tmp_path, lambda *a: None, None, worlds=worlds)
        assert len(seen) == len(cfg.space.zones) and {j.min_support_sigma_ps for j in seen} == {want}
    assert design_run._support_sigma(cfg, plan, "fast") > 50.0
    assert design_run._support_sigma(cfg, plan, "mitsuba") == 0.0


def test_the_twins_world_references_are_not_sized(tmp_path, monkeypatch):
    # the Mitsuba twin has no plan: its jobs carry 0, which expected_batch accepts for any backend
    from dataclasses import replace

    cfg = full_config()
    plan = design_run._world_plan(cfg)
    plan = replace(plan, scenes=replace(plan.scenes, backend="mitsuba"))
    seen = []
    monkeypatch.setattr(design_run, "_simulate", lambda executor, jobs, say, what, cache: seen.extend(jobs))
    design_run._world_references(cfg, tmp_path, plan, [(w, "1x1") for w in plan.worlds], None, lambda *a: None)
    assert len(seen) == len(plan.worlds) and {j.min_support_sigma_ps for j in seen} == {0.0}
    assert max(j.sensor.impulse_sigma_ps for j in seen) > 0
