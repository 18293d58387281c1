"""The scene's cheap per-scene checks (issue 38: a dataset builds 12,000 scenes; np.cross and np.allclose on
3-vectors cost more than the checks themselves, so they are written out)."""

import numpy as np
import pytest

from nlosplan.errors import UserError
from nlosplan.simulators import HiddenObject
from nlosplan.simulators.presets.denali import denali_scene, mount_mesh
from nlosplan.simulators.scene import Rect


def test_rect_normal_is_the_cross_product_of_its_axes():
    rng = np.random.default_rng(3)
    for _ in range(20):
        n = rng.normal(size=3)
        r = Rect.facing(rng.normal(size=3), n, rng.normal(size=3), width=1.0, height=2.0)
        np.testing.assert_allclose(r.normal, np.cross(r.u_axis, r.v_axis), rtol=0, atol=1e-15)
        np.testing.assert_allclose(r.normal, n / np.linalg.norm(n), atol=1e-12)
    wall = denali_scene("A", "8in", 0).wall
    assert wall.signed_distance(wall.center + 0.25 * wall.normal) == pytest.approx(0.25)


def _pose(rot, last=(0.0, 0.0, 0.0, 1.0)):
    m = np.eye(4)
    m[:3, :3] = rot
    m[3] = last
    m[:3, 3] = (0.1, 0.2, 0.3)
    return m


def test_rigid_transforms_pass_and_others_are_one_line_errors():
    c, s = np.cos(0.3), np.sin(0.3)
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    HiddenObject(mesh=mount_mesh(), to_world=_pose(rot))
    HiddenObject(mesh=mount_mesh(), to_world=_pose(rot * (1 + 4e-4)))  # within np.allclose(atol=1e-3) of rigid
    for bad in (_pose(rot * 1.01), _pose(np.diag([1.0, 1.0, -1.0]) @ rot + 0.01), _pose(rot, (0, 0, 1e-6, 1))):
        with pytest.raises(UserError, match="must be a rigid transform"):
            HiddenObject(mesh=mount_mesh(), to_world=bad)
    # the off-diagonal tolerance is np.allclose's: 1e-3 exactly (the diagonal's 1e-3 + 1e-5)
    shear = np.eye(3)
    shear[0, 1] = 1.0008e-3  # r.T r off-diagonal ~1.0008e-3
    with pytest.raises(UserError, match="must be a rigid transform"):
        HiddenObject(mesh=mount_mesh(), to_world=_pose(shear))
    with pytest.raises(UserError, match="finite 4x4"):
        HiddenObject(mesh=mount_mesh(), to_world=np.full((4, 4), np.nan))


def test_objects_behind_or_through_the_wall_are_refused_and_those_near_it_pass():
    scene = denali_scene("A", "8in", 0)
    wall, obj = scene.wall, scene.objects[0]
    centre, radius = obj.mesh.bounding_sphere
    assert np.all(np.linalg.norm(obj.mesh.vertices - centre, axis=1) <= radius + 1e-12)

    def at(distance):  # the object's sphere centre this far in front of the wall's plane (negative: behind)
        m = np.array(obj.to_world, dtype=float)
        m[:3, 3] += (distance - wall.signed_distance(m[:3, :3] @ centre + m[:3, 3])) * wall.normal
        return obj.moved_to(m)

    v = at(0.5).world_vertices()
    extent = float(np.ptp(wall.signed_distance(v))) / 2  # the object's half depth along the wall's normal
    for d in (0.5, radius + 1e-3, extent + 1e-3):  # far, just clear of the sphere, inside the sphere but clear
        scene.replace(objects=(at(d),))
    with pytest.raises(UserError, match="intersects the relay wall"):
        scene.replace(objects=(at(0.0),))
    with pytest.raises(UserError, match="lies behind the relay wall"):
        scene.replace(objects=(at(-0.5),))
