"""The DENALI rig preset: packaged data, geometry facts, labels and errors."""

from __future__ import annotations

import json
import math
from importlib import resources

import numpy as np
import pytest

from nlosplan.denali import CLASS_GROUPS, DENALI_OBJECTS, N_POSITIONS, SIZES, class_group, object_pose, positions_xy
from nlosplan.errors import UserError
from nlosplan.simulators.presets import denali_scene, mount_mesh, object_mesh, rig
from nlosplan.simulators.scene import Scene

DATA = resources.files("nlosplan.denali") / "data"
# TMF8828 3x3 SPAD map 33 x 32 deg (SENSOR_FACTS.md): half-diagonal ~ 23 deg
FOV_HALF_DIAGONAL_DEG = math.hypot(33 / 2, 32 / 2)


def _json(name):
    return json.loads((DATA / name).read_text())


@pytest.fixture(scope="module")
def world_vertices():
    """World vertices of every (object, size) at every position: {(obj, size): (100, V, 3)}."""
    poses = np.stack([object_pose(p) for p in range(N_POSITIONS)])
    out = {}
    for obj in DENALI_OBJECTS:
        for size in SIZES:
            v = object_mesh(obj, size).vertices
            out[obj, size] = np.einsum("pij,vj->pvi", poses[:, :3, :3], v) + poses[:, None, :3, 3]
    return out


# --------------------------------------------------------------- package data
def test_packaged_data_is_complete():
    names = {p.name for p in (DATA / "objects").iterdir()}
    assert len([n for n in names if n.endswith(".obj")]) == 60
    for f in ("object_mount.obj", "object_mount_plate.obj", "poses.json", "cameras.json",
              "tag1_positions.json", "LICENSE", "README.md"):
        assert (DATA / f).is_file(), f
    assert "MIT" in (DATA / "LICENSE").read_text()
    assert "9e1083293a4f6aac5e674c9bf0d948dc0697f8c3" in (DATA / "README.md").read_text()


def test_class_lists():
    assert len(DENALI_OBJECTS) == 30 and len(set(DENALI_OBJECTS)) == 30
    assert {g: len(v) for g, v in CLASS_GROUPS.items()} == {"numbers": 10, "letters": 10, "shapes": 10}
    assert SIZES == ("4in", "8in") and N_POSITIONS == 100
    assert class_group("7") == "numbers" and class_group("A") == "letters"
    assert class_group("widerectangle") == "shapes" and class_group("i") == "letters"


@pytest.mark.parametrize("obj", DENALI_OBJECTS)
def test_every_mesh_loads_with_plausible_size(obj):
    small, large = object_mesh(obj, "4in"), object_mesh(obj, "8in")
    for mesh, inches in ((small, 4), (large, 8)):
        assert mesh.area > 0
        ext = np.ptp(mesh.vertices, axis=0)
        # largest in-plane extent is the nominal size; thickness 6.6-7.6 mm
        assert ext[:2].max() == pytest.approx(inches * 0.0254, abs=2e-3)
        assert 0.006 < ext[2] < 0.008
    ratio = np.ptp(large.vertices, axis=0)[:2].max() / np.ptp(small.vertices, axis=0)[:2].max()
    assert ratio == pytest.approx(2.0, abs=0.05)
    assert 2.0 < large.area / small.area < 4.5  # ~4x area, less the constant-thickness sides
    assert object_mesh(obj, "8in") is large  # cached


def test_i_alias_and_file_names():
    assert object_mesh("i", "4in") is object_mesh("I", "4in")
    assert object_mesh("I", "4in").name == "I_4in" and object_mesh("I", "8in").name == "I_8in"
    assert denali_scene("i", "4in").meta["object"] == "I"
    assert mount_mesh().area > 0


# ------------------------------------------------------------------- the rig
def test_lidar_is_the_colocated_camera():
    cam = _json("cameras.json")["COLOCATED_CAMERA"]
    lidar, _, _ = rig()
    np.testing.assert_allclose(lidar.position, cam["position"], rtol=0, atol=1e-15)
    np.testing.assert_allclose(lidar.position, [0.459, 0.321, 0.373], atol=1e-3)
    r = np.array(cam["rotation_matrix"])
    np.testing.assert_allclose(lidar.forward, r[2], atol=1e-12)
    np.testing.assert_allclose(lidar.right, r[0], atol=1e-12)
    np.testing.assert_allclose(lidar.up, -r[1], atol=1e-12)
    assert lidar.up[2] > 0.99  # upright


