"""The node grid: deposits keep mass and mean time; node-to-bin matrix equals exact binning."""

import numpy as np
import pytest

from nlosplan._jax import jax, jnp
from nlosplan.sensor_models import SensorConfig, bin_arrivals, preset
from nlosplan.sensor_models.pipeline import pulse_boxes
from nlosplan.sensor_models.transient import (
    TimeGrid,
    bin_nodes_without_irf,
    deposit,
    irf_extent_ps,
    irf_matrix,
)


def _matrix(grid, s, dtype=np.float64):
    return irf_matrix(grid, bin_width_ps=jnp.asarray(s.bin_width_ps, dtype), sigma_ps=jnp.asarray(s.impulse_sigma_ps, dtype),
                      pulse=pulse_boxes(s), extent_ps=irf_extent_ps(s), nominal_bin_width_ps=s.bin_width_ps)


@pytest.fixture(scope="module")
def sensor():
    return preset("tmf8828-3x3-short").replace(jitter_fwhm_ps=120.0)


def test_deposit_keeps_mass_and_mean_time(sensor):
    grid = TimeGrid.for_sensor(sensor, 0.0, 20000.0, oversample=4)
    rng = np.random.default_rng(0)
    t = rng.uniform(1000.0, 9000.0, 2000)
    w = rng.uniform(0.0, 1.0, 2000)
    nodes = np.asarray(deposit(grid, t, w, None, 1, bin_width_ps=sensor.bin_width_ps,
                               start_offset_ps=sensor.start_offset_ps))[0]
    nt = np.asarray(grid.node_times(sensor.bin_width_ps, sensor.start_offset_ps))
    assert nodes.sum() == pytest.approx(w.sum(), rel=1e-12)
    assert (nodes * nt).sum() / nodes.sum() == pytest.approx((w * t).sum() / w.sum(), rel=1e-12)
    assert np.all(nodes >= 0)


def test_deposit_rows_and_dropping(sensor):
    grid = TimeGrid.for_sensor(sensor, 0.0, 5000.0, oversample=2)
    nt = np.asarray(grid.node_times(sensor.bin_width_ps, sensor.start_offset_ps))
    t = np.array([nt[3], nt[5], 1e9, -1e9])
    out = np.asarray(deposit(grid, t, np.array([1.0, 2.0, 5.0, 7.0]), np.array([0, 1, 1, 0]), 2,
                             bin_width_ps=sensor.bin_width_ps, start_offset_ps=sensor.start_offset_ps))
    assert out[0, 3] == pytest.approx(1.0) and out[1, 5] == pytest.approx(2.0)
    assert out.sum() == pytest.approx(3.0)  # far-off arrivals are dropped, not wrapped


@pytest.mark.parametrize("jitter", [0.0, 120.0, 3000.0])
def test_node_matrix_equals_exact_binning_of_node_impulses(sensor, jitter):
    s = sensor.replace(jitter_fwhm_ps=jitter)
    grid = TimeGrid.for_sensor(s, 0.0, 20000.0, oversample=4)
    nt = np.asarray(grid.node_times(s.bin_width_ps, s.start_offset_ps))
    idx = np.array([50, 51, 300, 310])
    w = np.array([1e7, 3.0, 10.0, 2.0])
    nodes = deposit(grid, nt[idx], w, None, 1, bin_width_ps=s.bin_width_ps, start_offset_ps=s.start_offset_ps)
    h = np.asarray(nodes @ _matrix(grid, s))[0]
    ref = np.asarray(bin_arrivals(nt[idx], w, s.bin_edges_ps(), s.impulse_sigma_ps, pulse_boxes(s)))
    big = ref > 1e-10 * ref.max()  # below, both are rounding-level (< 1e-13 absolute)
    np.testing.assert_allclose(h, ref, rtol=0, atol=1e-12 * ref.max())
    np.testing.assert_allclose(h[big], ref[big], rtol=1e-9)
    assert h.sum() == pytest.approx(ref.sum(), rel=1e-12)


def test_float32_keeps_a_small_return_beside_a_huge_peak(sensor):
    grid = TimeGrid.for_sensor(sensor, 0.0, 20000.0, oversample=4)
    nt = np.asarray(grid.node_times(sensor.bin_width_ps, sensor.start_offset_ps))
    t, w = nt[[50, 300]], np.array([1e7, 10.0])
    out = {}
    for dt in (np.float32, np.float64):
        nodes = deposit(grid, t.astype(dt), w.astype(dt), None, 1, bin_width_ps=dt(sensor.bin_width_ps),
                        start_offset_ps=dt(sensor.start_offset_ps))
        out[dt] = np.asarray(nodes @ _matrix(grid, sensor, dt))[0]
    late = slice(85, 100)  # bins of the 10-count return, on the peak's long tail
    np.testing.assert_allclose(out[np.float32][late], out[np.float64][late], rtol=1e-4)


def test_ideal_response_sums_nodes_per_bin():
    s = SensorConfig(n_bins=64, bin_width_ps=100.0, iterations=1, saturation=False)
    grid = TimeGrid.for_sensor(s, 0.0, 8000.0, oversample=4)
    rng = np.random.default_rng(1)
    t, w = rng.uniform(0, 6000, 300), rng.uniform(0, 1, 300)
    nodes = deposit(grid, t, w, None, 1, bin_width_ps=100.0, start_offset_ps=0.0)
    a = np.asarray(bin_nodes_without_irf(grid, nodes))
    b = np.asarray(nodes @ _matrix(grid, s))
    np.testing.assert_allclose(a, b, atol=1e-12)
    assert a.sum() == pytest.approx(w.sum(), rel=1e-12)


def test_grid_covers_what_can_reach_the_window(sensor):
    grid = TimeGrid.for_sensor(sensor, 0.0, 1e6, oversample=4)
    nt = np.asarray(grid.node_times(sensor.bin_width_ps, sensor.start_offset_ps))
    lo, hi = irf_extent_ps(sensor)
    assert nt[0] <= max(0.0, sensor.start_offset_ps - hi) + sensor.bin_width_ps
    assert nt[-1] >= sensor.start_offset_ps + sensor.window_ps - lo - sensor.bin_width_ps


def test_matrix_is_differentiable_in_bin_width_and_sigma(sensor):
    grid = TimeGrid.for_sensor(sensor, 0.0, 20000.0, oversample=4)
    nodes = jnp.zeros(grid.n_nodes).at[200].set(1.0)

    def f(bw, sig):
        m = irf_matrix(grid, bin_width_ps=bw, sigma_ps=sig, pulse=pulse_boxes(sensor), extent_ps=irf_extent_ps(sensor),
                       nominal_bin_width_ps=sensor.bin_width_ps)
        return (nodes @ m * jnp.arange(m.shape[1])).sum()

    g = jax.grad(f, argnums=(0, 1))(jnp.asarray(sensor.bin_width_ps), jnp.asarray(60.0))
    h = 1e-3
    fd = (f(sensor.bin_width_ps + h, 60.0) - f(sensor.bin_width_ps - h, 60.0)) / (2 * h)
    assert np.isfinite(g[1]) and float(g[0]) == pytest.approx(float(fd), rel=1e-4)
