"""The compiled kernels (deposit, sum-convolution): the same sums and derivatives as the XLA paths, and how they are built."""

import os
import stat
import warnings

import numpy as np
import pytest

from nlosplan._jax import jax, jnp
from nlosplan.sensor_models import compiled
from nlosplan.sensor_models.transient import (RowPattern, default_deposit, deposit_at, deposit_method,
                                              deposit_sum_convolve, sum_convolve)
from nlosplan.simulators import FastSimulator, denali_scene
from nlosplan.sensor_models.presets import resolve_sensor


def _both(fn):
    out = {}
    for m in ("kernel", "window"):
        with deposit_method(m):
            out[m] = fn()
    return out


@pytest.mark.parametrize("dtype", ["float32", "float64"])
def test_kernel_equals_the_scatter_on_a_samples_by_cells_array(dtype):
    rng = np.random.default_rng(7)
    m, n, n_nodes = 30, 11, 25
    pos = jnp.asarray(rng.uniform(-3.0, n_nodes + 3.0, (m, n)), dtype)  # off the grid on both sides
    pos = pos.at[0, :4].set(jnp.asarray([-1.0, -0.5, n_nodes - 1.0, n_nodes - 0.25], dtype))  # the edges exactly
    w = jnp.asarray(rng.uniform(-1.0, 1.0, (m, n)), dtype).at[1, 0].set(0.0)
    rows = jnp.arange(n)[None] % 4  # rows along the last axis, broadcast over the samples
    out = _both(lambda: np.asarray(jax.jit(lambda p, w: deposit_at(p, w, rows, 4, n_nodes))(pos, w)))
    assert out["kernel"].dtype == np.dtype(dtype) and out["kernel"].shape == (4, n_nodes)
    np.testing.assert_allclose(out["kernel"], out["window"], rtol=1e-5 if dtype == "float32" else 1e-12, atol=1e-12)
    # a row for every arrival (some out of range: dropped)
    full = jnp.asarray(rng.integers(-1, 5, (m, n)))
    out = _both(lambda: np.asarray(deposit_at(pos, w, full, 4, n_nodes)))
    assert np.abs(out["window"]).max() > 0
    np.testing.assert_allclose(out["kernel"], out["window"], rtol=1e-5 if dtype == "float32" else 1e-12, atol=1e-12)
    # what lies between the first and the last node keeps its weight and mean position
    p, wn = np.asarray(pos, np.float64), np.asarray(w, np.float64)
    inside = (p >= 0) & (p <= n_nodes - 1)
    with deposit_method("kernel"):
        grid = np.asarray(deposit_at(pos[inside], w[inside], jnp.broadcast_to(rows, pos.shape)[inside], 4, n_nodes),
                          np.float64)
    assert grid.sum() == pytest.approx(wn[inside].sum(), rel=1e-5)
    assert (grid * np.arange(n_nodes)).sum() == pytest.approx((wn * p)[inside].sum(), rel=1e-5)


@pytest.mark.parametrize("method", ["kernel", "window", "scatter"])
def test_row_patterns_equal_the_rows_written_out(method):
    """A row per sample, per cell, and per sample and zone: the pattern and the full rows give the same sums."""
    rng = np.random.default_rng(3)
    m, n, n_nodes = 7, 9, 16
    pos = jnp.asarray(rng.uniform(-2.0, n_nodes + 1.0, (m, n)))
    w = jnp.asarray(rng.uniform(0.0, 1.0, (m, n)))
    zone = jnp.asarray(rng.integers(0, 3, n))
    cases = [(RowPattern(jnp.zeros(n, jnp.int32), 1), jnp.broadcast_to(jnp.arange(m)[:, None], (m, n)), m),
             (RowPattern(jnp.arange(n), 0), jnp.broadcast_to(jnp.arange(n)[None], (m, n)), n),
             (RowPattern(zone, 3), jnp.arange(m)[:, None] * 3 + zone[None], 3 * m)]
    for pattern, full, n_rows in cases:
        with deposit_method("window"):
            ref = np.asarray(deposit_at(pos, w, full, n_rows, n_nodes))
        with deposit_method(method):
            got = np.asarray(jax.jit(lambda p, w: deposit_at(p, w, pattern, n_rows, n_nodes))(pos, w))
            batched = np.asarray(jax.vmap(lambda p: deposit_at(p, w, pattern, n_rows, n_nodes))(jnp.stack([pos, pos + 1])))
        assert (np.abs(ref).sum(axis=1) > 0).mean() > 0.8  # (nearly) every row gets arrivals
        np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(batched[0], ref, rtol=1e-12, atol=1e-15)
        with deposit_method("window"):
            np.testing.assert_allclose(batched[1], np.asarray(deposit_at(pos + 1, w, full, n_rows, n_nodes)), rtol=1e-12)


