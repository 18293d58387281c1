"""One localization metric, DENALI's loc_rmse: the benchmark table, the jitter study and the design planner's
trained evaluator (whose report the resolution/bins studies print) give the same number for the same model and
data, and print it."""

import math

import numpy as np
import pytest
from synthetic_tasks import synthetic_dataset

from nlosplan.planner.design.evaluators import trained_metric
from nlosplan.tasks.metrics import loc_rms_distance, loc_rmse

pytestmark = pytest.mark.usefixtures("one_torch_thread")

SEED, EPOCHS, WIDTH = 3, 6, 0.25


@pytest.fixture(scope="module")
def ds():
    return synthetic_dataset(n_side=5, bins=32, repeats=1, objects=("1", "A", "circle"))  # 150 scenes


def test_benchmark_jitter_study_and_design_evaluator_print_the_same_loc_rmse(ds):
    from nlosplan.experiments.jitter import JitterStudy, run_jitter_study
    from nlosplan.reports.benchmark_table import benchmark_table, benchmark_text
    from nlosplan.reports.design_report import _fmt_metric
    from nlosplan.tasks.benchmark import run_benchmark

    bench = run_benchmark(ds, models=("mlp",), tasks=("loc",), seed=SEED, epochs=EPOCHS, width=WIDTH)
    b = float(benchmark_table(bench, "loc").loc["mlp", ("loc_rmse", "all")])
    study = run_jitter_study(ds, JitterStudy(jitter_ps=(0.0,), models=("mlp",), tasks=("loc",), zone="all",
                                             seed=SEED, epochs=EPOCHS, width=WIDTH))
    j = next(r["value"] for r in study["rows"] if r["metric"] == "loc_rmse" and r["group"] == "all")
    value, (lo, hi), extra = trained_metric(ds, "loc", {"model": "mlp", "epochs": EPOCHS, "width": WIDTH,
                                                        "bootstrap": 50}, SEED)
    assert value == pytest.approx(b, rel=1e-9) and j == pytest.approx(b, rel=1e-9)
    assert lo <= value <= hi
    # the 2-D RMS distance is reported beside it under its own name, sqrt(2) larger
    assert extra["loc_rms_distance"] == pytest.approx(math.sqrt(2) * value, rel=0.25)
    assert extra["loc_rms_distance"] > value
    # printed: metres in the benchmark table, centimetres in the design report: the same figure
    assert f"{b:.4f}" in benchmark_text(bench)
    assert _fmt_metric("loc", value) == f"{100 * b:.1f} cm"


def test_design_requirements_are_stated_in_loc_rmse():
    from nlosplan.planner.design.requirements import METRIC_OF_TASK, parse_requirement
    from nlosplan.planner.design.summary import metric_definitions

    assert METRIC_OF_TASK["loc"][0] == "loc_rmse"
    assert parse_requirement("loc<=0.05").name == "loc loc_rmse <= 0.05 m"
    defs = metric_definitions()
    assert "pooled" in defs["loc_rmse"] and "sqrt(2) x loc_rmse" in defs["loc_rms_distance"]
    assert {"verdict met", "verdict not met", "verdict undecided"} <= set(defs)


def test_the_design_bound_is_on_loc_rmse_scale():
    """The design's CRLB halves the (x, y) trace under the root: 1 cm per axis is a loc_rmse bound of 1 cm."""
    import pandas as pd

    from nlosplan.planner.design.evaluators import _crlb

    class Ref:  # one bound scene: bin 0 informs x, bin 1 y, bin 2 the photon scale; 1e4 counts each
        crlb_labels = pd.DataFrame({"size": ["8in"]})

        def design_crlb(self, deg):
            lam = np.full((1, 1, 1, 3), 1e4)
            jac = np.zeros((1, 1, 1, 3, 3))
            jac[0, 0, 0, 0, 0] = jac[0, 0, 0, 1, 1] = 1e4  # Fisher 1e4 per m^2: a 1 cm standard deviation
            jac[0, 0, 0, 2, 2] = 1e4
            return lam, jac

    value, note = _crlb(Ref(), None, 1, None)
    assert note == ""
    assert value == pytest.approx(0.01, rel=1e-9)  # the 2-D RMS distance bound would be 1.41 cm
    truth = np.zeros((1, 2))
    assert loc_rmse([[value, value]], truth) == pytest.approx(value)
    assert loc_rms_distance([[value, value]], truth) == pytest.approx(math.sqrt(2) * value)
