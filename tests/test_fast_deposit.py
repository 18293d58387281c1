"""The deposit onto the node grid: the compiled kernel and the windowed scatter (issue 20) equal the two scalar
scatters of before, values and derivatives."""

import numpy as np
import pytest

from nlosplan._jax import jax, jnp
from nlosplan.errors import UserError
from nlosplan.sensor_models.presets import resolve_sensor
from nlosplan.sensor_models.transient import deposit_at, deposit_method
from nlosplan.simulators import FastSimulator, denali_scene


def test_methods_agree_on_random_arrivals_incl_off_grid_and_gradients():
    rng = np.random.default_rng(3)
    pos = jnp.asarray(rng.uniform(-5.0, 45.0, 2000))  # some off the grid on both sides
    w = jnp.asarray(rng.uniform(0.0, 1.0, 2000))
    rows = jnp.asarray(rng.integers(0, 7, 2000))
    out = {}
    for m in ("kernel", "window", "scatter"):
        with deposit_method(m):
            out[m] = np.asarray(deposit_at(pos, w, rows, 7, 40))
            g = jax.grad(lambda p: (deposit_at(p, w, rows, 7, 40) * jnp.arange(40.0)).sum())(pos)
            out[m + "_grad"] = np.asarray(g)
    for m in ("kernel", "window"):
        np.testing.assert_allclose(out[m], out["scatter"], rtol=1e-6, atol=1e-12)
        np.testing.assert_allclose(out[m + "_grad"], out["scatter_grad"], rtol=1e-6, atol=1e-12)
    # an arrival between the first and the last node keeps all its weight and its mean position
    inside = (np.asarray(pos) >= 0) & (np.asarray(pos) <= 39)
    with deposit_method("window"):
        grid = np.asarray(deposit_at(pos[inside], w[inside], rows[inside], 7, 40), np.float64)
    wi, pi = np.asarray(w)[inside], np.asarray(pos)[inside]
    assert grid.sum() == pytest.approx(wi.sum(), rel=1e-6)
    assert (grid * np.arange(40)).sum() == pytest.approx((wi * pi).sum(), rel=1e-6)
    with pytest.raises(ValueError, match="deposit method 'dense'"):
        with deposit_method("dense"):
            pass


@pytest.mark.parametrize("options", [{}, {"albedo": 0.36, "diffuse_albedo": 0.2},
                                     pytest.param({"albedo": 0.36, "diffuse_albedo": 0.2, "mount": True},
                                                  marks=pytest.mark.slow)],   # 49 s; CI runs it
                         ids=["retroreflective", "mixed", "mixed+mount"])
def test_simulator_new_deposit_equals_old_on_denali_scenes(options):
    sensor = resolve_sensor("tmf8828-3x3-short")
    scenes = [denali_scene(o, s, p, **options) for o, s, p in (("A", "8in", 0), ("circle", "4in", 47), ("3", "8in", 99))]
    old = FastSimulator(scenes, sensor, fidelity="draft", deposit="scatter").expected(parts=True)
    for method in ("kernel", "window"):
        new = FastSimulator(scenes, sensor, fidelity="draft", deposit=method).expected(parts=True)
        for part in ("counts", "object", "direct"):
            a, b = np.asarray(new[part], np.float64), np.asarray(old[part], np.float64)
            assert np.abs(b).max() > 0
            assert np.abs(a - b).sum() / np.abs(b).sum() < 1e-5, (method, part)
            assert np.abs(a - b).max() / np.abs(b).max() < 1e-5, (method, part)


def test_unknown_deposit_is_a_user_error():
    with pytest.raises(UserError, match="deposit='dense' is not supported; allowed: kernel, window, scatter"):
        FastSimulator(denali_scene("A", "8in", 0), resolve_sensor("tmf8828-3x3-short"), fidelity="draft",
                      deposit="dense")
