"""Leaving out what a scene does not need changes nothing (1e-6 relative) and does less work."""

import numpy as np
import pytest

from nlosplan.sensor_models import SensorConfig, preset
from nlosplan.simulators import FastSimulator, Fidelity, corner_scene, denali_scene, explain

FID = Fidelity(zone_sub=3, flash_sub=3, flash_outer=3, object_samples=128, time_oversample=4)
S3 = preset("tmf8828-3x3-short").linear_uniform()  # the pruning checks compare linear parts


def run(scene, sensor=S3, **kw):
    sim = FastSimulator(scene, sensor, fidelity=FID, dtype="float64", **kw)
    return sim.expected(), sim.plan


def object_part(scene, sensor=S3, **kw):
    return FastSimulator(scene, sensor, fidelity=FID, dtype="float64", **kw).expected(parts=True)["object"]


def rel(a, b):
    return float(np.abs(a - b).max() / np.abs(b).max())


@pytest.mark.parametrize("scene", [
    denali_scene("A", "8in", 19),  # back faces, flash cells beyond the lobe's reach, lights off
    denali_scene("circle", "4in", 77, lights="on", reflectance="lambertian"),
    corner_scene(object_xy=(0.5, 0.3), reflectance="retroreflective", lobe_fwhm_deg=0.0),
], ids=["denali-retro", "denali-lambertian-lights-on", "corner-retro-no-lobe"])
def test_pruned_equals_full(scene):
    pruned, plan_p = run(scene)
    full, plan_f = run(scene, prune=False)
    assert rel(pruned, full) < 1e-6
    # the three-bounce part on its own (the direct peak would hide a difference there)
    assert rel(object_part(scene), object_part(scene, prune=False)) < 1e-6
    assert plan_p.paths < plan_f.paths
    assert any(not t.computed for t in plan_p.terms)


def test_only_the_requested_zone():
    scene = denali_scene("S", "8in", 45)
    full, _ = run(scene)
    centre, plan = run(scene, zones=[(1, 1)])
    assert centre.shape == (1, 128)
    assert rel(centre[0], full[1, 1]) < 1e-6
    assert any(t.name == "zones" and "1 of 9" in t.reason for t in plan.terms)
    two, _ = run(scene, zones=[(0, 2), (2, 0)])
    assert rel(two, np.stack([full[0, 2], full[2, 0]])) < 1e-6


def test_object_outside_the_time_window_is_left_out_and_changes_nothing():
    # a 60-bin window ends before any three-bounce light of an object 0.9 m from the wall arrives
    s = S3.replace(n_bins=60)
    scene = corner_scene(object_xy=(0.9, 0.9), reflectance="lambertian")
    pruned, plan = run(scene, s)
    full, _ = run(scene, s, prune=False)
    background, _ = run(scene.without_objects(), s)
    assert not plan.static.objects
    assert any("outside the time window" in t.reason for t in plan.terms)
    assert rel(pruned, full) < 1e-12 and rel(pruned, background) < 1e-12


def test_zones_that_see_the_object_only_after_the_window_are_left_out():
    # wide field of view, short window: near zones see the three-bounce light in time, far ones do not
    s = SensorConfig(zones_rows=1, zones_cols=4, n_bins=64, bin_width_ps=100.0, fov_x_deg=90.0, fov_y_deg=10.0,
                     flash_profile="uniform", pulse_fwhm_ps=150.0, iterations=1, saturation=False)
    scene = corner_scene(wall_distance=0.3, object_xy=(0.9, 0.25), reflectance="lambertian", wall_size=(4.0, 1.0))
    pruned, plan = run(scene, s)
    full, _ = run(scene, s, prune=False)
    assert plan.static.objects and plan.static.objects[0].n_rows < 4
    assert any("after the window" in t.reason for t in plan.terms)
    assert rel(pruned, full) < 1e-6


def test_lights_off_leaves_out_ambient_and_jitter_zero_the_gaussian():
    scene = denali_scene("A", "8in", 0, lights="off")
    text = explain(scene, S3).explain()
    assert "left out  ambient light" in text and "lights off" in text
    assert "impulse response: Gaussian" in text
    on = explain(denali_scene("A", "8in", 0, lights="on"), S3.replace(jitter_fwhm_ps=50.0)).explain()
    assert "computed  ambient light" in on and "computed  impulse response" in on
    a, _ = run(denali_scene("A", "8in", 0, lights="on"))
    b, _ = run(scene)
    ambient = S3.ambient_rate_hz * S3.bin_width_ps * 1e-12 * S3.iterations
    np.testing.assert_allclose(a - b, ambient, rtol=1e-6)


def test_explain_is_json_friendly():
    import json

    d = explain(denali_scene(), S3).to_dict()
    json.dumps(d)
    assert {t["name"] for t in d["computed"]} >= {"first bounce: relay wall", "object 'A_8in'"}
    assert d["paths_per_scene"] > 0
