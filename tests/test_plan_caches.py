"""The plan's per-pose geometry is kept between plans of the same objects at the same poses (a design run's worlds)."""

import numpy as np

from nlosplan.sensor_models.presets import resolve_sensor
from nlosplan.simulators import denali_scene
from nlosplan.simulators.fast import plan_object as po
from nlosplan.simulators.fast.plan import build_plan


def _scenes(albedo):
    return [denali_scene(o, s, p, albedo=albedo, diffuse_albedo=0.2, mount=True, mount_in_background=False)
            for o in ("A", "circle") for s in ("8in",) for p in (0, 7, 42)]


def test_a_second_plan_of_the_same_poses_reuses_the_faces_and_spheres_and_equals_a_fresh_one(monkeypatch):
    sensor = resolve_sensor("tmf8828-3x3-short")
    monkeypatch.setattr(po, "_VISIBLE_CACHE", po.OrderedDict())
    monkeypatch.setattr(po, "_SPHERE_CACHE", po.OrderedDict())
    first = build_plan(_scenes(0.36), sensor, "draft")
    calls = []
    real = po._faces_seeing_the_wall
    monkeypatch.setattr(po, "_faces_seeing_the_wall", lambda *a: calls.append(1) or real(*a))
    again = build_plan(_scenes(0.5), sensor.replace(jitter_fwhm_ps=80.0), "draft")  # another world: same poses
    assert calls == []  # every mesh's faces came from the first plan
    moved = build_plan([denali_scene("A", "8in", 3, albedo=0.36)], sensor, "draft")  # a new pose: computed
    assert len(calls) == 1 and moved.paths > 0
    # the kept values are the computed ones: a plan with empty caches is the same plan
    monkeypatch.setattr(po, "_VISIBLE_CACHE", po.OrderedDict())
    monkeypatch.setattr(po, "_SPHERE_CACHE", po.OrderedDict())
    fresh = build_plan(_scenes(0.5), sensor.replace(jitter_fwhm_ps=80.0), "draft")
    assert fresh.static == again.static and fresh.paths == again.paths
    for a, b in zip(fresh.arrays["objects"], again.arrays["objects"]):
        assert a.keys() == b.keys() and all(np.array_equal(a[k], b[k]) for k in a)
    assert first.static.objects == again.static.objects


def test_bounding_spheres_hold_every_vertex_of_their_pose():
    objs = [s.objects[0] for s in _scenes(0.36)]
    for _ in range(2):  # computed, then from the cache
        centres, radii = po._bounding_spheres(objs)
        for obj, c, r in zip(objs, centres, radii):
            d = np.linalg.norm(obj.world_vertices() - c, axis=1)
            assert d.max() == r
