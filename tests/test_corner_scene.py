"""The parametric corner scene."""

from __future__ import annotations

import numpy as np
import pytest

from nlosplan.errors import UserError
from nlosplan.simulators.meshes import square_patch
from nlosplan.simulators.presets import corner_scene, object_mesh


def _patch_normal(scene) -> np.ndarray:
    o = scene.objects[0]
    return o.to_world[:3, :3] @ o.mesh.face_normals[0]


@pytest.mark.parametrize("d", [0.2, 0.5, 1.7])
def test_lidar_faces_the_wall_at_wall_distance(d):
    s = corner_scene(wall_distance=d)
    assert s.wall.signed_distance(s.lidar.position) == pytest.approx(d, rel=1e-15)
    np.testing.assert_allclose(s.lidar.position, [0, -d, 0])
    np.testing.assert_allclose(s.lidar.forward, [0, 1, 0])
    np.testing.assert_allclose(s.lidar.up, [0, 0, 1])
    np.testing.assert_allclose(s.lidar.right, [1, 0, 0])  # +x is the LiDAR's right
    np.testing.assert_allclose(s.wall.normal, [0, -1, 0])
    # the optical axis meets the wall at its centre
    t = s.wall.signed_distance(s.lidar.position) / -(s.lidar.forward @ s.wall.normal)
    np.testing.assert_allclose(s.lidar.position + t * s.lidar.forward, s.wall.center, atol=1e-15)


def test_wall_size_and_albedo():
    s = corner_scene(wall_size=(2.0, 1.0), wall_albedo=0.6)
    np.testing.assert_allclose(s.wall.corners()[[0, 2]], [[-1.0, 0, -0.5], [1.0, 0, 0.5]], atol=1e-15)
    assert s.wall.albedo == 0.6 and s.planes == ()


def test_patch_centre_size_and_normal():
    s = corner_scene(object_xy=(0.3, 0.2), object_size=0.1, albedo=0.4, reflectance="retroreflective")
    o = s.objects[0]
    np.testing.assert_allclose(o.to_world[:3, 3], [0.3, -0.2, 0.0])
    np.testing.assert_allclose(o.world_vertices().mean(axis=0), [0.3, -0.2, 0.0], atol=1e-15)
    # a 10 cm square standing 0.2 m in front of the wall, parallel to it, facing it
    np.testing.assert_allclose(s.wall.signed_distance(o.world_vertices()), 0.2, atol=1e-15)
    np.testing.assert_allclose(np.ptp(o.world_vertices(), axis=0), [0.1, 0.0, 0.1], atol=1e-15)
    np.testing.assert_allclose(_patch_normal(s), [0, 1, 0], atol=1e-15)
    assert (o.reflectance, o.albedo) == ("retroreflective", 0.4)
    assert s.meta == {"preset": "corner", "object": "patch", "object_xy": [0.3, 0.2], "wall_distance": 0.5,
                      "reflectance": "retroreflective", "albedo": 0.4, "diffuse_albedo": 0.0, "lobe_fwhm_deg": 2.0,
                      "object_yaw_deg": 0.0,
                      "object_size": 0.1, "lights": "off"}


def test_defaults():
    s = corner_scene()
    np.testing.assert_allclose(s.objects[0].to_world[:3, 3], [0.45, -0.30, 0.0])
    assert s.objects[0].reflectance == "lambertian" and s.lights_on is False
    assert corner_scene(lights_on=True).lights_on is True


@pytest.mark.parametrize("yaw, normal", [(90.0, [-1, 0, 0]), (-90.0, [1, 0, 0]), (30.0, [-0.5, 3**0.5 / 2, 0])])
def test_yaw_turns_about_the_vertical_through_the_centre(yaw, normal):
    s = corner_scene(object_xy=(0.4, 0.3), yaw_deg=yaw)
    np.testing.assert_allclose(_patch_normal(s), normal, atol=1e-12)
    np.testing.assert_allclose(s.objects[0].to_world[:3, 3], [0.4, -0.3, 0.0])
    np.testing.assert_allclose(s.objects[0].world_vertices()[:, 2], corner_scene().objects[0].world_vertices()[:, 2],
                               atol=1e-15)  # heights unchanged


