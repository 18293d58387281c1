"""Zone geometry: solid angles, flash profile normalisation, sub-rays."""

from __future__ import annotations

import math

import numpy as np
import pytest

from nlosplan.sensor_models.config import SensorConfig
from nlosplan.sensor_models.zones import (
    flash_intensity,
    solid_angle_rect,
    zone_edges_tan,
    zone_rays,
    zone_solid_angles,
)


def _full_rect(sensor):
    tu = math.tan(math.radians(sensor.fov_x_deg) / 2)
    tv = math.tan(math.radians(sensor.fov_y_deg) / 2)
    return float(solid_angle_rect(-tu, tu, -tv, tv))


# ---------------------------------------------------------------- solid angles
def test_solid_angle_known_values():
    # a full 90 x 90 degree square (tan = +-1) is one sixth of the sphere (a cube face)
    assert float(solid_angle_rect(-1, 1, -1, 1)) == pytest.approx(4 * math.pi / 6, rel=1e-14)
    # quadrant symmetry and bound order do not matter
    a = float(solid_angle_rect(0, 1, 0, 1))
    assert a == pytest.approx(4 * math.pi / 24, rel=1e-14)
    assert float(solid_angle_rect(1, 0, 1, 0)) == pytest.approx(a, rel=1e-15)
    # a half-space in the limit
    assert float(solid_angle_rect(-1e8, 1e8, -1e8, 1e8)) == pytest.approx(2 * math.pi, rel=1e-6)
    assert float(solid_angle_rect(0.3, 0.3, -1, 1)) == 0.0


def test_solid_angle_is_additive():
    u = np.array([-0.7, 0.1, 0.4])
    v = np.array([-0.2, 0.5, 1.3])
    whole = solid_angle_rect(u[0], u[2], v[0], v[2])
    parts = sum(solid_angle_rect(u[i], u[i + 1], v[j], v[j + 1]) for i in range(2) for j in range(2))
    assert float(parts) == pytest.approx(float(whole), rel=1e-13)


@pytest.mark.parametrize("u, v", [(0.0, 0.0), (0.5, -0.3), (-2.0, 1.5), (10.0, 3.0)])
def test_tiny_rectangle_is_area_times_cosine_cubed(u, v):
    d = 1e-4
    omega = float(solid_angle_rect(u - d / 2, u + d / 2, v - d / 2, v + d / 2))
    assert omega == pytest.approx(d * d / (1 + u * u + v * v) ** 1.5, rel=1e-5)


@pytest.mark.parametrize("rows, cols", [(1, 1), (3, 3), (4, 8), (16, 16)])
@pytest.mark.parametrize("fov", [(1.0, 1.0), (33.0, 32.0), (120.0, 90.0), (169.0, 160.0)])
def test_zone_solid_angles_sum_to_fov(rows, cols, fov):
    s = SensorConfig(zones_rows=rows, zones_cols=cols, fov_x_deg=fov[0], fov_y_deg=fov[1])
    om = zone_solid_angles(s)
    assert om.shape == (rows, cols)
    assert np.all(np.isfinite(om)) and np.all(om > 0)
    assert om.sum() == pytest.approx(_full_rect(s), rel=1e-12)


def test_zone_edges_orientation():
    s = SensorConfig(zones_rows=2, zones_cols=4, fov_x_deg=90.0, fov_y_deg=60.0)
    ue, ve = zone_edges_tan(s)
    np.testing.assert_allclose(ue, [-1, -0.5, 0, 0.5, 1], atol=1e-15)
    np.testing.assert_allclose(ve, [math.tan(math.radians(30)), 0, -math.tan(math.radians(30))], atol=1e-15)


def test_centre_zone_is_largest_and_solid_angles_symmetric():
    s = SensorConfig(zones_rows=5, zones_cols=7, fov_x_deg=100.0, fov_y_deg=80.0)
    om = zone_solid_angles(s)
    assert np.unravel_index(np.argmax(om), om.shape) == (2, 3)
    np.testing.assert_allclose(om, om[::-1, :], rtol=1e-13)
    np.testing.assert_allclose(om, om[:, ::-1], rtol=1e-13)


