"""Physics invariants of the fast transport.

Timing against geometric path length, 1/r^2 first-bounce falloff, the
three-bounce distance laws (Lambertian 1/d^4 with cosines, retroreflective
1/d^2), monotone decrease with distance, symmetry of a symmetric scene,
reciprocity of illumination and detection, and agreement of the first
bounce with the foundation's exact impulse binning.
"""

import math

import numpy as np
import pytest

from nlosplan.constants import C_M_PER_PS
from nlosplan.sensor_models import SensorConfig, preset
from nlosplan.simulators import FastSimulator, Fidelity, WallScene, corner_scene, simulate_wall
from nlosplan.simulators.scene import LidarPose, Rect, Scene

#: A narrow, long-window sensor with a symmetric (Gaussian) impulse response and no noise terms.
NARROW = SensorConfig(
    name="narrow", zones_rows=1, zones_cols=1, n_bins=256, bin_width_ps=100.0, start_offset_ps=0.0,
    fov_x_deg=2.0, fov_y_deg=2.0, flash_profile="uniform", pulse_fwhm_ps=150.0, photon_scale=1.0,
    iterations=1, saturation=False,
)
FID = Fidelity(zone_sub=4, flash_sub=4, flash_outer=0, object_samples=256, time_oversample=8)


def object_part(scene, sensor, fidelity=FID, **kw):
    return FastSimulator(scene, sensor, fidelity=fidelity, dtype="float64", **kw).expected(parts=True)["object"]


@pytest.mark.parametrize("reflectance", ["lambertian", "retroreflective"])
def test_three_bounce_peak_at_the_geometric_path_length(reflectance):
    x, y, d = 0.3, 0.4, 0.5
    scene = corner_scene(wall_distance=d, object_xy=(x, y), object_size=0.02, reflectance=reflectance,
                         lobe_fwhm_deg=0.5)
    h = object_part(scene, NARROW)[0, 0]
    path = 2 * d + 2 * math.hypot(x, y)  # LiDAR -> spot -> object -> spot -> LiDAR
    want = path / C_M_PER_PS / NARROW.bin_width_ps
    assert abs(int(np.argmax(h)) - math.floor(want)) <= 1
    centroid = (h * (np.arange(h.size) + 0.5)).sum() / h.sum()
    assert centroid == pytest.approx(want, abs=0.5)


def test_first_bounce_falls_as_one_over_distance_squared():
    s = preset("tmf8828-3x3-short").linear_uniform().replace(pulse_shape=None, pulse_fwhm_ps=150.0, n_bins=512,
                                                              saturation=False)
    totals = []
    for d in (0.5, 1.0):
        scene = corner_scene(wall_distance=d, wall_size=(6.0, 6.0)).without_objects()
        totals.append(FastSimulator(scene, s, fidelity=FID, dtype="float64").expected(parts=True)["direct"].sum())
    assert totals[0] / totals[1] == pytest.approx(4.0, rel=1e-9)


@pytest.mark.parametrize("reflectance, power", [("lambertian", 2), ("retroreflective", 1)])
def test_three_bounce_distance_law_with_cosines(reflectance, power):
    # a small patch facing the wall, lit through a 2 deg spot: each leg carries cos_w cos_x / d^2 = y^2 / d^4;
    # Lambertian paths have two legs, retroreflected paths one (the lobe returns where it came from)
    x = 0.3
    totals = {}
    for y in (1.0, 2.0):
        scene = corner_scene(wall_distance=0.5, object_xy=(x, y), object_size=0.01, reflectance=reflectance,
                             lobe_fwhm_deg=0.0, wall_size=(3.0, 3.0))
        totals[y] = object_part(scene, NARROW).sum()
    leg = {y: y**2 / (x * x + y * y) ** 2 for y in totals}
    assert totals[1.0] / totals[2.0] == pytest.approx((leg[1.0] / leg[2.0]) ** power, rel=1e-2)