def test_denali_named_object_faces_the_wall():
    s = corner_scene(object="A_8in", object_xy=(0.5, 0.25), reflectance="retroreflective")
    o = s.objects[0]
    assert o.mesh is object_mesh("A", "8in") and o.name == "A_8in" and s.meta["object"] == "A_8in"
    r = o.to_world[:3, :3]
    np.testing.assert_allclose(r @ [0, 0, -1.0], [0, 1, 0], atol=1e-15)  # mesh -z face looks at the wall
    np.testing.assert_allclose(r @ [0, 1.0, 0], [0, 0, 1], atol=1e-15)  # mesh +y is up
    back = o.mesh.face_normals[:, 2] < -0.99
    np.testing.assert_allclose((o.mesh.face_normals[back] @ r.T)[:, 1], 1.0, atol=1e-12)
    np.testing.assert_allclose(o.to_world[:3, 3], [0.5, -0.25, 0.0])
    assert s.wall.signed_distance(o.world_vertices()).min() > 0.24
    assert corner_scene(object="i_4in").objects[0].name == "I_4in"


def test_mesh_and_obj_path_objects(tmp_path):
    m = square_patch(0.05, name="tile")
    s = corner_scene(object=m)
    assert s.objects[0].mesh is m and s.meta["object"] == "tile"
    # a generic mesh gets DENALI's convention: its -z side looks at the wall
    np.testing.assert_allclose(_patch_normal(s), [0, -1, 0], atol=1e-15)
    path = tmp_path / "tri.obj"
    path.write_text("v 0 0 0\nv 0.1 0 0\nv 0 0.1 0\nf 1 2 3\n")
    for obj in (path, str(path)):
        s = corner_scene(object=obj)
        assert s.objects[0].mesh.area == pytest.approx(0.005, rel=1e-12) and s.meta["object"] == "tri"


def test_floor():
    s = corner_scene(floor_z=-0.4)
    (floor,) = s.planes
    np.testing.assert_allclose(floor.normal, [0, 0, 1], atol=1e-15)
    assert floor.center[2] == -0.4 and floor.albedo == 0.3 and floor.area == pytest.approx(9.0)
    assert floor.signed_distance(s.lidar.position) == pytest.approx(0.4)
    assert bool(floor.contains(np.array([0.0, -0.01, -0.4]))) and not bool(floor.contains(np.array([0.0, 0.01, -0.4])))


@pytest.mark.parametrize(
    "kwargs, words",
    [
        ({"wall_distance": 0}, "wall_distance=0 must be > 0"),
        ({"wall_distance": -1.0}, "wall_distance"),
        ({"wall_distance": float("nan")}, "finite"),
        ({"object_xy": (0.3, 0.0)}, "must be > 0"),
        ({"object_xy": (0.3, -0.2)}, "must be > 0"),
        ({"object_xy": 0.3}, "two numbers"),
        ({"object_size": 0.0}, "object_size"),
        ({"wall_size": (0.0, 1.0)}, "wall_size"),
        ({"wall_size": (1.0, -1.0)}, "wall_size"),
        ({"object": "teapot"}, "allowed: 'patch'"),
        ({"object": "Q_8in"}, "allowed: 'patch'"),
        ({"floor_z": 0.1}, "floor_z"),
        ({"yaw_deg": float("inf")}, "yaw_deg"),
        ({"lights_on": "yes"}, "lights_on"),
        ({"albedo": 2.0}, "albedo"),
    ],
)
def test_validation_errors(kwargs, words):
    with pytest.raises(UserError) as err:
        corner_scene(**kwargs)
    assert "\n" not in str(err.value) and words in str(err.value)


def test_missing_obj_path_is_a_user_error(tmp_path):
    with pytest.raises(UserError, match="does not exist"):
        corner_scene(object=str(tmp_path / "nope.obj"))
