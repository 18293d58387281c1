"""Keep-out: gantry limits and the direct-view ray test against the zone cones."""

import numpy as np
import pytest

from nlosplan.errors import UserError
from nlosplan.planner.capture import direct_view_zones, grid_points, region_points, screen_candidates
from nlosplan.sensor_models import preset
from nlosplan.simulators import corner_scene

SENSOR = preset("tmf8828-3x3-short")


def corner(x_mm, y_mm):
    """Corner scene: LiDAR 0.5 m from the wall, a 10 cm patch at lateral x, y in front of the wall (mm)."""
    return corner_scene(object_xy=(x_mm / 1000.0, y_mm / 1000.0))


def test_an_object_between_lidar_and_wall_is_seen_by_every_zone():
    assert direct_view_zones(corner(0, 250), SENSOR) == [(r, c) for r in range(3) for c in range(3)]


def test_an_object_beside_the_cone_is_hidden_and_one_at_its_edge_is_seen_by_one_column():
    assert direct_view_zones(corner(450, 300), SENSOR) == []
    assert direct_view_zones(corner(100, 300), SENSOR) == [(0, 2), (1, 2), (2, 2)]
    # the cone's half-width 0.2 m from the LiDAR is 0.2 tan(16.5 deg) = 59.3 mm; the patch's near edge is at x - 50
    assert direct_view_zones(corner(105, 300), SENSOR) != []
    assert direct_view_zones(corner(110, 300), SENSOR) == []


def test_screening_removes_limits_and_direct_view_with_reasons():
    pts = [[0, 250], [450, 300], [500, 300], [-450, 300]]
    cand = screen_candidates(pts, limits=((-480, 480), (0, 400)), scene_fn=corner, sensor=SENSOR)
    assert cand.points_mm.tolist() == [[450, 300], [-450, 300]]
    reasons = {(e["x_mm"], e["y_mm"]): e["reason"] for e in cand.excluded}
    assert reasons[(0.0, 250.0)].startswith("object in the LiDAR's direct view (zones 0,0, 0,1")
    assert reasons[(500.0, 300.0)] == "outside the gantry limits x -480-480 mm, y 0-400 mm"
    assert len(reasons) == 2


def test_denali_rig_positions_are_all_nlos():
    from nlosplan.planner.capture import denali_scene_fn

    cand = screen_candidates(grid_points(3, 3), scene_fn=denali_scene_fn(), sensor=SENSOR)
    assert len(cand.points_mm) == 9 and cand.excluded == []


def test_candidate_generators():
    g = grid_points(3, 2, (0, 100), (0, 50))
    assert g.tolist() == [[0, 0], [50, 0], [100, 0], [0, 50], [50, 50], [100, 50]]
    r = region_points(64, (10, 20), (30, 40), seed=1)
    assert r.shape == (64, 2) and r[:, 0].min() >= 10 and r[:, 1].max() <= 40
    assert np.unique(r.round(6), axis=0).shape[0] == 64
    with pytest.raises(UserError, match="must be finite"):
        screen_candidates([[np.nan, 0]])
