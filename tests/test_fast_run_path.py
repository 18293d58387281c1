"""The batched run path of issue 20 (chunk parameters built once on the host, sensor terms computed once) equals the per-call path of before."""

import numpy as np
import pytest

from nlosplan.sensor_models.presets import resolve_sensor
from nlosplan.simulators import FastSimulator, denali_scene


@pytest.mark.parametrize("options", [{}, pytest.param({"albedo": 0.36, "diffuse_albedo": 0.2, "mount": True},
                                                      marks=pytest.mark.slow)],   # 68 s; CI runs it
                         ids=["retroreflective", "mixed+mount"])
def test_cached_chunks_equal_per_call_slices_with_a_padded_last_chunk(options):
    sensor = resolve_sensor("tmf8828-3x3-short")
    sensors = [sensor, sensor.replace(jitter_fwhm_ps=80.0, photon_scale=2.0)]
    scenes = [denali_scene(o, s, p, **options) for o, s, p in (("A", "8in", 0), ("circle", "4in", 47), ("3", "8in", 99),
                                                              ("S", "4in", 13), ("minus", "8in", 71))]
    # 5 scenes in chunks of 2: the last chunk holds one scene padded with itself
    new = FastSimulator(scenes, sensors=sensors, fidelity="draft", chunk=2)
    old = FastSimulator(scenes, sensors=sensors, fidelity="draft", chunk=2, cache_chunks=False)
    a, b = new.expected(parts=True), old.expected(parts=True)
    assert a["counts"].shape == (2, 5, 3, 3, 128)
    for part in ("counts", "object", "direct", "floor"):  # two compilations: float32 rounding apart
        assert np.abs(a[part] - b[part]).max() <= 1e-6 * np.abs(b[part]).max(), part
    assert np.abs(a["object"]).max() > 0
    # every scene of a chunk is its own: the scene simulated alone (its own plan: the retroreflector's
    # within float32 round-off; the Lambertian terms' cells and grids are the batch's union, within 0.3 %)
    tol = 1e-5 if not options else 3e-3
    for k in (1, 4):
        alone = FastSimulator(scenes[k], sensors=sensors, fidelity="draft").expected(parts=True)["object"]
        assert np.abs(a["object"][:, k] - alone).max() <= tol * np.abs(alone).max()
    # a second call reuses the chunks and returns a fresh, writable array
    again = new.expected()
    np.testing.assert_array_equal(again, a["counts"])
    again[...] = 0.0
    assert np.abs(new.expected()).max() > 0


def test_single_scene_call_reuses_its_parameters():
    sim = FastSimulator(denali_scene("A", "8in", 5), resolve_sensor("tmf8828-3x3-short"), fidelity="draft")
    first = sim.expected()
    chunks, terms = sim._chunks, sim._sensor_terms
    assert first.shape == (3, 3, 128) and len(chunks) == 1 and terms["irf"].shape[0] == 1
    np.testing.assert_array_equal(sim.expected(), first)
    assert sim._chunks is chunks and sim._sensor_terms is terms


def test_sensors_of_nearby_jitter_share_one_plan_structure_and_its_results_are_theirs():
    # the design run's worlds differ in jitter (47-100 ps FWHM here): one plan structure, so one compiled program;
    # the support sized for the rounded sigma changes nothing but the Gaussian's mass beyond 9 sigma
    from nlosplan.simulators.fast.plan import SUPPORT_SIGMA_STEP_PS, support_sigma_ps

    assert support_sigma_ps(0.0) == 0.0 and support_sigma_ps(SUPPORT_SIGMA_STEP_PS) == SUPPORT_SIGMA_STEP_PS
    assert support_sigma_ps(1.0) == support_sigma_ps(42.5) == SUPPORT_SIGMA_STEP_PS
    assert support_sigma_ps(SUPPORT_SIGMA_STEP_PS + 1) == 2 * SUPPORT_SIGMA_STEP_PS
    base = resolve_sensor("tmf8828-3x3-short")
    scenes = [denali_scene("A", "8in", 10, albedo=0.36, diffuse_albedo=0.2)]
    sims = [FastSimulator(scenes, base.replace(jitter_fwhm_ps=j), fidelity="draft") for j in (47.7, 65.6, 100.4)]
    assert len({s.plan.static for s in sims}) == 1
    assert FastSimulator(scenes, base.replace(jitter_fwhm_ps=300.0), fidelity="draft").plan.static != sims[0].plan.static
    # each equals the same sensor in a batch sized for a much wider Gaussian (sigma ~ 850 ps: support 7.6 ns wider)
    for j in (47.7, 65.6, 100.4):
        wide = FastSimulator(scenes, sensors=[base.replace(jitter_fwhm_ps=j), base.replace(jitter_fwhm_ps=2000.0)],
                             fidelity="draft", dtype="float64").expected()[0]
        own = FastSimulator(scenes, base.replace(jitter_fwhm_ps=j), fidelity="draft", dtype="float64").expected()
        assert np.abs(own - wide).max() <= 1e-9 * np.abs(own).max()