@pytest.mark.parametrize("dtype", ["float32", "float64"])
def test_a_row_per_sample_taken_four_samples_at_once_keeps_each_rows_order(dtype):
    # the kernel deposits a row per sample (RowPattern(zeros, 1)) four samples at once, position by position
    # (deposit.cc, kInterleave): each row must take its own cells in order, exactly as cell by cell over the
    # transposed array does (the layout the Lambertian leg 1 used), for 4k samples and a remainder
    rng = np.random.default_rng(13)
    for m in (8, 11, 3):
        n, n_nodes = 37, 20
        pos = rng.uniform(-1.5, n_nodes + 0.5, (m, n)) + rng.integers(0, 2, (m, n)) * 0.5
        pos[0, 0] = np.nan
        w = rng.normal(size=(m, n)) * (rng.random((m, n)) < 0.8)
        p, wj = jnp.asarray(pos, dtype), jnp.asarray(w, dtype)
        with deposit_method("kernel"):
            by_sample = np.asarray(deposit_at(p, wj, RowPattern(jnp.zeros(n, jnp.int32), 1), m, n_nodes))
            by_cell = np.asarray(deposit_at(p.T, wj.T, RowPattern(jnp.arange(m, dtype=jnp.int32), 0), m, n_nodes))
        assert np.count_nonzero(by_sample) > m * 10
        np.testing.assert_array_equal(by_sample, by_cell)


def _legs(rng, m=6, z=3, n1=20, n2=12):
    """Sparse legs like a Lambertian object's: leg 1 on a span of each row, leg 2 on a few nodes per zone."""
    a = np.zeros((m, n1))
    b = np.zeros((m, z, n2))
    for i in range(m):
        lo = rng.integers(0, n1 - 5)
        a[i, lo:lo + rng.integers(1, 6)] = rng.uniform(0.1, 1.0)
        for k in range(z):
            b[i, k, rng.integers(0, n2, 3)] = rng.uniform(-1.0, 1.0, 3)
    a[2] = 0.0  # a sample that sees no lit wall
    return jnp.asarray(a), jnp.asarray(b)


def test_sum_convolve_kernel_equals_the_definition_and_the_ffts():
    rng = np.random.default_rng(5)
    a, b = _legs(rng)
    m, n1 = a.shape
    _, z, n2 = b.shape
    want = np.zeros((z, n1 + n2 - 1))
    for i in range(m):
        for k in range(z):
            want[k] += np.convolve(np.asarray(a[i]), np.asarray(b[i, k]))
    for method in ("kernel", "window"):
        with deposit_method(method):
            got = np.asarray(jax.jit(lambda a, b: sum_convolve(a, b, 32))(a, b))
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12 * np.abs(want).max())
    with deposit_method("kernel"):  # float32, and batched
        got32 = np.asarray(sum_convolve(a.astype(jnp.float32), b.astype(jnp.float32), 32))
        batched = np.asarray(jax.vmap(lambda s: sum_convolve(a * s, b, 32))(jnp.asarray([1.0, -2.0])))
    assert got32.dtype == np.float32
    np.testing.assert_allclose(got32, want, rtol=1e-5, atol=1e-6 * np.abs(want).max())
    np.testing.assert_allclose(batched, np.stack([want, -2.0 * want]), rtol=1e-12, atol=1e-12 * np.abs(want).max())


def test_sum_convolve_derivatives_equal_the_ffts():
    rng = np.random.default_rng(6)
    a, b = _legs(rng)
    weight = jnp.asarray(rng.normal(size=(3, 31)))

    def loss(s):
        return jnp.sum(jnp.sin(sum_convolve(a * s[0] + s[1] * a**2, b * s[2], 32)) * weight)

    s0 = jnp.asarray([1.0, 0.3, 1.5])
    grads = _both(lambda: np.asarray(jax.grad(loss)(s0)))
    jacs = _both(lambda: np.asarray(jax.jacfwd(lambda s: sum_convolve(a * s[0], b * s[2] + s[1], 32))(s0)))
    hess = _both(lambda: np.asarray(jax.hessian(loss)(s0)))
    assert np.abs(grads["window"]).max() > 0
    for got in (grads, jacs, hess):
        np.testing.assert_allclose(got["kernel"], got["window"], rtol=1e-9, atol=1e-12)