@pytest.mark.parametrize("reflectance", ["lambertian", "retroreflective"])
def test_signal_decreases_monotonically_with_distance_from_the_lit_spot(reflectance):
    # along a ray from the lit spot the angles stay fixed and only the distance grows; (moving straight
    # away from the wall at a lateral offset first *raises* the cosines, so the signal can rise there)
    s = preset("tmf8828-3x3-short")
    fid = Fidelity(zone_sub=3, flash_sub=3, flash_outer=3, object_samples=128)
    totals = [object_part(corner_scene(object_xy=(0.6 * r, 0.8 * r), reflectance=reflectance), s, fid).sum()
              for r in (0.35, 0.5, 0.7, 1.0)]
    assert all(a > b > 0 for a, b in zip(totals, totals[1:])), totals


def test_mirror_symmetric_scene_gives_mirror_symmetric_zones():
    # object at the LiDAR's height on a wall centred there: the scene is symmetric top/bottom
    s = preset("tmf8828-3x3-short").linear_uniform()
    scene = corner_scene(object_xy=(0.45, 0.3), object_size=0.1, reflectance="lambertian")
    parts = FastSimulator(scene, s, fidelity=Fidelity(object_samples=2048), dtype="float64").expected(parts=True)
    np.testing.assert_allclose(parts["direct"][0], parts["direct"][2], rtol=1e-9)
    top, bottom = parts["object"][0], parts["object"][2]
    assert np.abs(top - bottom).sum() / top.sum() < 5e-3
    # and not left/right: the object is on the right
    assert parts["object"][:, 2].sum() > 1.2 * parts["object"][:, 0].sum()


def test_reciprocity_illumination_and_detection_grids_exchange():
    # uniform flash over exactly the field of view, flat sensitivity, one zone: the flash weight is the
    # detection weight / Omega, so every path x1 -> x -> x2 weighs the same as x2 -> x -> x1; exchanging
    # the illumination grid (flash_sub) and the detection grid (zone_sub) must give the same transient
    s = SensorConfig(zones_rows=1, zones_cols=1, n_bins=128, bin_width_ps=92.8, fov_x_deg=20.0, fov_y_deg=20.0,
                     flash_profile="uniform", pulse_fwhm_ps=200.0, iterations=1, saturation=False)
    scene = corner_scene(object_xy=(0.4, 0.25), reflectance="lambertian")
    a = object_part(scene, s, Fidelity(zone_sub=3, flash_sub=7, flash_outer=0, object_samples=128, time_oversample=8))
    b = object_part(scene, s, Fidelity(zone_sub=7, flash_sub=3, flash_outer=0, object_samples=128, time_oversample=8))
    assert a.sum() == pytest.approx(b.sum(), rel=1e-9)
    assert np.abs(a - b).sum() / a.sum() < 2e-3  # the node grids' sub-bin splitting differs per leg


def test_first_bounce_matches_the_exact_impulse_binning_of_the_wall_scene():
    s = preset("tmf8828-3x3-short").linear_uniform().replace(dark_rate_hz=0.0, ambient_rate_hz=0.0, saturation=False)
    wall = WallScene(distance_m=0.6, yaw_deg=20.0)
    exact = simulate_wall(wall, s, n_sub=4)
    n = wall.normal()
    u = np.cross([0.0, 1.0, 0.0], n)
    scene = Scene(lidar=LidarPose(position=(0, 0, 0), right=(1, 0, 0), up=(0, 1, 0), forward=(0, 0, 1)),
                  wall=Rect(center=(0, 0, 0.6), u_axis=u, v_axis=np.cross(n, u), half_u=50.0, half_v=50.0))
    fast = FastSimulator(scene, s, fidelity=Fidelity(zone_sub=4, time_oversample=16), dtype="float64").expected()
    assert fast.sum() == pytest.approx(exact.sum(), rel=1e-9)
    assert np.abs(fast - exact).sum() / exact.sum() < 1e-3
