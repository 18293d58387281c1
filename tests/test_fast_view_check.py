"""The plan's "object in the LiDAR's direct view" check skips poses whose bounding sphere is out of view, and finds
exactly the zones the check of every dense point finds."""

import dataclasses

import numpy as np

from nlosplan.sensor_models import preset
from nlosplan.simulators import corner_scene, denali_scene
from nlosplan.simulators.fast.plan import (_dense_world_points, _direct_view_zones, _in_view_zones,
                                           _outside_view)

SENSOR = preset("tmf8828-3x3-short")


def _posed(obj, rng, n):
    """``n`` copies of ``obj`` moved to random places around the LiDAR (in front, beside, behind) and turned."""
    out = []
    for _ in range(n):
        a = rng.uniform(0, 2 * np.pi)
        rot = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
        m = np.eye(4)
        m[:3, :3] = rot @ obj.to_world[:3, :3]
        m[:3, 3] = rng.uniform([-1.0, -1.0, -0.5], [1.0, 1.0, 0.8])
        out.append(dataclasses.replace(obj, to_world=m))
    return out


def test_skipping_out_of_view_poses_finds_the_same_zones():
    rng = np.random.default_rng(3)
    scene = corner_scene(object_xy=(0.0, 0.2))
    objs = _posed(scene.objects[0], rng, 400)
    outside = _outside_view(scene, SENSOR, objs)
    assert 0 < outside.sum() < len(objs)  # some poses culled, some kept
    # a culled pose has no dense point in view: each one alone finds no zone
    for obj in [o for o, out in zip(objs, outside) if out][:60]:
        assert _direct_view_zones(scene, SENSOR, _dense_world_points([obj])) == []
    for k in range(0, 400, 40):  # batches of 40 poses: the same zones with and without the culling
        batch = objs[k:k + 40]
        assert _in_view_zones(scene, SENSOR, batch) == _direct_view_zones(scene, SENSOR, _dense_world_points(batch))
    # the corner scene's patch in front of the LiDAR: seen in the zones every dense point names
    zones = _in_view_zones(scene, SENSOR, scene.objects)
    assert zones and zones == _direct_view_zones(scene, SENSOR, _dense_world_points(scene.objects))


def test_denali_objects_behind_the_occluder_are_all_culled():
    scenes = [denali_scene(o, "8in", p) for o in ("A", "triangle") for p in (0, 45, 99)]
    objs = [sc.objects[0] for sc in scenes]
    assert _outside_view(scenes[0], SENSOR, objs).all()
    assert _in_view_zones(scenes[0], SENSOR, objs) == []