def _detection_leg(rng, m=5, cells=12, z=3, n2=16):
    """Leg 1 with zero runs, and a detection leg's positions (some off the grid, one NaN), weights (some zero) and
    zones, as a Lambertian term has them."""
    a = jnp.asarray(rng.random((m, 20)) * (rng.random((m, 20)) < 0.6))
    a = a.at[2].set(0.0)  # a sample no light reaches
    p = rng.uniform(-1.5, n2 + 0.5, (m, cells))
    p[0, 0] = np.nan
    w = rng.normal(size=(m, cells)) * (rng.random((m, cells)) < 0.7)
    zone = rng.integers(0, z, cells)
    return a, jnp.asarray(p), jnp.asarray(w), RowPattern(jnp.asarray(zone, jnp.int32), z), n2


def test_deposit_and_convolve_in_one_pass_equal_the_two_steps_to_the_bit():
    rng = np.random.default_rng(11)
    a, p, w, rows, n2 = _detection_leg(rng)
    m, z = p.shape[0], rows.step

    def two_steps(a, p, w):
        return sum_convolve(a, deposit_at(p, w, rows, m * z, n2).reshape(m, z, n2), 40)

    for dtype in (jnp.float64, jnp.float32):
        args = [x.astype(dtype) for x in (a, p, w)]
        with deposit_method("kernel"):
            want = np.asarray(jax.jit(two_steps)(*args))
            got = np.asarray(jax.jit(lambda a, p, w: deposit_sum_convolve(a, p, w, rows, n2, 40))(*args))
        assert got.dtype == dtype and np.abs(want).max() > 0
        np.testing.assert_array_equal(got, want)  # the same sums in the same order
    # a cell of no zone is dropped (the two steps would put it in the next sample's first zone)
    zone = np.asarray(rows.cells).copy()
    zone[3] = z
    with deposit_method("kernel"):
        dropped = np.asarray(deposit_sum_convolve(a, p, w, RowPattern(jnp.asarray(zone, jnp.int32), z), n2, 40))
        np.testing.assert_array_equal(dropped, np.asarray(two_steps(a, p, w.at[:, 3].set(0.0))))
    p = jnp.where(jnp.isnan(p), 3.3, p)  # the XLA scatter keeps a NaN position's NaN
    with deposit_method("window"):  # the XLA path: the two steps
        xla = np.asarray(deposit_sum_convolve(a, p, w, rows, n2, 40))
    with deposit_method("kernel"):
        want = np.asarray(deposit_sum_convolve(a, p, w, rows, n2, 40))
    np.testing.assert_allclose(xla, want, rtol=1e-9, atol=1e-12 * np.abs(want).max())
    with deposit_method("kernel"):  # batched
        got = np.asarray(jax.vmap(lambda s: deposit_sum_convolve(a * s, p, w, rows, n2, 40))(jnp.asarray([1.0, -2.0])))
        one = np.asarray(deposit_sum_convolve(a, p, w, rows, n2, 40))
    np.testing.assert_allclose(got, np.stack([one, -2.0 * one]), rtol=1e-12, atol=1e-12 * np.abs(one).max())


def test_long_runs_of_touched_nodes_convolve_in_blocks_to_the_same_bits():
    # the one-pass kernel adds four touched detection nodes at once (kernels/sum_convolve.cc, kBlock): runs of 1-9
    # touched nodes, with zero nodes (a weight of 0) inside and whole blocks of them, must give the two steps' bits
    rng = np.random.default_rng(5)
    m, cells, z, n2 = 6, 90, 2, 48
    a = rng.random((m, 30)) * (rng.random((m, 30)) < 0.8)
    starts = rng.integers(0, n2 - 10, (m, cells))
    p = starts + rng.random((m, cells)) * rng.integers(1, 9, (m, cells))
    w = rng.normal(size=(m, cells)) * (rng.random((m, cells)) < 0.5)
    w[:, ::7] = 0.0
    zone = np.arange(cells) % z
    rows = RowPattern(jnp.asarray(zone, jnp.int32), z)
    for dtype in (jnp.float64, jnp.float32):
        args = [jnp.asarray(x, dtype) for x in (a, p, w)]
        with deposit_method("kernel"):
            leg2 = deposit_at(args[1], args[2], rows, m * z, n2).reshape(m, z, n2)
            want = np.asarray(sum_convolve(args[0], leg2, 80))  # the unblocked kernel
            got = np.asarray(deposit_sum_convolve(*args, rows, n2, 80))
        assert np.count_nonzero(want) > 100
        np.testing.assert_array_equal(got, want)