def test_a_plan_sized_for_a_wider_sigma_shares_its_structure_and_keeps_its_results():
    # a design run's worlds: each world's reference is planned for the largest world sigma (min_support_sigma_ps),
    # so worlds whose own sigmas round to different supports (100 and 50 ps here) run one compiled program
    from nlosplan.errors import UserError
    from nlosplan.simulators import expected_batch
    from nlosplan.simulators.fast.plan import build_plan

    base = resolve_sensor("tmf8828-3x3-short")
    scenes = [denali_scene("A", "8in", 10, albedo=0.36, diffuse_albedo=0.2)]
    narrow, wide = base.replace(jitter_fwhm_ps=60.0), base.replace(jitter_fwhm_ps=140.0)
    assert build_plan(scenes, narrow, "draft").static != build_plan(scenes, wide, "draft").static
    sigma = wide.impulse_sigma_ps
    sized = FastSimulator(scenes, narrow, fidelity="draft", min_support_sigma_ps=sigma)
    assert sized.plan.static == FastSimulator(scenes, wide, fidelity="draft", min_support_sigma_ps=sigma).plan.static
    own = FastSimulator(scenes, narrow, fidelity="draft", dtype="float64").expected()
    got = expected_batch(scenes, narrow, fidelity="draft", dtype="float64", min_support_sigma_ps=sigma).expected[0]
    assert np.abs(own - got).max() <= 1e-9 * np.abs(own).max() and own.max() > 0
    # a sensor without any Gaussian (a design run's nominal references) planned the same way: the Gaussian path
    # with sigma 0 instead of the pulse-only one, the same structure as its worlds', the same histograms
    sharp = base.replace(jitter_fwhm_ps=0.0, pulse_fwhm_ps=0.0)
    assert sharp.impulse_sigma_ps == 0.0 and build_plan(scenes, sharp, "draft").static.irf in ("pulse", "none")
    planned = FastSimulator(scenes, sharp, fidelity="draft", dtype="float64", min_support_sigma_ps=sigma)
    assert planned.plan.static == sized.plan.static and planned.plan.static.irf == "full"
    assert "planned for" in planned.explain()
    own = FastSimulator(scenes, sharp, fidelity="draft", dtype="float64").expected()
    assert np.abs(own - planned.expected()).max() <= 1e-9 * np.abs(own).max() and own.max() > 0
    for bad in (-1.0, float("nan"), float("inf")):
        with pytest.raises(UserError, match="min_support_sigma_ps=.* must be a finite number >= 0"):
            build_plan(scenes, narrow, "draft", min_support_sigma_ps=bad)
    with pytest.raises(UserError, match="min_support_sigma_ps sizes a fast-backend plan; backend 'mitsuba' has none"):
        expected_batch(scenes, narrow, backend="mitsuba", min_support_sigma_ps=sigma)


@pytest.mark.parametrize("dtype", ["float32", "float64"])
def test_to_jax_casts_on_the_host_as_the_device_would(dtype):
    import jax
    import jax.numpy as jnp

    from nlosplan.simulators.fast.simulator import to_jax

    rng = np.random.default_rng(0)
    tree = {"x": rng.normal(size=(4, 3)) * 1e3, "n": np.arange(6, dtype=np.int64), "flag": np.array([True, False]),
            "scalar": 0.1, "nested": [np.float32(2.5), {"tiny": np.array([1e-300, 1e-40, 3.0])}]}
    got = to_jax(tree, jnp.dtype(dtype))
    for a, b in zip(jax.tree_util.tree_leaves(got), jax.tree_util.tree_leaves(tree)):
        b = np.asarray(b)
        want = jnp.asarray(b) if b.dtype == bool else jnp.asarray(b, jnp.int32 if b.dtype.kind == "i" else dtype)
        assert isinstance(a, jax.Array) and a.dtype == want.dtype and a.shape == want.shape
        np.testing.assert_array_equal(np.asarray(a), np.asarray(want))