# --------------------------------------------------------------------- flash
def _hemisphere_integral(sensor, n_theta=1200, n_phi=2400):
    """Midpoint rule in spherical coordinates (independent of the package's grid)."""
    th = (np.arange(n_theta) + 0.5) * (math.pi / 2) / n_theta
    ph = (np.arange(n_phi) + 0.5) * (2 * math.pi) / n_phi
    dth, dph = (math.pi / 2) / n_theta, 2 * math.pi / n_phi
    total = 0.0
    for chunk in np.array_split(np.arange(n_theta), 8):
        t = th[chunk][:, None]
        dirs = np.stack(
            [np.sin(t) * np.cos(ph), np.sin(t) * np.sin(ph), np.cos(t) * np.ones_like(ph)], axis=-1
        )
        total += float(np.sum(flash_intensity(sensor, dirs) * np.sin(t))) * dth * dph
    return total


@pytest.mark.parametrize(
    "kw",
    [
        dict(flash_profile="gaussian"),
        dict(flash_profile="gaussian", flash_fwhm_x_deg=60.0, flash_fwhm_y_deg=10.0),
        dict(flash_profile="gaussian", flash_fwhm_x_deg=120.0, flash_fwhm_y_deg=100.0),
        dict(flash_profile="gaussian", flash_fwhm_x_deg=360.0, flash_fwhm_y_deg=360.0),
        dict(flash_profile="uniform"),
        dict(flash_profile="uniform", fov_x_deg=120.0, fov_y_deg=60.0),
    ],
    ids=["gauss-default", "gauss-elliptic", "gauss-wide", "gauss-360", "uniform", "uniform-wide"],
)
def test_flash_intensity_integrates_to_one_over_hemisphere(kw):
    s = SensorConfig(**kw)
    assert _hemisphere_integral(s) == pytest.approx(1.0, abs=1e-3)


@pytest.mark.parametrize("fwhm", [1.0, 0.5, 0.2, 0.1, 0.05])
def test_narrow_gaussian_flash_is_normalised(fwhm):
    """Small-angle limit: the on-axis intensity of a unit-power beam is 1 / (2 pi s_x s_y).

    The validator allows any FWHM in (0, 360] degrees; a collimated (sub-degree)
    beam must still carry unit power.
    """
    s = SensorConfig(flash_fwhm_x_deg=fwhm, flash_fwhm_y_deg=fwhm)
    sigma = math.radians(fwhm) / 2.3548200450309493
    on_axis = float(flash_intensity(s, np.array([0.0, 0.0, 1.0])))
    assert on_axis * 2 * math.pi * sigma * sigma == pytest.approx(1.0, rel=1e-3)


def test_flash_intensity_values():
    s = SensorConfig(flash_profile="uniform", fov_x_deg=90.0, fov_y_deg=90.0)
    dirs = np.array([[0, 0, 1.0], [0.5, 0.5, 1.0], [2.0, 0, 1.0], [0, 0, -1.0], [1, 0, 0.0]])
    dirs /= np.linalg.norm(dirs, axis=-1, keepdims=True)
    got = flash_intensity(s, dirs)
    np.testing.assert_allclose(got, [1 / (4 * math.pi / 6)] * 2 + [0.0, 0.0, 0.0], rtol=1e-14)
    g = SensorConfig(flash_profile="gaussian", flash_fwhm_x_deg=30.0, flash_fwhm_y_deg=30.0)
    # half maximum at 15 degrees off axis along x
    on = flash_intensity(g, np.array([0, 0, 1.0]))
    off = flash_intensity(g, np.array([math.sin(math.radians(15)), 0, math.cos(math.radians(15))]))
    assert float(off / on) == pytest.approx(0.5, rel=1e-12)
    assert float(flash_intensity(g, np.array([0, 0, -1.0]))) == 0.0


# ------------------------------------------------------------------ symmetry
def _zone_weights(sensor, n_sub=4):
    r = zone_rays(sensor, n_sub)
    return np.sum(r.solid_angle * r.sensitivity * r.flash, axis=-1)


