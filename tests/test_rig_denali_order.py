"""nlosplan's position p is DENALI's capture p at the same gantry place: the order of DENALI's capture code.

The reference below restates, in our own code, what DENALI's capture script does (facts read from
NikhilBehari/denali ``capture/capture_spad_nlos.py`` and the cc-hardware it vendors,
``drivers/stepper_motors/stepper_controller.py::SnakeStepperController.get_position`` and
``telemetrix_stepper.py``): axes ``x`` then ``y``, each ``np.linspace(0, 32, 10)`` cm; every axis starts
"flipped" and toggles its flip whenever ``iter % samples == 0``; the first axis takes
``positions[(iter // stride) % n]`` with ``stride = total / n`` and never reverses; the second takes
``positions[iter % n]``, reversed while flipped. The script calls it once per capture, ``iter = 0, 1, ...``,
and moves ``gantry.move_to(x, y)`` with x on the motor at pins 2/5.
"""

import numpy as np
import pytest

from nlosplan.denali import grid_index, grid_mm, label_xy, object_pose, object_pose_mm, tag1_positions
from nlosplan.hardware.plans import raster_plan
from nlosplan.hardware.status import plan_steps
from nlosplan.hardware.telemetrix_config import TelemetrixConfig


class DenaliSnake:
    """DENALI's stateful snake controller, as its capture loop drives it (one call per capture, in order)."""

    def __init__(self, axes=(("x", (0.0, 32.0), 10), ("y", (0.0, 32.0), 10))):
        self.axes = [{"name": n, "index": i, "positions": np.linspace(lo, hi, k), "flipped": True}
                     for i, (n, (lo, hi), k) in enumerate(axes)]
        self.total = int(np.prod([len(a["positions"]) for a in self.axes]))

    def position(self, it: int):
        if it >= self.total:
            return None
        out, stride = {}, self.total
        for a in self.axes:
            n = len(a["positions"])
            stride //= n
            if it % n == 0:
                a["flipped"] = not a["flipped"]
            i = (it // stride) % n
            if a["index"] % 2 == 1 and a["flipped"]:
                i = n - 1 - i
            out[a["name"]] = float(a["positions"][i])
        return out


def test_position_p_is_denalis_capture_p_at_the_same_gantry_place():
    snake = DenaliSnake()
    denali_cm = [snake.position(p) for p in range(100)]
    assert snake.position(100) is None
    for p, pos in enumerate(denali_cm):
        assert grid_mm(p) == pytest.approx((10 * pos["x"], 10 * pos["y"]), abs=1e-9), p
        assert grid_index(*grid_mm(p)) == p
    # x is the slow axis, y the serpentine one: 0 -> 1 moves y only, 9 -> 10 moves x only (one pitch)
    assert grid_mm(1)[0] == grid_mm(0)[0] and grid_mm(1)[1] > grid_mm(0)[1]
    assert grid_mm(10)[1] == grid_mm(9)[1] == pytest.approx(320.0) and grid_mm(10)[0] > grid_mm(9)[0]


def test_denalis_poses_stay_indexed_by_capture_and_the_scan_is_a_snake_in_the_world():
    tags = np.asarray(tag1_positions())[:, :2]
    for p in range(100):
        np.testing.assert_allclose(object_pose_mm(*grid_mm(p)), object_pose(p), atol=1e-12)
        np.testing.assert_allclose(label_xy(*grid_mm(p)), tags[p], atol=1e-12)
    # DENALI's own poses: consecutive captures are neighbours (one pitch, ~3.6 cm), including 9 -> 10
    step = np.linalg.norm(np.diff(tags, axis=0), axis=1)
    assert np.all((step > 0.025) & (step < 0.05))
    # gantry y (the serpentine axis) moves the tag along one world direction, gantry x along the other
    dy, dx = tags[1] - tags[0], tags[10] - tags[9]
    assert abs(dy[0]) > 5 * abs(dy[1]) and abs(dx[1]) > 5 * abs(dx[0])


def test_the_raster_plan_drives_denalis_motors_in_denalis_order():
    cfg = TelemetrixConfig()
    assert (cfg.x.step_pin, cfg.x.dir_pin, cfg.y.step_pin, cfg.y.dir_pin) == (2, 5, 3, 6)   # x on motor 0, pins 2/5
    steps = [cfg.to_steps(x, y) for _, x, y, _ in plan_steps(raster_plan(repeats=1, settle_s=0.0))]
    assert len(steps) == 100
    moved = [tuple(a != b for a, b in zip(s, t)) for s, t in zip(steps, steps[1:])]
    # within a column only the y motor (1) moves; between columns only the x motor (0)
    assert [m for i, m in enumerate(moved) if (i + 1) % 10] == [(False, True)] * 90
    assert [m for i, m in enumerate(moved) if (i + 1) % 10 == 0] == [(True, False)] * 9
