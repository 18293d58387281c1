"""The simulators' batch seam: expected_batch, counts_and_jacobian, direct_arrivals, the one table of backends."""

from __future__ import annotations

import numpy as np
import pytest

from nlosplan.errors import UserError
from nlosplan.sensor_models import preset
from nlosplan.simulators import (BACKENDS, NUISANCE_PARAMETERS, FastSimulator, check_backend, counts_and_jacobian,
                                 denali_scene, direct_arrivals, expected_batch, expected_histogram, resolve_fidelity)

SENSOR = preset("tmf8828-3x3-short")
FID = "draft"
SCENES = [denali_scene(o, "8in", p) for o in ("A", "S") for p in (3, 40)]


def test_a_batch_is_the_fast_simulator_of_the_list_and_each_scene_alone():
    batch = expected_batch(SCENES, SENSOR, fidelity=FID)
    assert batch.expected.shape == (4, 3, 3, 128) and batch.parts is None
    np.testing.assert_array_equal(batch.expected, FastSimulator(SCENES, SENSOR, fidelity=FID).expected())
    one = expected_histogram(SCENES[2], SENSOR, fidelity=FID)
    np.testing.assert_allclose(batch.expected[2], one, rtol=2e-6, atol=1e-6 * one.max())  # float32 batching
    assert batch.fidelity == resolve_fidelity(FID) and batch.warnings == ()


def test_batch_parts_add_up_to_the_counts_without_pileup_or_clip():
    sensor = SENSOR.replace(ambient_rate_hz=2e6, pileup=False, saturation=False)
    scenes = [denali_scene("A", "8in", 3, lights="on"), denali_scene("A", "8in", 3, lights="off")]
    batch = expected_batch(scenes, sensor, fidelity=FID, zones=[(1, 1)], dtype="float64", parts=True)
    assert batch.expected.shape == (2, 1, 128)
    assert set(batch.parts) == {"direct", "object", "floor", "crosstalk"}
    total = sum(batch.parts.values())
    np.testing.assert_allclose(batch.expected, total, rtol=1e-12)
    per_hz = sensor.bin_width_ps * 1e-12 * sensor.iterations  # counts per bin of 1 Hz
    np.testing.assert_allclose(batch.parts["floor"][0], (2e6 + sensor.dark_rate_hz) * per_hz, rtol=1e-12)
    np.testing.assert_allclose(batch.parts["floor"][1], sensor.dark_rate_hz * per_hz, rtol=1e-12)


def test_progress_is_called_in_scenes():
    seen = []
    expected_batch(SCENES, SENSOR, fidelity=FID, chunk=2, progress=lambda done, total: seen.append((done, total)))
    assert seen == [(2, 4), (4, 4)]


def test_counts_and_jacobian_through_the_seam_names_its_parameters():
    lam, jac, names, fid = counts_and_jacobian(SCENES[:1], SENSOR, fidelity=FID, nuisance=("photon_scale", "albedo"))
    assert names == ("x", "y", "log_photon_scale", "log_albedo") and fid == resolve_fidelity(FID)
    assert lam.shape == (1, 9, 128) and jac.shape == (1, 9, 128, 4)
    # photon scale is linear in the light that is not the floor: d lam / d log s = lam - floor
    floor = SENSOR.dark_rate_hz * SENSOR.bin_width_ps * 1e-12 * SENSOR.iterations
    np.testing.assert_allclose(jac[0, ..., 2], lam[0] - floor, rtol=1e-5, atol=1e-6 * lam.max())


@pytest.mark.parametrize("call, message", [
    (lambda: expected_batch([], SENSOR), "give at least one scene"),
    (lambda: expected_batch(["A"], SENSOR), "scenes must be Scenes"),
    (lambda: expected_batch(SCENES, "tmf8828-3x3-short"), "sensor must be a SensorConfig"),
    (lambda: expected_batch(SCENES, SENSOR, backend="blender"), "unknown backend 'blender'; available: fast, mitsuba"),
    (lambda: counts_and_jacobian(SCENES, SENSOR, nuisance=("gain",)), "each at most once from photon_scale, ambient"),
    (lambda: counts_and_jacobian(SCENES, SENSOR, backend="mitsuba"), "the mitsuba twin is not differentiated"),
    (lambda: counts_and_jacobian(SCENES, SENSOR, axes=[[1, 0, 0], [1, 0, 0]]), "axes must be orthogonal"),
])
def test_bad_input_is_one_line(call, message):
    with pytest.raises(UserError, match=message) as err:
        call()
    assert "\n" not in str(err.value)


def test_one_table_of_backends():
    assert tuple(BACKENDS) == ("fast", "mitsuba")
    assert check_backend("mitsuba") == "mitsuba"
    assert NUISANCE_PARAMETERS == ("photon_scale", "ambient", "dark", "albedo")


def test_direct_arrivals_are_the_wall_and_table_returns_per_zone():
    scene = denali_scene("A", "8in", 3)
    t, w, surface = direct_arrivals(scene, SENSOR, fidelity=FID)
    sub = resolve_fidelity(FID).zone_sub ** 2
    assert t.shape == w.shape == surface.shape == (9, sub)
    assert np.all(w[surface >= 0] > 0) and np.all(w[surface < 0] == 0)
    assert np.all((surface == 0).any(axis=1))  # every zone of the DENALI preset sees the relay wall
    # the direct part of the simulator is these arrivals binned: their total weight matches its light
    direct = expected_batch([scene], SENSOR.replace(dark_rate_hz=0.0, crosstalk=0.0, pileup=False, saturation=False),
                            fidelity=FID, dtype="float64", parts=True).parts["direct"][0]
    np.testing.assert_allclose(direct.reshape(9, -1).sum(-1), SENSOR.photon_scale * SENSOR.iterations * w.sum(-1),
                               rtol=0.02)