def test_wall_geometry():
    lidar, wall, _ = rig()
    assert (2 * wall.half_u, 2 * wall.half_v) == pytest.approx((0.93, 0.6096), abs=1e-12)
    # the lit normal is -(x5 x y5) and points at the LiDAR (about -y world)
    r5 = np.array(_json("poses.json")["tracking_avgposes"]["5"]["rotation_matrix"])
    np.testing.assert_allclose(wall.normal, -np.cross(r5[:, 0], r5[:, 1]), atol=1e-6)
    assert wall.normal[1] < -0.99
    to_lidar = lidar.position - wall.center
    assert wall.signed_distance(lidar.position) > 0.45
    assert wall.normal @ to_lidar / np.linalg.norm(to_lidar) > 0.7
    # tag 5 sits 0.034 m in from the wall's left edge and 0.186 + 0.034 m above its bottom edge
    c5 = np.array(_json("poses.json")["tracking_avgposes"]["5"]["center"])
    np.testing.assert_allclose(wall.local(c5), [-(0.465 - 0.034), 0.3048 - 0.034 - 0.186], atol=1e-9)
    assert abs(wall.signed_distance(c5)) < 1e-9
    # the optical axis meets the wall inside it, 0.45-0.60 m away
    t = float(wall.signed_distance(lidar.position) / -(lidar.forward @ wall.normal))
    assert 0.45 < t < 0.60
    assert bool(wall.contains(lidar.position + t * lidar.forward, margin=-0.1))
    corners = wall.corners()
    assert corners[:, 2].min() == pytest.approx(0.024, abs=2e-3)  # near the table tops
    assert np.all((corners[:, 1] > 0.78) & (corners[:, 1] < 0.83))


def test_tables():
    lidar, _, tables = rig()
    assert [t.name for t in tables] == ["table 14", "table 15"]
    for t in tables:
        assert t.normal[2] > 0.99  # lit side up
        assert lidar.position[2] - t.center[2] > 0.3 and t.signed_distance(lidar.position) > 0.3
        assert sorted([2 * t.half_u, 2 * t.half_v]) == pytest.approx([0.78, 1.524], abs=1e-12)
        assert t.albedo == 0.5
    # tag 14 is the world origin with axes (x, -y, -z): hand-derived centre
    np.testing.assert_allclose(tables[0].center, [0.35, 0.762 - 0.548, -0.001], atol=2e-4)
    np.testing.assert_allclose(tables[1].center, [1.133, 0.225, 0.011], atol=2e-3)
    assert rig(tables=False)[2] == ()
    assert rig(wall_albedo=0.3)[1].albedo == 0.3


# ----------------------------------------------------------------- positions
def test_labels_cover_the_documented_area():
    xy = positions_xy()
    assert xy.shape == (100, 2)
    assert np.all((xy[:, 0] >= 0.95) & (xy[:, 0] <= 1.33) & (xy[:, 1] >= 0.15) & (xy[:, 1] <= 0.52))
    np.testing.assert_allclose([xy[:, 0].min(), xy[:, 0].max()], [0.969, 1.308], atol=1e-3)
    np.testing.assert_allclose([xy[:, 1].min(), xy[:, 1].max()], [0.166, 0.508], atol=1e-3)
    labels = _json("tag1_positions.json")
    lidar = rig()[0]
    d = [np.linalg.norm(np.array(labels[f"frame{p}_tag1"]) - lidar.position) for p in range(100)]
    assert 0.5 < min(d) and max(d) < 0.9
    # a snake scan on a ~3.56 cm pitch: neighbours in the scan are 3-5 cm apart
    step = np.linalg.norm(np.diff(xy, axis=0), axis=1)
    assert np.all((step > 0.025) & (step < 0.05))


def test_object_poses_face_the_wall_near_their_labels():
    _, wall, _ = rig()
    xy = positions_xy()
    for p in range(N_POSITIONS):
        m = object_pose(p)
        r = m[:3, :3]
        np.testing.assert_allclose(r.T @ r, np.eye(3), atol=1e-6)
        assert (r @ [0, 0, -1.0])[1] > 0.99  # mesh -z face looks at the wall (+y)
        assert 0.27 < wall.signed_distance(m[:3, 3]) < 0.63
        # the averaged tag-1 pose sits (0.038, 0.028) m from the published label
        assert np.linalg.norm(xy[p] - m[:2, 3]) < 0.06
    a = object_pose(3)
    a[0, 0] = 99.0
    assert object_pose(3)[0, 0] != 99.0  # callers get copies


