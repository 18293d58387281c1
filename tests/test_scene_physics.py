"""Scene physics of issue 16: mixed object reflectance (retroreflective lobe + Lambertian base) and the mount.

Fast backend only (the twin's agreement is in ``test_mitsuba_agreement.py``).
"""

import dataclasses
import re

import numpy as np
import pytest

from nlosplan.errors import UserError
from nlosplan.sensor_models import preset
from nlosplan.simulators import FastSimulator, HiddenObject, denali_scene, explain, simulate
from nlosplan.simulators.fast.fidelity import FIDELITY_LEVELS, Fidelity
from nlosplan.denali import object_pose, plate_pose
from nlosplan.simulators.presets.denali import mount_mesh, plate_mesh

#: Same surface samples for the diffuse base as for the object: its term is then exactly a Lambertian object's.
FID = Fidelity(zone_sub=3, flash_sub=3, flash_outer=4, object_samples=128, time_oversample=4, diffuse_samples=128)


@pytest.fixture(scope="module")
def sensor():
    # the scene's parts add and scale in the transport; the preset's pile-up and time walk (one unit's calibration)
    # are nonlinear in the light and are tested with the sensor terms
    return preset("tmf8828-3x3-short").linear_uniform()


#: The centre zone only (the physics is the same in every zone; this keeps the file fast).
CENTRE = [(1, 1)]


def _object(scene, sensor, **kw):
    return FastSimulator(scene, sensor, fidelity=FID, dtype="float64", zones=CENTRE, **kw).expected(parts=True)["object"]


# ------------------------------------------------------------------ the mixture
def test_zero_diffuse_is_todays_retroreflector_bit_for_bit(sensor):
    today = FastSimulator(denali_scene("S", "8in", 45), sensor, fidelity="default").expected(parts=True)
    zero = FastSimulator(denali_scene("S", "8in", 45, diffuse_albedo=0.0), sensor, fidelity="default").expected(parts=True)
    for k in today:
        assert np.array_equal(today[k], zero[k]), k
    plan = explain(denali_scene("S", "8in", 45), sensor)
    left = [t for t in plan.terms if t.name == "object 'S_8in': diffuse base"]
    assert len(left) == 1 and not left[0].computed and "diffuse_albedo 0" in left[0].reason


def test_pure_diffuse_part_equals_todays_lambertian_object(sensor):
    lamb = _object(denali_scene("A", "8in", 19, reflectance="lambertian", albedo=0.7), sensor)
    mixed = _object(denali_scene("A", "8in", 19, albedo=0.0, diffuse_albedo=0.7), sensor)
    assert lamb.sum() > 0
    np.testing.assert_allclose(mixed, lamb, rtol=1e-12, atol=1e-12 * lamb.max())


def test_the_two_parts_add_and_scale_linearly(sensor):
    retro = _object(denali_scene("circle", "4in", 73, albedo=0.4), sensor)
    lamb = _object(denali_scene("circle", "4in", 73, reflectance="lambertian", albedo=0.3), sensor)
    mixed = _object(denali_scene("circle", "4in", 73, albedo=0.4, diffuse_albedo=0.3), sensor)
    np.testing.assert_allclose(mixed, retro + lamb, rtol=1e-12, atol=1e-12 * mixed.max())
    double = _object(denali_scene("circle", "4in", 73, albedo=0.4, diffuse_albedo=0.6), sensor)
    np.testing.assert_allclose(double - mixed, lamb, rtol=1e-9, atol=1e-9 * lamb.max())
    # the Lambertian return is a few per cent of an equal-albedo retroreflector's (DENALI geometry)
    assert 0.02 < (lamb.sum() / 0.3) / (retro.sum() / 0.4) < 0.2


def test_mixture_is_non_negative_and_grows_with_the_diffuse_albedo(sensor):
    scenes = [denali_scene("3", "8in", 47, albedo=0.3, diffuse_albedo=d) for d in (0.0, 0.1, 0.35, 0.7)]
    out = FastSimulator(scenes, sensor, fidelity=FID, dtype="float64", zones=CENTRE).expected(parts=True)
    obj = out["object"]
    assert np.all(np.isfinite(obj)) and np.all(obj >= 0) and np.all(out["counts"] >= 0)
    totals = obj.reshape(len(scenes), -1).sum(-1)
    assert np.all(np.diff(totals) > 0)
    # a batch mixing zero and non-zero diffuse bases equals separate runs (zero albedo: exactly nothing added)
    alone = _object(scenes[0], sensor)
    np.testing.assert_allclose(obj[0], alone, rtol=1e-12, atol=1e-12 * alone.max())


def test_diffuse_base_is_computed_and_explained(sensor):
    plan = explain(denali_scene("A", "8in", 19, albedo=0.4, diffuse_albedo=0.2), sensor)
    line = next(t for t in plan.terms if t.name == "object 'A_8in': diffuse base")
    assert line.computed and line.reason.startswith("Lambertian (albedo 0.2), ")
    n = int(re.search(r"(\d+) surface samples", line.reason).group(1))
    assert abs(n - FIDELITY_LEVELS["default"].diffuse_samples) <= 8  # clusters of the quadrature: about the asked number
    assert plan.object_albedo == ("albedo", "diffuse_albedo")