@pytest.mark.parametrize("profile", ["gaussian", "uniform"])
@pytest.mark.parametrize("rows, cols", [(3, 3), (4, 6), (8, 8)])
def test_symmetric_sensor_gives_symmetric_zone_weights(profile, rows, cols):
    s = SensorConfig(
        zones_rows=rows, zones_cols=cols, fov_x_deg=60.0, fov_y_deg=45.0,
        flash_profile=profile, flash_fwhm_x_deg=40.0, flash_fwhm_y_deg=25.0, sensitivity_cos_power=2.0,
    )
    w = _zone_weights(s)
    assert np.all(w > 0)
    np.testing.assert_allclose(w, w[::-1, :], rtol=1e-12)  # up-down
    np.testing.assert_allclose(w, w[:, ::-1], rtol=1e-12)  # left-right
    if profile == "gaussian" and rows % 2 == 0 and cols % 2 == 0:
        # centre zones are brighter than the corners
        assert w[rows // 2, cols // 2] > w[0, 0]


def test_zone_rays_directions_are_unit_and_ordered():
    s = SensorConfig(zones_rows=2, zones_cols=2, fov_x_deg=40.0, fov_y_deg=40.0)
    r = zone_rays(s, 3)
    assert r.directions.shape == (2, 2, 9, 3)
    np.testing.assert_allclose(np.linalg.norm(r.directions, axis=-1), 1.0, rtol=1e-15)
    assert np.all(r.directions[..., 2] > 0)
    # row 0 is the top (v > 0), column 0 the left (u < 0)
    assert np.all(r.directions[0, :, :, 1] > 0) and np.all(r.directions[1, :, :, 1] < 0)
    assert np.all(r.directions[:, 0, :, 0] < 0) and np.all(r.directions[:, 1, :, 0] > 0)
    # sensitivity cos^0 = 1
    np.testing.assert_array_equal(r.sensitivity, 1.0)


def test_sensitivity_is_cos_power():
    s = SensorConfig(fov_x_deg=80.0, fov_y_deg=80.0, sensitivity_cos_power=3.0)
    r = zone_rays(s, 2)
    np.testing.assert_allclose(r.sensitivity, r.directions[..., 2] ** 3, rtol=1e-15)
    assert np.all(r.sensitivity <= 1.0)


@pytest.mark.parametrize("n_sub", [1, 2, 5])
@pytest.mark.parametrize("rows, cols", [(1, 1), (3, 5), (16, 16)])
def test_zone_rays_solid_angles_sum_to_zone(n_sub, rows, cols):
    s = SensorConfig(zones_rows=rows, zones_cols=cols, fov_x_deg=70.0, fov_y_deg=50.0)
    r = zone_rays(s, n_sub)
    assert r.solid_angle.shape == (rows, cols, n_sub * n_sub)
    np.testing.assert_allclose(r.solid_angle.sum(axis=-1), zone_solid_angles(s), rtol=1e-12)


def test_zone_rays_flash_integral_converges():
    """With a uniform flash the zone-ray integral of the flash over the FoV is exactly 1."""
    s = SensorConfig(zones_rows=4, zones_cols=4, flash_profile="uniform", fov_x_deg=50.0, fov_y_deg=30.0)
    r = zone_rays(s, 3)
    assert float(np.sum(r.solid_angle * r.flash)) == pytest.approx(1.0, rel=1e-12)
    # gaussian flash much wider than the FoV: close to flat over the zones
    g = SensorConfig(zones_rows=4, zones_cols=4, fov_x_deg=10.0, fov_y_deg=10.0, flash_fwhm_x_deg=360.0, flash_fwhm_y_deg=360.0)
    rg = zone_rays(g, 3)
    assert rg.flash.max() / rg.flash.min() < 1.01


def test_zone_rays_rejects_bad_n_sub():
    with pytest.raises(ValueError):
        zone_rays(SensorConfig(), 0)


@pytest.mark.parametrize("profile", ["gaussian", "uniform"])
@pytest.mark.parametrize("rows, cols", [(1, 1), (16, 16)])
@pytest.mark.parametrize("fov", [1.0, 120.0])
def test_extreme_configurations_finite_positive(profile, rows, cols, fov):
    s = SensorConfig(zones_rows=rows, zones_cols=cols, fov_x_deg=fov, fov_y_deg=fov, flash_profile=profile,
                     sensitivity_cos_power=1.0)
    om = zone_solid_angles(s)
    r = zone_rays(s, 2)
    for a in (om, r.solid_angle, r.sensitivity, r.flash, r.directions[..., 2]):
        assert np.all(np.isfinite(a)) and np.all(a > 0)
    np.testing.assert_allclose(r.solid_angle.sum(), _full_rect(s), rtol=1e-12)