def test_deposit_and_convolve_derivatives_equal_the_two_steps():
    rng = np.random.default_rng(12)
    a, p, w, rows, n2 = _detection_leg(rng)
    p = jnp.where(jnp.isnan(p), 3.3, p)  # derivatives at a NaN position are NaN on every path
    m, z = p.shape[0], rows.step
    weight = jnp.asarray(rng.normal(size=(z, 20 + n2 - 1)))

    def out(s, fused):
        aa, pp, ww = a * s[0] + s[1] * a**2, p + s[2], w * s[3]
        if fused:
            return deposit_sum_convolve(aa, pp, ww, rows, n2, 40)
        return sum_convolve(aa, deposit_at(pp, ww, rows, m * z, n2).reshape(m, z, n2), 40)

    s0 = jnp.asarray([1.0, 0.3, 0.05, 1.5])
    with deposit_method("kernel"):
        for fn in (lambda f: jax.grad(lambda s: jnp.sum(jnp.sin(out(s, f)) * weight))(s0),
                   lambda f: jax.jacfwd(lambda s: out(s, f))(s0)):
            want, got = np.asarray(fn(False)), np.asarray(fn(True))
            assert np.abs(want).max() > 0
            np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12 * np.abs(want).max())


def test_kernel_drops_nan_positions_and_rows_out_of_range():
    with deposit_method("kernel"):
        out = np.asarray(deposit_at(jnp.asarray([jnp.nan, 2.25, 1.0, 1.0]), jnp.asarray([5.0, 1.0, 3.0, 7.0]),
                                    jnp.asarray([0, 1, -1, 2]), 2, 4))
    np.testing.assert_array_equal(out, [[0, 0, 0, 0], [0, 0, 0.75, 0.25]])


def test_kernel_derivatives_equal_the_scatter_forward_reverse_and_batched():
    rng = np.random.default_rng(1)
    pos = jnp.asarray(rng.uniform(-2.0, 22.0, (40, 6)))
    w = jnp.asarray(rng.uniform(0.1, 1.0, (40, 6)))
    rows = jnp.arange(6)[None]
    weight = jnp.asarray(rng.normal(size=(6, 20)))

    def loss(s):
        return jnp.sum(jnp.sin(deposit_at(pos * s[0] + s[1], w * s[2], rows, 6, 20)) * weight)

    s0 = jnp.asarray([1.0, 0.3, 1.5])
    grads = _both(lambda: np.asarray(jax.grad(loss)(s0)))
    jacs = _both(lambda: np.asarray(jax.jacfwd(lambda s: deposit_at(pos * s[0] + s[1], w * s[2], rows, 6, 20))(s0)))
    hess = _both(lambda: np.asarray(jax.hessian(loss)(s0)))
    batched = _both(lambda: np.asarray(jax.vmap(lambda p: deposit_at(p, w, rows, 6, 20))(jnp.stack([pos, pos + 2.5]))))
    assert np.abs(grads["window"]).max() > 0 and np.abs(jacs["window"]).max() > 0
    for got in (grads, jacs, hess, batched):
        np.testing.assert_allclose(got["kernel"], got["window"], rtol=1e-10, atol=1e-12)
    with deposit_method("kernel"):
        one = np.asarray(deposit_at(pos + 2.5, w, rows, 6, 20))
    np.testing.assert_allclose(batched["kernel"][1], one, rtol=1e-12)


def test_the_simulator_uses_the_kernel_by_default_and_gets_the_same_histograms():
    assert compiled.available()  # the test machines have a C++ compiler
    sensor = resolve_sensor("tmf8828-3x3-short")
    scenes = [denali_scene("A", "8in", 3, albedo=0.36, diffuse_albedo=0.2), denali_scene("minus", "4in", 60)]
    sim = FastSimulator(scenes, sensor, fidelity="draft")
    assert sim.plan.static.deposit == "kernel"
    assert {o.kind for o in sim.plan.static.objects} == {"retroreflective", "lambertian"}  # the legs' sum-convolution
    got = np.asarray(sim.expected(), np.float64)
    ref = np.asarray(FastSimulator(scenes, sensor, fidelity="draft", deposit="window").expected(), np.float64)
    assert np.abs(ref).max() > 0
    assert np.abs(got - ref).max() / np.abs(ref).max() < 1e-6


@pytest.fixture
def fresh(monkeypatch, tmp_path):
    """A process state that has not looked for the kernel yet, with its own kernel folder."""
    monkeypatch.setattr(compiled, "_STATE", {})
    monkeypatch.setenv("NLOSPLAN_CACHE", str(tmp_path))
    monkeypatch.delenv(compiled.ENV_SWITCH, raising=False)
    return tmp_path


