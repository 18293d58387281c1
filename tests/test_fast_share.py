"""Object terms shared by many scenes of a batch (the gantry mount under every object) are simulated once per pose.

Also the planning shortcuts that make a 3,000-scene reference batch plan in seconds: surface quadratures cached by
mesh content, and the faces that see the wall found for every pose at once.
"""

import numpy as np
import pytest

from nlosplan.sensor_models.presets import resolve_sensor
from nlosplan.simulators import FastSimulator, denali_scene
from nlosplan.simulators.fast.plan_object import _visible_faces
from nlosplan.simulators.meshes import surface_quadrature
from nlosplan.simulators.presets.denali import object_mesh

CALIBRATED = {"albedo": 0.3667, "diffuse_albedo": 0.2, "mount": True, "mount_albedo": 0.8, "mount_in_background": False}


def _batch(positions, **extra):
    return [denali_scene(o, s, p, **CALIBRATED, **extra) for o in ("A", "S", "circle") for s in ("4in", "8in")
            for p in positions]


@pytest.mark.parametrize("walk", [pytest.param(0.0, marks=pytest.mark.slow), 40.0], ids=["no-walk", "time-walk"])  # no-walk: 30 s, the time-walk case covers it
def test_mount_is_simulated_once_per_position_and_equals_the_unshared_batch(walk):
    base = resolve_sensor("tmf8828-3x3-short").replace(time_walk_ps=walk)
    sensors = [base, base.replace(jitter_fwhm_ps=150.0, photon_scale=0.5)]
    scenes = _batch((0, 31, 77))  # 3 objects x 2 sizes x 3 positions = 18 scenes, the mount at 3 poses
    shared = FastSimulator(scenes, sensors=sensors, fidelity="draft", chunk=4)  # 5 chunks, the last padded
    plain = FastSimulator(scenes, sensors=sensors, fidelity="draft", chunk=4, share=False)
    terms, first, group = shared.shared_terms()
    # the object's retro and diffuse terms differ per scene; the mount and its plate follow the position only
    kinds = [shared.plan.static.objects[k].kind for k in terms]
    assert len(terms) == 2 and kinds == ["lambertian", "lambertian"]
    assert [shared.plan.object_index[k] for k in terms] == [1, 2]
    assert len(first) == 3 and list(group) == [0, 1, 2] * 6
    assert plain.shared_terms() is None
    a, b = shared.expected(parts=True), plain.expected(parts=True)
    assert a["counts"].shape == (2, 18, 3, 3, 128)
    for part in ("counts", "object"):
        assert np.abs(a[part] - b[part]).max() <= 1e-6 * np.abs(b[part]).max(), part
    # the mount is a real part of the signal here: without it the object part is clearly lower
    bare = FastSimulator([denali_scene("A", "4in", 0, **{**CALIBRATED, "mount": False})], sensors[0],
                         fidelity="draft").expected(parts=True)["object"]
    assert a["object"][0, 0].sum() > 1.05 * bare.sum()


def test_no_term_is_shared_when_every_scene_has_its_own_pose():
    scenes = [denali_scene(o, "8in", p, **CALIBRATED) for o, p in (("A", 0), ("S", 10), ("circle", 20), ("3", 30))]
    sim = FastSimulator(scenes, resolve_sensor("tmf8828-3x3-short"), fidelity="draft")
    assert sim.shared_terms() is None


def test_a_term_shared_by_only_some_scenes_is_left_per_scene():
    # 4 scenes, 3 mount poses: sharing would save one evaluation of 4, under the "at most half" rule
    scenes = [denali_scene(o, "8in", p, **CALIBRATED) for o, p in (("A", 0), ("S", 0), ("circle", 20), ("3", 30))]
    assert FastSimulator(scenes, resolve_sensor("tmf8828-3x3-short"), fidelity="draft").shared_terms() is None


def test_surface_quadrature_is_computed_once_per_mesh_and_read_only():
    mesh = object_mesh("A", "8in")
    a = surface_quadrature(mesh, 64)
    assert surface_quadrature(mesh, 64) is a
    assert surface_quadrature(mesh, 65) is not a and len(surface_quadrature(mesh, 65).points) >= 65
    mask = np.zeros(len(mesh.faces), bool)
    mask[: len(mask) // 2] = True
    half = surface_quadrature(mesh, 64, face_mask=mask)
    assert half is not a and half.areas.sum() == pytest.approx(mesh.face_areas[mask & (mesh.face_areas > 0)].sum())
    assert a.areas.sum() == pytest.approx(mesh.area)
    with pytest.raises(ValueError):
        a.points[0, 0] = 1.0
    with pytest.raises(ValueError):
        mesh.face_normals[0, 0] = 1.0


def test_visible_faces_of_all_poses_at_once_equal_the_pose_by_pose_test():
    scenes = _batch((0, 13, 50, 99))
    scene = scenes[0]
    objs = [sc.objects[0] for sc in scenes if sc.objects[0].mesh is scenes[0].objects[0].mesh]
    mesh = objs[0].mesh
    corners = scene.wall.corners()
    expect = np.zeros(len(mesh.faces), bool)
    for obj in objs:  # the definition, one pose at a time
        r, t = obj.to_world[:3, :3], obj.to_world[:3, 3]
        tw = mesh.triangles @ r.T + t
        nw = mesh.face_normals @ r.T
        cen = tw.mean(axis=1)
        sees = np.einsum("fk,fck->fc", nw, corners[None] - cen[:, None]).max(axis=1) > 0
        expect |= sees & (scene.wall.signed_distance(tw).max(axis=1) > 0)
    expect &= mesh.face_areas > 0
    got = _visible_faces(objs, scene)
    np.testing.assert_array_equal(got, expect)
    assert 0 < got.sum() < len(got)  # some faces see the wall, the back ones do not
