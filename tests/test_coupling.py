"""Point-to-wall-cell coupling: exact Lambert form factor and the midpoint kernel."""

import numpy as np
import pytest

from nlosplan._jax import jax, jnp
from nlosplan.simulators.fast.coupling import _angle, far_coupling, polygon_coupling

N_W = np.array([0.0, 0.0, 1.0])  # wall plane z = 0, lit side up


def quad(x0, x1, y0, y1):
    return np.array([[x0, y0, 0.0], [x1, y0, 0.0], [x1, y1, 0.0], [x0, y1, 0.0]])


def brute(x, n, x0, x1, y0, y1, k=1200):
    g = (np.arange(k) + 0.5) / k
    xx, yy = np.meshgrid(x0 + (x1 - x0) * g, y0 + (y1 - y0) * g)
    cells = np.stack([xx.ravel(), yy.ravel(), 0 * xx.ravel()])
    c, _ = far_coupling(cells, np.full(k * k, (x1 - x0) * (y1 - y0) / k**2), x[None], n[None], np.array([x[2]]))
    return float(np.sum(c))


def exact(x, n, corners):
    return float(polygon_coupling(np.asarray(x)[None], np.asarray(n)[None], np.asarray(corners)[None])[0, 0])


def test_integral_over_a_plane_is_pi_even_1mm_away():
    x, n = np.array([0.0, 0.0, 0.001]), np.array([0.0, 0.0, -1.0])
    assert exact(x, n, quad(-100, 100, -100, 100)) == pytest.approx(np.pi, rel=1e-6)
    # the midpoint rule on one 1 m cell explodes like area / h^2
    c, _ = far_coupling(np.zeros((3, 1)), np.array([1.0]), x[None], n[None], np.array([0.001]))
    assert float(c[0, 0]) > 1e5


@pytest.mark.parametrize(
    "x, n",
    [
        ([0.1, 0.05, 0.2], [0.3, -0.2, -0.9]),  # oblique, whole cell in front
        ([0.0, 0.0, 0.02], [1.0, 0.0, 0.0]),  # normal parallel to the wall: half the cell clipped
        ([0.0, 0.0, 0.02], [0.6, 0.0, -0.8]),
        ([0.03, -0.01, 0.01], [-0.6, 0.3, -0.4]),
    ],
)
def test_polygon_matches_brute_force_integration(x, n):
    x, n = np.array(x), np.array(n) / np.linalg.norm(n)
    box = (-0.05, 0.07, -0.04, 0.09)
    assert exact(x, n, quad(*box)) == pytest.approx(brute(x, n, *box), rel=2e-5)


def test_facing_away_and_behind_give_zero():
    corners = quad(-0.05, 0.05, -0.05, 0.05)
    assert exact([0, 0, 0.02], [0, 0, 1.0], corners) == 0.0
    c, _ = far_coupling(np.zeros((3, 1)), np.array([0.01]), np.array([[0.0, 0.0, -0.1]]), np.array([[0.0, 0.0, 1.0]]),
                        np.array([-0.1]))
    assert float(c[0, 0]) == 0.0


def test_midpoint_kernel_agrees_far_away():
    x, n = np.array([0.0, 0.0, 0.5]), np.array([0.0, 0.0, -1.0])
    c, d = far_coupling(np.zeros((3, 1)), np.array([1e-4]), x[None], n[None], np.array([0.5]))
    assert float(c[0, 0]) == pytest.approx(exact(x, n, quad(-0.005, 0.005, -0.005, 0.005)), rel=1e-3)
    assert float(d[0, 0]) == pytest.approx(0.5)


def test_gradient_finite_1mm_from_the_wall():
    corners = jnp.asarray(quad(-0.05, 0.05, -0.05, 0.05))[None]

    def f(z, nx):
        n = jnp.array([nx, 0.0, -1.0]) / jnp.sqrt(1 + nx * nx)
        return polygon_coupling(jnp.array([[0.0, 0.0, z]]), n[None], corners)[0, 0]

    g = jax.grad(f, argnums=(0, 1))(0.001, 0.0)
    assert np.all(np.isfinite(np.array(g)))
    fd = (f(0.0011, 0.0) - f(0.0009, 0.0)) / 0.0002
    assert float(g[0]) == pytest.approx(float(fd), rel=1e-3)


def _angles_case():
    rng = np.random.default_rng(3)
    y = np.abs(rng.standard_normal(20000)) * 10.0 ** rng.uniform(-8, 3, 20000)
    x = rng.standard_normal(20000) * 10.0 ** rng.uniform(-8, 3, 20000)
    # axes, the diagonal, both signs of zero, tiny and equal magnitudes, the tan(pi/8) reduction bound
    y = np.concatenate([y, [0.0, 0.0, 1.0, 1.0, 1e-20, 3.0, 0.0, 0.41421356, 0.41421357, 2.0]]).astype(np.float32)
    x = np.concatenate([x, [1.0, -1.0, 0.0, -0.0, 1e-20, 3.0, 0.0, 1.0, 1.0, -2.0]]).astype(np.float32)
    return y, x


def test_float32_angle_is_atan2_to_float32_rounding():
    y, x = _angles_case()
    exact = np.arctan2(y.astype(np.float64), x.astype(np.float64))
    raw = jax.jit(_angle)(jnp.asarray(y), jnp.asarray(x))
    assert raw.dtype == jnp.float32
    got = np.asarray(raw, np.float64)
    assert np.all(np.isfinite(got))
    assert np.max(np.abs(got - exact)) < 3e-7  # numpy's own float32 arctan2 is off by up to ~3e-7 here
    assert got[-10] == 0.0 and got[-9] == pytest.approx(np.pi, abs=3e-7) and got[-8] == pytest.approx(np.pi / 2, abs=2e-7)
    # float64 keeps jnp.arctan2
    y64, x64 = y.astype(np.float64), x.astype(np.float64)
    np.testing.assert_array_equal(np.asarray(_angle(jnp.asarray(y64), jnp.asarray(x64))), np.asarray(jnp.arctan2(y64, x64)))


def test_float32_angle_derivative_is_atan2s():
    y, x = _angles_case()
    y, x = y[:2000], x[:2000]
    g = jax.jit(jax.vmap(jax.grad(_angle, argnums=(0, 1))))(jnp.asarray(y), jnp.asarray(x))
    r2 = y.astype(np.float64) ** 2 + x.astype(np.float64) ** 2
    for got, want in zip(g, (x / r2, -y / r2)):
        got = np.asarray(got, np.float64)
        assert np.all(np.isfinite(got))
        np.testing.assert_allclose(got, want, rtol=2e-5, atol=1e-30)


def test_polygon_coupling_in_float32_matches_float64():
    rng = np.random.default_rng(5)
    x = np.column_stack([rng.uniform(-0.1, 0.1, 64), rng.uniform(-0.1, 0.1, 64), rng.uniform(1e-3, 0.2, 64)])
    n = rng.standard_normal((64, 3))
    n[:, 2] = -np.abs(n[:, 2])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    corners = np.stack([quad(-0.05, 0.07, -0.04, 0.09), quad(0.1, 0.2, 0.0, 0.05), quad(-0.01, 0.01, -0.01, 0.01)])
    want = np.asarray(polygon_coupling(x, n, corners))
    got = np.asarray(polygon_coupling(*(jnp.asarray(a, jnp.float32) for a in (x, n, corners))), np.float64)
    assert want.min() >= 0 and want.max() > 0.1
    np.testing.assert_allclose(got, want, rtol=2e-5, atol=2e-6 * want.max())
