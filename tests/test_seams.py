"""One name and one type at each seam (issue 15): the planner protocol, the typed design job, the scoring module,
the unknown-key check and the impulse-response width."""

import hashlib
import json
import math
import pickle

import numpy as np
import pytest

from nlosplan.errors import UserError, check_keys
from nlosplan.planner.design.jobs import DesignJob, OptimizeJob
from nlosplan.planner.design.requirements import Condition, Requirement, parse_requirement
from nlosplan.planner.design.space import Design, DesignSpace
from nlosplan.planner.protocol import AskTellPlanner
from nlosplan.sensor_models.impulse import impulse_fwhm_ps, impulse_sigma_ps
from nlosplan.tasks.metrics import loc_rms_distance, loc_rmse, regression_metrics, top1_accuracy


def _job(condition=None) -> DesignJob:
    return DesignJob("trained", "size", Design(zones=(2, 2), jitter_fwhm_ps=150.0), 3, {"model": "mlp", "epochs": 5},
                     condition, "/some/out/reference/3x3_abc.npz", {"name": "ref"})


def test_design_job_pickles_and_keeps_the_logged_key_of_its_dict_form():
    job = _job(Condition("size", "4in"))
    again = pickle.loads(pickle.dumps(job))
    assert again == job and again.key == job.key and isinstance(again.condition, Condition)
    # the key is the one resume looks up in old logs: sha1 of the plain fields, condition as "col=value",
    # the reference by file name only
    fields = {"evaluator": "trained", "task": "size", "design": job.design.to_dict(), "seed": 3,
              "fidelity": {"model": "mlp", "epochs": 5}, "condition": "size=4in", "reference": "3x3_abc.npz"}
    assert job.key == hashlib.sha1(json.dumps(fields, sort_keys=True, default=str).encode()).hexdigest()[:16]
    moved = DesignJob(**{**job.__dict__, "reference": "/elsewhere/3x3_abc.npz"})
    assert moved.key == job.key and _job(None).key != job.key
    record = job.to_dict()
    assert record["condition"] == "size=4in" and record["design"] == job.design.to_dict() and record["key"] == job.key
    json.dumps(record)  # a result record is plain data


def test_condition_is_parsed_once_into_data():
    req = parse_requirement("size>=0.9@lights=on")
    assert isinstance(req.condition, Condition) and req.condition == ("lights", "on")
    assert str(req.condition) == "lights=on" and req.name.endswith("[lights=on]")
    assert Requirement.from_dict(req.to_dict()) == req and Requirement.from_dict(req.to_dict()).condition == req.condition
    assert Condition.parse(None) is None and Condition.parse("nonsense") is None
    assert Requirement("size", 0.9, ("size", "4in")).condition == Condition("size", "4in")
    import pandas as pd

    labels = pd.DataFrame({"size": ["4in", "8in", "4in"], "lights": ["on", "on", "off"]})
    assert Condition("size", "4in").mask(labels).tolist() == [True, False, True]
    assert Condition("lights", "off").mask(labels).tolist() == [False, False, True]


def test_optimize_job_pickles_with_its_space_and_makes_bound_jobs():
    space = DesignSpace()
    req = Requirement("loc", 0.05, ("size", "8in"))
    job = OptimizeJob(req, 0.3, space, None, space.reference_design(), 10, {"draws": 100}, "r.npz", {"n": 1})
    again = pickle.loads(pickle.dumps(job))
    assert again.space == space and again.space.sensor == space.sensor and again.requirement == req
    bound = again.bound_job(space.reference_design())
    assert (bound.evaluator, bound.task, bound.seed, bound.condition) == ("bound", "loc", 0, req.condition)


def test_planners_speak_suggest_and_ingest():
    from nlosplan.planner.capture.closed_loop import ClosedLoop
    from nlosplan.planner.capture.planner import CapturePlanner
    from nlosplan.planner.design.search import DesignSearch

    for cls in (DesignSearch, CapturePlanner, ClosedLoop):
        assert callable(getattr(cls, "suggest", None)) and callable(getattr(cls, "ingest", None)), cls
        assert not hasattr(cls, "ask") and not hasattr(cls, "tell"), cls
    assert isinstance(ClosedLoop(planner=None), AskTellPlanner)


