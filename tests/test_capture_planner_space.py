"""The planner's counts model equals the simulator, and its calibration Jacobian equals the simulator's derivatives."""

import numpy as np
import pytest

from nlosplan.planner.capture import build_space, denali_scene_fn
from nlosplan.sensor_models import preset
from nlosplan.simulators import FastSimulator
from nlosplan.tasks.bounds import counts_and_jacobian

SENSOR = preset("tmf8828-3x3-short").linear_uniform()  # the planner's counts model is linear
POINTS = [[0.0, 0.0], [200.0, 120.0]]


@pytest.mark.slow
def test_counts_and_jacobian_match_the_differentiable_simulator():
    space = build_space(POINTS, SENSOR, fidelity="draft")
    scenes = [denali_scene_fn()(x, y) for x, y in POINTS]
    direct = FastSimulator(scenes, SENSOR, fidelity="draft", dtype="float64").expected().reshape(2, -1)
    np.testing.assert_allclose(space.counts(), direct, rtol=1e-9, atol=1e-6)
    lam, jac, names, _ = counts_and_jacobian(scenes, SENSOR, fidelity="draft", nuisance=("photon_scale", "albedo"))
    assert names == ("x", "y", "log_photon_scale", "log_albedo")
    mine = space.jacobian()
    scale = np.abs(jac).max(axis=(1, 2), keepdims=True)
    np.testing.assert_allclose(mine, jac.reshape(2, -1, 4), rtol=1e-6, atol=1e-9 * scale.max())
    assert np.all(space.labels_xy[:, 0] > 0.9) and space.shape == (3, 3, 128)
