"""Emulating a lower-spec sensor from a better one: exactness, reachability, agreement with the simulator."""

import numpy as np
import pytest

from nlosplan.errors import UserError
from nlosplan.planner.design.space import Design
from nlosplan.sensor_models import preset
from nlosplan.sensor_models.degrade import (Degradation, degrade_counts, degrade_expected, degrade_linear,
                                            jitter_kernel, merge_bins, pool_zones, reach)
from nlosplan.sensor_models.pipeline import apply_jitter

BASE = preset("tmf8828-8x8-short")


@pytest.mark.parametrize("fwhm", [50.0, 300.0, 900.0])
def test_jitter_kernel_equals_exact_box_rebinning(fwhm):
    k, half = jitter_kernel(fwhm, 92.816)
    x = np.zeros(128)
    x[64] = 1.0
    y = np.asarray(apply_jitter(x, fwhm, 92.816))
    np.testing.assert_allclose(y[64 - half: 64 + half + 1], k, atol=1e-7)
    assert abs(k.sum() - 1) < 1e-12 and np.argmax(k) == half


def test_pool_and_merge_conserve_counts():
    rng = np.random.default_rng(0)
    h = rng.poisson(5.0, (4, 8, 8, 128)).astype(float)
    p = pool_zones(h, (4, 2))
    assert p.shape == (4, 2, 4, 128) and p.sum() == h.sum()
    assert p[0, 1, 3, 7] == h[0, 4:8, 6:8, 7].sum()
    m = merge_bins(h, 4, 32)
    assert m.shape == (4, 8, 8, 32) and m.sum() == h.sum()
    assert merge_bins(h, 2, 10).sum() == h[..., :20].sum()


def test_reach_refuses_what_cannot_be_emulated():
    ok, why = reach(BASE, Design((2, 2), 2, 60, 300, 0, 0.5).sensor(BASE))
    assert why == "" and ok == Degradation((4, 4), 2, 60, 300.0, 0.5, BASE.bin_width_ps)
    cases = [
        (Design((3, 3)).sensor(BASE), "zones 3x3 are not a pooling of the captured 8x8"),
        (BASE.replace(bin_width_ps=BASE.bin_width_ps * 1.5), "is not a whole multiple"),
        (Design((8, 8), 2, 65).sensor(BASE), "need a 12.07 ns window"),
        (Design((8, 8), photon_fraction=2.0).sensor(BASE), "cannot be emulated from counts"),
    ]
    for design, message in cases:
        d, why = reach(BASE, design)
        assert d is None and message in why
    blurred = BASE.replace(jitter_fwhm_ps=400.0)
    d, why = reach(blurred, blurred.replace(jitter_fwhm_ps=100.0))
    assert d is None and "sharper than the captured 400 ps" in why
    d, _ = reach(blurred, blurred.replace(jitter_fwhm_ps=500.0))
    assert d.extra_jitter_fwhm_ps == pytest.approx(300.0)  # adds in quadrature
    d, why = reach(BASE, Design((8, 8), photon_fraction=2.0).sensor(BASE), counts=False)
    assert why == "" and d.photon_fraction == pytest.approx(2.0)  # expected counts scale freely


def test_degraded_counts_are_poisson_with_the_degraded_mean():
    lam = np.zeros((8, 8, 64))
    lam[..., 20] = 40.0
    lam[..., 40:] = 3.0
    d = Degradation((2, 4), 2, 30, 400.0, 0.3, 92.816)
    counts = degrade_counts(np.random.default_rng(1).poisson(lam, (3000,) + lam.shape), d, rng=2)
    mean = degrade_expected(lam, d)
    assert counts.shape == (3000, 4, 2, 30) and counts.dtype == np.int64
    np.testing.assert_allclose(counts.mean(0), mean, rtol=0.04, atol=0.05)
    busy = mean > 20
    np.testing.assert_allclose(counts.var(0)[busy], mean[busy], rtol=0.12)  # thinned Poisson stays Poisson
    with pytest.raises(UserError, match="more photons"):
        degrade_counts(counts[:1], Degradation(photon_fraction=1.5), 0)


def test_linear_operator_applies_to_jacobians():
    rng = np.random.default_rng(3)
    jac = rng.normal(size=(2, 8, 8, 64, 3))
    d = Degradation((4, 4), 2, 20, 250.0, 0.7, 92.816)
    out = degrade_linear(jac, d)
    assert out.shape == (2, 2, 2, 20, 3)
    for p in range(3):
        np.testing.assert_allclose(out[..., p], degrade_expected(jac[..., p], d), rtol=1e-12)


def test_emulated_design_matches_simulating_it():
    """Degrading the reference equals simulating the design (jitter, merged bins, photons; default fidelity)."""
    from nlosplan.simulators import FastSimulator, denali_scene

    base = preset("tmf8828-3x3-short")
    scene = denali_scene("A", "8in", 40)
    ref = FastSimulator(scene, base).expected()
    for design in (Design((3, 3), 1, 128, 300.0, 0, 1.0), Design((3, 3), 2, 50, 0.0, 200.0, 0.25)):
        sensor = design.sensor(base)
        d, why = reach(base, sensor, counts=False)
        assert why == ""
        emulated = degrade_expected(ref, d)
        direct = FastSimulator(scene, sensor).expected()
        assert np.abs(emulated - direct).sum() / direct.sum() < 0.02
        assert abs(emulated.sum() / direct.sum() - 1) < 1e-3
