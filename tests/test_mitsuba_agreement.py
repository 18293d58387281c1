"""Reduced cross-validation (CI): twin and fast backend agree on DENALI objects.

The full table (3 models x 3 objects x 2 sizes x 10 positions) is made by
``nlosplan bench crossval``; here a few cases per model at the twin's cross-validation fidelity.
"""

import numpy as np
import pytest

from nlosplan.errors import UserError
from nlosplan.simulators.mitsuba.crossval import (
    CENTROID_TARGET_BINS,
    L1_TARGET,
    check_models,
    compare_signals,
    cross_validate,
    format_table,
)


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


@pytest.mark.parametrize("model, obj, position", [("mixed", "A", 19), ("mixed", "circle", 73), ("mount", "circle", 73)])
def test_twin_agrees_on_mixed_reflectance_and_mount(model, obj, position):
    result = cross_validate(objects=(obj,), sizes=("8in",), positions=(position,), models=(model,))
    (case,) = result["cases"]
    assert case["model"] == model
    assert case["rel_l1"] <= L1_TARGET, case
    assert case["centroid_shift_bins"] <= CENTROID_TARGET_BINS, case
    assert 0.95 < case["total_ratio"] < 1.05, case
    assert f"| {model} | {obj} | 8in | 1 |" in format_table(result)


def test_unknown_crossval_model_is_one_line_error():
    with pytest.raises(UserError, match="unknown cross-validation model 'glossy'; allowed: lambertian, mixed, mount"):
        check_models(["mixed", "glossy"])
    with pytest.raises(UserError, match="no cross-validation model"):
        check_models([])
