"""Reduced cross-validation (CI): twin and fast backend agree on Lambertian DENALI objects.

The full table (3 objects x 2 sizes x 10 positions) is made by
``nlosplan bench crossval``; here two cases at the twin's cross-validation fidelity.
"""

import numpy as np
import pytest

from nlosplan.simulators.mitsuba.crossval import CENTROID_TARGET_BINS, L1_TARGET, compare_signals, cross_validate


def test_compare_signals_metrics():
    b = np.zeros((2, 10))
    b[0, 4] = 3.0
    b[1, 6] = 1.0
    a = b.copy()
    a[0, 4], a[0, 5] = 2.0, 1.0  # a third of zone 0 moved one bin later
    m = compare_signals(a, b)
    assert m["rel_l1"] == pytest.approx(2.0 / 4.0)
    assert m["centroid_shift_bins"] == pytest.approx(1.0 / 3.0)
    assert m["total_ratio"] == pytest.approx(1.0)


def test_twin_agrees_with_fast_backend_on_two_cases():
    result = cross_validate(objects=("A", "circle"), sizes=("8in",), positions=(19, 73))
    assert result["summary"]["cases"] == 4
    for case in result["cases"]:
        assert case["rel_l1"] <= L1_TARGET, case
        assert case["centroid_shift_bins"] <= CENTROID_TARGET_BINS, case
        assert 0.95 < case["total_ratio"] < 1.05, case
