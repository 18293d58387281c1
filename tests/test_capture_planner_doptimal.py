"""D-optimal designs with known answers, rounding, and joint batch selection (diversity, motion cost)."""

import numpy as np
import pytest

from nlosplan.errors import UserError
from nlosplan.planner.capture import MotionModel, batch_information, relaxed_doptimal, round_design, select_batch
from nlosplan.planner.capture.doptimal import exchange, logdet


def regression(degree: int, n: int = 21):
    x = np.linspace(-1, 1, n)
    f = np.stack([x ** k for k in range(degree + 1)], axis=1)
    return x, f[:, :, None] * f[:, None, :]


def test_quadratic_regression_approximate_design_is_one_third_at_minus_one_zero_one():
    # Kiefer-Wolfowitz: the D-optimal approximate design for a quadratic on [-1, 1]
    x, fis = regression(2)
    w = relaxed_doptimal(fis, 1.0, upper=1.0)
    assert w.sum() == pytest.approx(1.0, abs=1e-6)
    support = np.flatnonzero(w > 1e-3)
    assert x[support].tolist() == [-1.0, 0.0, 1.0]
    np.testing.assert_allclose(w[support], 1 / 3, atol=1e-4)


def test_linear_regression_batch_of_two_takes_the_two_ends():
    x, fis = regression(1)
    w = relaxed_doptimal(fis, 2.0)
    assert sorted(x[round_design(w, 2, fis)].tolist()) == [-1.0, 1.0]


def test_cubic_batch_of_four_is_the_exact_design():
    # exact D-optimal 4-point design for a cubic on [-1, 1]: +-1 and +-1/sqrt(5) (grid points nearest)
    x, fis = regression(3, n=201)
    batch = round_design(relaxed_doptimal(fis, 4.0), 4, fis)
    np.testing.assert_allclose(sorted(x[batch]), [-1, -1 / np.sqrt(5), 1 / np.sqrt(5), 1], atol=0.006)


def test_rounding_respects_allowed_and_exchange_never_lowers_the_criterion():
    x, fis = regression(2)
    allowed = np.abs(x) < 0.95  # the ends are taken already
    w = relaxed_doptimal(fis[allowed], 3.0)
    full = np.zeros(len(x))
    full[allowed] = w
    batch = round_design(full, 3, fis, allowed=allowed)
    assert all(allowed[batch])
    assert sorted(x[batch].round(2).tolist()) == [-0.9, 0.0, 0.9]
    start = [8, 9, 10]
    better = exchange(start, fis, np.eye(3) * 1e-6)
    assert logdet(fis[better].sum(0) + np.eye(3) * 1e-6) >= logdet(fis[start].sum(0) + np.eye(3) * 1e-6)


def test_design_size_and_shapes_are_checked():
    _, fis = regression(1, n=3)
    with pytest.raises(UserError, match=r"design size n=4 must be in \(0, 3\]"):
        relaxed_doptimal(fis, 4)
    with pytest.raises(UserError, match="information matrices must be"):
        relaxed_doptimal(np.ones((3, 2)), 1)


def _clusters():
    """Six candidates: three copies of a strong direction e1, three of a weaker e2."""
    v = np.array([[3, 0]] * 3 + [[0, 2]] * 3, dtype=float)
    return v[:, :, None] * v[:, None, :]


def test_joint_batch_is_diverse_where_the_top_n_of_one_score_is_not():
    fis = _clusters()
    prior = np.eye(2)
    single = [batch_information([c], fis, prior) for c in range(6)]
    top2 = np.argsort(single)[::-1][:2]
    assert set(top2) <= {0, 1, 2}  # the top-n of one score repeats direction e1
    batch = select_batch(fis, prior, 2)
    assert {batch[0] // 3, batch[1] // 3} == {0, 1}
    assert batch_information(batch, fis, prior) > batch_information(top2, fis, prior)


def test_motion_aware_batch_prefers_the_near_candidate_of_equal_information():
    v = np.array([[1.0, 0.0], [1.0, 0.0], [0.0, 1.0], [0.0, 1.0]])
    fis = v[:, :, None] * v[:, None, :]
    pts = np.array([[300.0, 300.0], [10.0, 0.0], [320.0, 0.0], [0.0, 10.0]])
    batch = select_batch(fis, np.eye(2), 2, points_mm=pts, start_mm=(0, 0), motion=MotionModel())
    assert sorted(batch) == [1, 3]
    far = select_batch(fis, np.eye(2), 2)  # without motion, ties go to the first index
    assert sorted(far) == [0, 2]
