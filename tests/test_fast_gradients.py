"""Gradients of the fast simulator against central finite differences (float64).

The loss is a fixed random weighting of all zone-bin counts, so every bin's
derivative takes part.
"""

import numpy as np
import pytest

from nlosplan._jax import jax, jnp
from nlosplan.sensor_models import preset
from nlosplan.simulators import FastSimulator, Fidelity, corner_scene, denali_scene
from nlosplan.simulators.fast.simulator import to_jax

FID = Fidelity(zone_sub=3, flash_sub=3, flash_outer=3, object_samples=128, time_oversample=4)


def setup(scene, sensor):
    sim = FastSimulator(scene, sensor, fidelity=FID, dtype="float64")
    sc, sp = sim.params()
    sc = jax.tree_util.tree_map(lambda a: a[0], to_jax(sc, jnp.float64))
    sp = jax.tree_util.tree_map(lambda a: a[0], to_jax(sp, jnp.float64))
    f = sim.function()
    weights = jnp.asarray(np.random.default_rng(0).uniform(0.5, 1.5, (sensor.n_zones, sensor.n_bins)))
    return f, sc, sp, weights


def with_shift(sc, shift):
    obj = dict(sc["objects"][0])
    obj["to_world"] = obj["to_world"].at[:3, 3].add(shift)
    return {**sc, "objects": [obj] + list(sc["objects"][1:])}


SCENES = {
    "denali-retro": lambda: denali_scene("A", "8in", 19),
    "corner-lambertian": lambda: corner_scene(object_xy=(0.45, 0.3), reflectance="lambertian"),
    "corner-retro-no-lobe": lambda: corner_scene(object_xy=(0.45, 0.3), reflectance="retroreflective",
                                                 lobe_fwhm_deg=0.0),
}
SENSOR = preset("tmf8828-3x3-short").replace(pulse_shape=None, pulse_fwhm_ps=180.0, jitter_fwhm_ps=100.0,
                                             saturation=False, dark_rate_hz=0.0)


@pytest.mark.parametrize("name", [pytest.param(n, marks=pytest.mark.slow) if n == "corner-lambertian" else n
                                  for n in sorted(SCENES)])  # Lambertian: ~30 s (the full double integral)
def test_gradient_wrt_object_position_matches_finite_differences(name):
    f, sc, sp, wts = setup(SCENES[name](), SENSOR)

    def loss(shift):
        return jnp.sum(f(with_shift(sc, shift), sp) * wts)

    g = np.asarray(jax.grad(loss)(jnp.zeros(3)))
    h = 2e-5
    fd = np.array([(loss(jnp.eye(3)[i] * h) - loss(-jnp.eye(3)[i] * h)) / (2 * h) for i in range(3)])
    assert np.all(np.isfinite(g))
    np.testing.assert_allclose(g, fd, rtol=2e-3, atol=2e-3 * np.abs(fd).max())


@pytest.mark.parametrize("field, step", [("jitter_fwhm_ps", 0.05), ("pulse_fwhm_ps", 0.05),
                                         ("bin_width_ps", 1e-3), ("photon_scale", 1e-4), ("start_offset_ps", 0.01)])
def test_gradient_wrt_sensor_parameters_matches_finite_differences(field, step):
    f, sc, sp, wts = setup(SCENES["denali-retro"](), SENSOR)

    def loss(v):
        return jnp.sum(f(sc, {**sp, field: v}) * wts)

    v0 = sp[field]
    g = float(jax.grad(loss)(v0))
    fd = float((loss(v0 + step) - loss(v0 - step)) / (2 * step))
    assert np.isfinite(g) and g == pytest.approx(fd, rel=2e-3)


def test_gradient_at_zero_jitter_is_finite_and_zero():
    f, sc, sp, wts = setup(SCENES["denali-retro"](), SENSOR.replace(jitter_fwhm_ps=0.0, pulse_fwhm_ps=0.0))
    g = jax.grad(lambda j: jnp.sum(f(sc, {**sp, "jitter_fwhm_ps": j}) * wts))(jnp.float64(0.0))
    assert float(g) == 0.0  # blur variance grows as jitter^2: no first-order change at 0


def test_vmap_over_positions_equals_the_batch():
    scenes = [denali_scene("A", "8in", p) for p in (3, 50)]
    sim = FastSimulator(scenes, SENSOR, fidelity=FID, dtype="float64")
    sc, sp = sim.params()
    sc, sp = to_jax(sc, jnp.float64), jax.tree_util.tree_map(lambda a: a[0], to_jax(sp, jnp.float64))
    v = jax.vmap(lambda q: sim.function()(q, sp))(sc)
    np.testing.assert_allclose(np.asarray(v).reshape(2, 3, 3, -1), sim.expected(), rtol=1e-10, atol=1e-9)
