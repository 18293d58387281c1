"""Route ordering (nearest neighbour + 2-opt) and the gantry motion-time model."""

import numpy as np
import pytest

from nlosplan.errors import UserError
from nlosplan.planner.capture import MotionModel, order_batch
from nlosplan.planner.capture.route import _costs, path_cost


def test_move_time_is_triangular_then_trapezoidal():
    m = MotionModel(feed_mm_s=20.0, accel_mm_s2=50.0, settle_s=0.5, capture_s=1.0)
    # v^2/a = 8 mm: below it the speed never reaches the feed
    assert float(m.move_time(2.0)) == pytest.approx(2 * np.sqrt(2.0 / 50.0))
    assert float(m.move_time(100.0)) == pytest.approx(100.0 / 20.0 + 20.0 / 50.0)
    assert float(m.move_time(8.0)) == pytest.approx(0.8)  # both branches meet at d = v^2/a
    assert float(m.move_time(0.0)) == 0.0
    assert m.route_seconds((0, 0), [[100.0, 0.0], [100.0, 0.0]]) == pytest.approx(5.4 + 2 * 1.5)


@pytest.mark.parametrize("seed", range(8))
def test_ordered_route_is_never_longer_than_the_batch_as_given(seed):
    rng = np.random.default_rng(seed)
    pts = rng.uniform(0, 320, (9, 2))
    m = MotionModel()
    order, seconds, given = order_batch((0.0, 0.0), pts, m)
    assert sorted(order.tolist()) == list(range(9))
    assert seconds <= given + 1e-9
    cost = _costs((0.0, 0.0), pts, m)
    assert seconds == pytest.approx(path_cost(order + 1, cost))


def test_two_opt_removes_a_crossing_and_finds_the_straight_line():
    pts = np.array([[40.0, 0.0], [10.0, 0.0], [30.0, 0.0], [20.0, 0.0]])
    order, seconds, given = order_batch((0.0, 0.0), pts, MotionModel())
    assert pts[order, 0].tolist() == [10.0, 20.0, 30.0, 40.0]
    assert seconds < given


def test_bad_motion_settings_are_user_errors():
    with pytest.raises(UserError, match="feed_mm_s=0 must be a finite number > 0"):
        MotionModel(feed_mm_s=0)
    with pytest.raises(UserError, match="settle_s=-1 must be"):
        MotionModel(settle_s=-1)