def test_loc_rms_distance_is_the_2d_rms_and_sqrt2_times_denalis_pooled_rmse():
    rng = np.random.default_rng(0)
    truth = rng.uniform(0, 0.3, (50, 2))
    pred = truth + rng.normal(0, 0.02, (50, 2))
    d2 = ((pred - truth) ** 2).sum(axis=1)
    assert loc_rms_distance(pred, truth) == math.sqrt(float(d2.mean()))
    assert loc_rms_distance(pred, truth) == pytest.approx(math.sqrt(2) * regression_metrics(pred, truth)["loc_rmse"])
    assert loc_rms_distance([[3.0, 4.0]], [[0.0, 0.0]]) == 5.0


def test_loc_rmse_pools_x_and_y_as_denali():
    """DENALI's RMSE: sqrt of the mean over the N x 2 entries (its benchmark/main_table/metrics.py)."""
    rng = np.random.default_rng(1)
    truth = rng.uniform(0, 0.3, (40, 2))
    pred = truth + rng.normal(0, 0.02, (40, 2))
    assert loc_rmse(pred, truth) == math.sqrt(float(np.mean((pred - truth) ** 2)))
    assert loc_rmse(pred, truth) == regression_metrics(pred, truth)["loc_rmse"]
    assert loc_rmse([[3.0, 4.0]], [[0.0, 0.0]]) == pytest.approx(math.sqrt(12.5))  # a 5 m distance: 5 / sqrt(2)
    with pytest.raises(UserError, match="must both be"):
        loc_rmse([[1.0, 2.0, 3.0]], [[0.0, 0.0, 0.0]])


def test_top1_accuracy():
    scores = np.array([[0.1, 0.9], [0.8, 0.2], [0.3, 0.7], [0.6, 0.4]])
    assert top1_accuracy(scores, [1, 0, 0, 1]) == 0.5
    assert top1_accuracy(scores, [1, 0, 1, 0]) == 1.0


def test_check_keys_names_unknown_keys_sorted_and_allowed_in_order():
    check_keys({"a": 1}, ("a", "b"), "thing(s)")
    with pytest.raises(UserError, match=r"^f\.toml: unknown thing\(s\) x, y in \[t\]; allowed: b, a$"):
        check_keys({"y": 1, "x": 2, "a": 3}, ("b", "a"), "thing(s)", prefix="f.toml: ", suffix=" in [t]")


@pytest.mark.parametrize("pulse, jitter", [(0.0, 0.0), (30.0, 0.0), (0.0, 100.0), (300.0, 400.0), (1e-3, 1e5)])
def test_impulse_width_adds_in_quadrature_for_floats_and_arrays(pulse, jitter):
    from nlosplan._jax import jax, jnp

    fwhm = impulse_fwhm_ps(pulse, jitter)
    assert fwhm == math.hypot(pulse, jitter)
    assert impulse_sigma_ps(pulse, jitter) == fwhm / 2.3548200450309493
    traced = impulse_fwhm_ps(jnp.float64(pulse), jnp.float64(jitter))
    assert float(traced) == pytest.approx(fwhm, rel=1e-15, abs=0)
    grad = jax.grad(lambda p: impulse_sigma_ps(p, jnp.float64(jitter)))(jnp.float64(pulse))
    assert np.isfinite(float(grad))  # finite at zero width too


def test_sensor_sigma_is_the_impulse_sigma():
    from nlosplan.sensor_models import preset

    s = preset("tmf8828-3x3-short").replace(pulse_fwhm_ps=120.0, jitter_fwhm_ps=90.0)
    assert s.impulse_sigma_ps == impulse_sigma_ps(120.0, 90.0) == 150.0 / 2.3548200450309493


def test_capture_planner_localizer_scores_with_denalis_loc_rmse():
    """The capture planner's ensemble (and so rig run's --target-rmse) uses the pooled loc_rmse, not the 2-D RMS."""
    from nlosplan.planner.capture.ensemble import EnsembleLocalizer

    rng = np.random.default_rng(2)
    xy = rng.uniform(0, 0.3, (30, 2))
    hist = np.hstack([xy * 100, rng.uniform(0, 1, (30, 4))]) + 5.0
    loc = EnsembleLocalizer(hist.mean(axis=0), members=3, seed=0).fit(hist, xy)
    test_xy = rng.uniform(0, 0.3, (10, 2))
    test_h = np.hstack([test_xy * 100, rng.uniform(0, 1, (10, 4))]) + 5.0
    pred = loc.predict(test_h)
    assert loc.loc_rmse(test_h, test_xy) == pytest.approx(loc_rmse(pred, test_xy), rel=1e-12)
    assert loc.loc_rmse(test_h, test_xy) == pytest.approx(loc_rms_distance(pred, test_xy) / math.sqrt(2), rel=1e-12)