def test_a_fresh_folder_builds_the_library_once_and_loads_it(fresh, monkeypatch):
    ok, path = compiled.status()
    assert ok and path.startswith(str(fresh / "kernels")) and os.path.getsize(path) > 0
    assert [p.name for p in (fresh / "kernels").iterdir() if p.suffix == ".tmp"] == []
    # a second process finds it built: no compiler run
    monkeypatch.setattr(compiled, "_STATE", {})
    monkeypatch.setattr(compiled, "_build", lambda *a: pytest.fail("rebuilt a library that exists"))
    assert compiled.status() == (True, path)
    with deposit_method("kernel"):
        out = np.asarray(deposit_at(jnp.asarray([0.5]), jnp.asarray([2.0]), None, 1, 2))
    np.testing.assert_allclose(out, [[1.0, 1.0]])


def test_without_a_compiler_the_scatter_is_used_and_a_warning_says_why(fresh, monkeypatch):
    monkeypatch.setenv("CXX", str(fresh / "no-such-compiler"))
    with pytest.warns(RuntimeWarning, match=r"compiled kernels are not available \(no C\+\+ compiler .*XLA's scatter-add and FFTs"):
        assert default_deposit() == "window"
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # once per process
        assert compiled.status() == (False, "no C++ compiler (set CXX, or install g++ or clang++)")
    sim = FastSimulator(denali_scene("A", "8in", 0), resolve_sensor("tmf8828-3x3-short"), fidelity="draft")
    assert sim.plan.static.deposit == "window"


def test_a_plan_made_for_the_kernel_runs_where_it_cannot_be_built(fresh, monkeypatch):
    """A plan built where the kernel loads, run in a process without a compiler (a remote worker)."""
    sensor = resolve_sensor("tmf8828-3x3-short")
    scene = denali_scene("S", "4in", 12)
    ref = np.asarray(FastSimulator(scene, sensor, fidelity="draft", deposit="window").expected())
    jax.clear_caches()  # trace again, in the "worker"
    monkeypatch.setattr(compiled, "_STATE", {})
    monkeypatch.setenv("CXX", str(fresh / "no-such-compiler"))
    with pytest.warns(RuntimeWarning, match="no C\\+\\+ compiler"):
        got = np.asarray(FastSimulator(scene, sensor, fidelity="draft", deposit="kernel").expected())
    np.testing.assert_allclose(got, ref, rtol=1e-6, atol=1e-6 * np.abs(ref).max())


def test_a_failing_build_names_the_compiler_error_and_leaves_no_file(fresh, monkeypatch):
    cxx = fresh / "bad-cxx"
    cxx.write_text('#!/bin/sh\nif [ "$1" = --version ]; then echo "bad-cxx 1.0"; exit 0; fi\n'
                   'echo "deposit.cc:1: error: no such header" >&2\nexit 1\n')
    cxx.chmod(cxx.stat().st_mode | stat.S_IEXEC)
    monkeypatch.setenv("CXX", str(cxx))
    with pytest.warns(RuntimeWarning, match="bad-cxx failed: deposit.cc:1: error: no such header"):
        assert not compiled.available()
    assert sorted(p.name for p in (fresh / "kernels").iterdir() if not p.name.endswith(".lock")) == []


def test_the_switch_turns_it_off_without_a_warning(fresh, monkeypatch):
    monkeypatch.setenv(compiled.ENV_SWITCH, "0")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert default_deposit() == "window"
    assert compiled.status() == (False, f"turned off by {compiled.ENV_SWITCH}=0")
    with pytest.raises(RuntimeError, match="compiled kernels are not available: turned off"):
        compiled.deposit(jnp.zeros(1), jnp.zeros(1), jnp.zeros(1, jnp.int32), 1, 1)


def test_on_a_gpu_the_kernels_step_aside_for_xla_without_a_warning(fresh, monkeypatch):
    """Where JAX computes on a GPU the CPU custom calls cannot run: XLA's own path is used, silently (issue 38)."""
    monkeypatch.setattr(compiled.jax, "default_backend", lambda: "gpu")
    monkeypatch.setattr(compiled, "_load", lambda: pytest.fail("loaded the CPU kernels for a GPU"))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert default_deposit() == "window"
        assert compiled.status() == (False, "JAX computes on gpu, and the kernels are CPU-only (XLA's own path runs there)")
    with deposit_method("kernel"):   # a plan made on a CPU machine, traced where the GPU is
        out = np.asarray(deposit_at(jnp.asarray([0.25]), jnp.asarray([4.0]), None, 1, 2))
    np.testing.assert_allclose(out, [[3.0, 1.0]])