@pytest.mark.parametrize("kw, message", [
    ({"diffuse_albedo": 1.2}, "diffuse_albedo=1.2 is out of range; allowed: 0 to 1"),
    ({"diffuse_albedo": -0.1}, "diffuse_albedo=-0.1 is out of range"),
    ({"albedo": 0.7, "diffuse_albedo": 0.4}, "reflects more than the incident power; their sum must be <= 1"),
    ({"reflectance": "lambertian", "diffuse_albedo": 0.2}, "a Lambertian object's diffuse albedo is its albedo"),
    ({"mount": "yes"}, "mount and mount_in_background must be true or false"),
])
def test_bad_reflectance_parameters_are_one_line_errors(kw, message):
    with pytest.raises(UserError, match=message) as exc:
        denali_scene("A", "8in", 19, **kw)
    assert "\n" not in str(exc.value)


def test_fidelity_knob_for_the_diffuse_base_is_validated():
    assert FIDELITY_LEVELS["default"].diffuse_samples == 32
    assert all(a.diffuse_samples <= b.diffuse_samples for a, b in zip(list(FIDELITY_LEVELS.values()),
                                                                      list(FIDELITY_LEVELS.values())[1:]))
    with pytest.raises(UserError, match="diffuse_samples=0 must be an integer >= 1"):
        Fidelity(diffuse_samples=0)


# ------------------------------------------------------------------ the mount
def test_mount_and_plate_move_with_the_gantry():
    for p in (0, 57, 99):
        sc = denali_scene("A", "4in", p, mount=True)
        post, plate = sc.objects[1], sc.objects[2]
        assert (post.name, plate.name) == ("object mount", "mount plate")
        np.testing.assert_array_equal(post.to_world, object_pose(p))
        np.testing.assert_array_equal(plate.to_world, plate_pose(object_pose(p)))
        assert post.reflectance == plate.reflectance == "lambertian" and post.albedo == plate.albedo == 0.8
        assert post.fixture and plate.fixture
        # the plate sits on top of the post (DENALI's twin: plate at tag 1, post 4 cm below it)
        top = post.world_vertices()[:, 2].max()
        assert abs(plate.world_vertices()[:, 2].min() - top) < 0.02
    assert mount_mesh().area > plate_mesh().area > 0


def test_mount_in_the_signal_adds_a_size_independent_term(sensor):
    def obj(mount):  # one batch of both sizes (one compiled plan each)
        scenes = [denali_scene("square", z, 30, mount=mount, mount_in_background=False) for z in ("4in", "8in")]
        return FastSimulator(scenes, sensor, fidelity=FID, dtype="float64", zones=CENTRE).expected(parts=True)["object"]

    bare, mounted = obj(False), obj(True)
    add4, add8 = mounted[0] - bare[0], mounted[1] - bare[1]
    assert add4.sum() > 0
    np.testing.assert_allclose(add4, add8, rtol=1e-9, atol=1e-9 * add4.max())
    # the mount's return comes later than the object's (the post reaches down to the table)
    b = np.arange(add4.shape[-1])
    assert (add4 * b).sum() / add4.sum() > (bare[0] * b).sum() / bare[0].sum()


def test_a_fixture_mount_cancels_from_the_signal(sensor):
    with_mount = simulate(denali_scene("A", "8in", 19, mount=True), sensor, fidelity=FID, dtype="float64",
                          zones=CENTRE)
    plain = _object(denali_scene("A", "8in", 19), sensor)
    # the mount's three-bounce light is in the capture ...
    assert with_mount.parts["object"].sum() > 1.01 * plain.sum()
    # ... and in the background, so the signal is the object's alone
    np.testing.assert_allclose(with_mount.signal, plain, rtol=1e-9, atol=1e-6 * plain.max())
    assert any(t.name == "object 'object mount': fixture" and "not in the signal" in t.reason
               for t in with_mount.plan.terms)


def test_without_objects_keeps_or_drops_fixtures():
    sc = denali_scene("A", "8in", 19, mount=True)
    assert [o.name for o in sc.without_objects().objects] == ["object mount", "mount plate"]
    assert sc.without_objects(keep_fixtures=False).objects == ()
    free = dataclasses.replace(sc.objects[1], fixture=False)
    assert sc.replace(objects=(sc.objects[0], free)).without_objects().objects == ()
    with pytest.raises(UserError, match="fixture='no' must be true or false"):
        HiddenObject(mesh=mount_mesh(), fixture="no")


def test_batch_must_share_fixture_flags(sensor):
    a = denali_scene("A", "8in", 19, mount=True)
    b = denali_scene("A", "8in", 20, mount=True, mount_in_background=False)
    with pytest.raises(UserError, match="fixture flags"):
        FastSimulator([a, b], sensor, fidelity=FID)