def test_all_objects_in_front_of_wall_and_outside_the_fov(world_vertices):
    lidar, wall, _ = rig()
    for (obj, size), v in world_vertices.items():
        assert wall.signed_distance(v).min() > 0.25, (obj, size)
        d = v - lidar.position
        r = np.linalg.norm(d, axis=-1)
        ang = np.degrees(np.arccos(np.clip(d @ lidar.forward / r, -1, 1)))
        assert ang.min() > FOV_HALF_DIAGONAL_DEG + 5, (obj, size)
        assert 0.3 < r.min() and r.max() < 1.0


def test_every_position_gives_a_valid_scene():
    for p in range(N_POSITIONS):
        s = denali_scene("A", "8in", position=p)
        assert isinstance(s, Scene) and s.meta["position"] == p
        assert s.wall.signed_distance(s.objects[0].world_vertices()).min() > 0


# ------------------------------------------------------------------ the scene
def test_scene_defaults_and_meta():
    s = denali_scene()
    xy = positions_xy()[19]
    assert s.meta == {
        "preset": "denali", "object": "A", "size": "8in", "position": 19, "class_group": "letters",
        "lights": "off", "object_xy": [float(xy[0]), float(xy[1])], "reflectance": "retroreflective",
        "albedo": 0.5, "lobe_fwhm_deg": 2.0, "diffuse_albedo": 0.0, "mount": False, "wall_albedo": 0.8,
        "tables": True,
    }
    assert s.lights_on is False and len(s.objects) == 1 and len(s.planes) == 2
    o = s.objects[0]
    assert (o.reflectance, o.albedo, o.lobe_fwhm_deg, o.name) == ("retroreflective", 0.5, 2.0, "A_8in")
    np.testing.assert_array_equal(o.to_world, object_pose(19))
    assert s.without_objects().objects == ()


@pytest.mark.parametrize("lights, on", [("on", True), ("off", False), (True, True), (False, False), ("ON", True)])
def test_lights(lights, on):
    s = denali_scene("plus", "4in", 5, lights)
    assert s.lights_on is on and s.meta["lights"] == ("on" if on else "off")
    assert s.meta["class_group"] == "shapes" and s.meta["size"] == "4in"


def test_mount_and_reflectance_options():
    s = denali_scene("3", "4in", 42, "on", mount=True, reflectance="lambertian", albedo=0.2, tables=False)
    obj, mount, plate = s.objects   # the mount is the post and the plate the object sits on (two fixtures)
    assert (obj.reflectance, obj.albedo, obj.fixture) == ("lambertian", 0.2, False)
    assert (mount.reflectance, mount.albedo, mount.fixture) == ("lambertian", 0.8, True)
    assert (plate.reflectance, plate.albedo, plate.fixture) == ("lambertian", 0.8, True)
    np.testing.assert_array_equal(mount.to_world, obj.to_world)
    assert s.meta["mount"] is True and s.meta["mount_albedo"] == 0.8
    assert s.planes == () and s.meta["reflectance"] == "lambertian"
    # the mount post hangs below the object towards the tables
    assert mount.world_vertices()[:, 2].min() < 0.05 < obj.world_vertices()[:, 2].min()


@pytest.mark.parametrize(
    "kwargs, words",
    [
        ({"obj": "Q"}, "unknown DENALI object 'Q'; allowed: 0, 1"),
        ({"obj": "a"}, "widerectangle"),
        ({"size": "6in"}, "allowed: 4in, 8in"),
        ({"position": 100}, "allowed: integers 0 to 99"),
        ({"position": -1}, "allowed: integers 0 to 99"),
        ({"position": 1.0}, "allowed: integers 0 to 99"),
        ({"position": True}, "allowed: integers 0 to 99"),
        ({"lights": "dim"}, "allowed: 'on', 'off'"),
        ({"albedo": 1.5}, "albedo"),
        ({"reflectance": "mirror"}, "allowed: retroreflective, lambertian"),
        ({"wall_albedo": -0.1}, "wall_albedo"),
    ],
)
def test_errors_are_one_line_and_list_allowed_values(kwargs, words):
    with pytest.raises(UserError) as err:
        denali_scene(**kwargs)
    assert "\n" not in str(err.value) and words in str(err.value)


def test_position_accepts_numpy_integers():
    assert denali_scene(position=np.int64(7)).meta["position"] == 7
