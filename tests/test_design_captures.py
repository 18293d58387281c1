"""Noisy captures of an emulated design: the mean of repeats drawn as one Poisson sum has their law."""

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from nlosplan.planner.design.data import ReferenceData
from nlosplan.sensor_models import preset


def reference(lam, **sensor_kw):
    sensor = preset("tmf8828-3x3-short").replace(zones_rows=1, zones_cols=1, n_bins=lam.shape[-1], **sensor_kw)
    labels = pd.DataFrame({"object": ["A"] * lam.shape[0]})
    ref = ReferenceData(sensor, labels, means=lam.reshape(lam.shape[0], 1, 1, -1).astype(np.float32))
    deg, why = ref.degradation(sensor)
    assert deg is not None, why
    return ref, deg


def averaged(ref, seed, repeats):
    """The mean of ``repeats`` captures drawn one by one (each clipped at the sensor's ceiling), (N, 1, 1, B)."""
    lam = ref.means.astype(np.float64)
    cap = np.random.default_rng(seed).poisson(np.broadcast_to(lam[:, None], (lam.shape[0], repeats) + lam.shape[1:]))
    return (np.minimum(cap, ref.sensor.max_count) if ref.sensor.saturation else cap).mean(axis=1)


def test_the_mean_of_repeats_has_the_law_of_averaged_captures():
    lam = np.tile(np.array([0.3, 4.0, 1000.0, 2.5e4]), (20000, 1))
    ref, deg = reference(lam)
    fast = ref.design_mean_capture(deg, 1, 2)[:, 0, 0]
    slow = averaged(ref, 2, 2)[:, 0, 0]
    assert fast.shape == slow.shape == lam.shape
    for col, lam_k in enumerate(lam[0]):
        # mean lam, variance lam / 2; halves only (a sum of two counts over 2)
        assert fast[:, col].mean() == pytest.approx(lam_k, rel=0.02)
        assert fast[:, col].var() == pytest.approx(lam_k / 2, rel=0.05)
        assert slow[:, col].var() == pytest.approx(fast[:, col].var(), rel=0.07)
        assert np.allclose(fast[:, col] * 2, np.round(fast[:, col] * 2))
    # the low-count bin's whole distribution: P(mean = k / 2) = Poisson(0.6) at k
    k, n = np.unique((fast[:, 0] * 2).astype(int), return_counts=True)
    assert np.allclose(n[:3] / fast.shape[0], stats.poisson.pmf(k[:3], 0.6), atol=0.01)


def test_saturated_sums_are_split_into_their_captures_and_clipped():
    # counts near the 24-bit ceiling: a capture saturates, so the mean of two clipped captures is not
    # the clipped mean; given their sum, the captures are binomial halves, clipped one by one
    ref, deg = reference(np.full((40000, 2), 2 ** 24 - 1 - 2000.0))
    cap = ref.sensor.max_count
    fast = ref.design_mean_capture(deg, 3, 2)
    slow = averaged(ref, 4, 2)
    assert fast.max() <= cap and slow.max() <= cap
    # both pulled under lam by the clip, by E[(X - M)+] = sigma (phi(z) - z (1 - Phi(z))) ~ 823 at z = 2000 / sigma
    # (the standard error of either mean is ~12)
    lam, z = 2 ** 24 - 1 - 2000.0, 2000.0 / np.sqrt(2 ** 24 - 1 - 2000.0)
    pull = np.sqrt(lam) * (stats.norm.pdf(z) - z * stats.norm.sf(z))
    assert fast.mean() == pytest.approx(slow.mean(), abs=50.0)
    assert fast.mean() == pytest.approx(lam - pull, abs=50.0) and pull > 700
    assert np.mean(fast == cap) == pytest.approx(np.mean(slow == cap), abs=0.01)
    # no saturation: nothing is clipped, the mean is lam
    free, deg = reference(np.full((40000, 2), 2 ** 24 - 1 - 2000.0), saturation=False)
    assert free.design_mean_capture(deg, 3, 2).mean() == pytest.approx(2 ** 24 - 1 - 2000.0, abs=50.0)
    assert free.design_mean_capture(deg, 3, 2).max() > cap


def test_the_draw_is_reproducible_for_a_seed():
    ref, deg = reference(np.full((50, 8), 30.0))
    assert np.array_equal(ref.design_mean_capture(deg, 5, 2), ref.design_mean_capture(deg, 5, 2))
    assert not np.array_equal(ref.design_mean_capture(deg, 5, 2), ref.design_mean_capture(deg, 6, 2))
