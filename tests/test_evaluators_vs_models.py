"""The fast evaluators against trained models on the same simulated data.

* The localization Cramér–Rao bound sits below the RMSE a trained model
  reaches on positions it has not seen, and tightens as photons grow.
* The ideal observer is at least as accurate as trained classifiers when the
  classes differ only through the simulator's expected histograms (the data
  differ by Poisson noise alone).

Both sides use one sensor, one fidelity and one set of expected counts, so
any violation is a bug in the bound, the observer or the data path.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from nlosplan.sensor_models import preset
from nlosplan.simulators import denali_scene
from nlosplan.simulators.fast.simulator import FastSimulator
from nlosplan.tasks.bounds import localization_crlb_batch
from nlosplan.data.dataset import Dataset
from nlosplan.tasks.ideal_observer import ideal_observer
from nlosplan.tasks.metrics import classification_metrics, regression_metrics
from nlosplan.tasks.splits import heldout_positions
from nlosplan.tasks.training import TrainConfig, train_model

SENSOR = preset("tmf8828-3x3-short")
FIDELITY = "draft"


def _noisy(means: np.ndarray, draws: int, rng: np.random.Generator) -> np.ndarray:
    """Poisson captures, shape (draws, *means.shape), float32."""
    return rng.poisson(np.broadcast_to(means, (draws, *means.shape))).astype(np.float32)


@pytest.fixture(scope="module")
def localization_data():
    """Object A (8 in) at all 100 positions, 12 Poisson captures each, with the scenes."""
    scenes = [denali_scene("A", "8in", p) for p in range(100)]
    means = FastSimulator(scenes, SENSOR, fidelity=FIDELITY, dtype="float64").expected()  # (100, 3, 3, 128)
    draws = 12
    hist = _noisy(np.asarray(means), draws, np.random.default_rng(5))  # (draws, 100, 3, 3, 128)
    hist = hist.transpose(1, 0, 2, 3, 4).reshape(-1, *means.shape[1:])
    rows = [dict(object="A", size="8in", class_group="letters", position=s.meta["position"],
                 x=s.meta["object_xy"][0], y=s.meta["object_xy"][1], lights="off", zones="3x3", repeat=r,
                 source="test") for s in scenes for r in range(draws)]
    return scenes, Dataset(hist, pd.DataFrame(rows), SENSOR.bin_width_ps)


def test_crlb_is_below_a_trained_models_rmse_on_unseen_positions(localization_data):
    scenes, ds = localization_data
    split = heldout_positions(ds, test_size=0.3, seed=3)
    train, test = ds.take(split.train), ds.take(split.test)
    xy = ["x", "y"]
    model = train_model(train.histograms, train.labels[xy].to_numpy(), model="mlp", task="loc", width=0.5,
                        config=TrainConfig(max_epochs=60, patience=8, seed=0))
    pred = model.predict(test.histograms)
    rmse = regression_metrics(pred, test.labels[xy].to_numpy())["loc_rmse"]

    test_positions = sorted(set(test.labels["position"]))
    bound = localization_crlb_batch([scenes[p] for p in test_positions], SENSOR, fidelity=FIDELITY, repeats=1,
                                    nuisance=("photon_scale",))
    assert not bound.unidentifiable
    # The model learnt something (well under the 12 cm spread of the grid) ...
    spread = float(np.sqrt(test.labels[xy].var(ddof=0).sum()))
    assert rmse < 0.6 * spread
    # ... and no unbiased estimator can beat the bound; the trained model does not either. Both on DENALI's
    # pooled loc_rmse: the bound's trace over (x, y) is a 2-D mean square, halved under the root.
    print(f"MLP loc_rmse {rmse:.4f} m; CRLB {bound.loc_rmse_bound_m:.4f} m (2-D {bound.rms_bound_m:.4f} m)")
    assert bound.loc_rmse_bound_m == pytest.approx(bound.rms_bound_m / np.sqrt(2), rel=1e-12)
    assert 0 < bound.rms_bound_known_m <= bound.rms_bound_m
    assert bound.loc_rmse_bound_m <= rmse

    # Four times the integration time: every mean (signal and dark) grows 4x, the bound halves exactly.
    test_scenes = [scenes[p] for p in test_positions]
    longer = localization_crlb_batch(test_scenes, SENSOR.replace(iterations=4 * SENSOR.iterations),
                                     fidelity=FIDELITY, repeats=1, nuisance=("photon_scale",))
    assert longer.rms_bound_m == pytest.approx(bound.rms_bound_m / 2, rel=0.01)
    # Four times the laser power (signal only; the dark counts stay): per bin the information grows by
    # between 4x (signal-dominated) and 16x (dark-dominated), so the bound shrinks by between 2x and 4x.
    brighter = localization_crlb_batch(test_scenes, SENSOR.replace(photon_scale=4 * SENSOR.photon_scale),
                                       fidelity=FIDELITY, repeats=1, nuisance=("photon_scale",))
    assert bound.rms_bound_known_m / 4 * 0.99 <= brighter.rms_bound_known_m <= bound.rms_bound_known_m / 2 * 1.01
    assert brighter.rms_bound_m < bound.rms_bound_m / 2 * 1.01


OBJECTS = ("A", "S", "circle", "plus", "1", "7")
POSITIONS = (10, 45, 80)
DIM = SENSOR.replace(photon_scale=0.1)  # IO accuracy ~85 %: far from both chance and 100 %


@pytest.fixture(scope="module")
def shape_data():
    """Six objects (8 in) at three positions on a dim sensor: train and test captures, shape (N, 3, 3, 128)."""
    scenes = [denali_scene(o, "8in", p) for o in OBJECTS for p in POSITIONS]
    means = np.asarray(FastSimulator(scenes, DIM, fidelity=FIDELITY, dtype="float64").expected())
    labels = np.repeat(np.arange(len(OBJECTS)), len(POSITIONS))
    rng = np.random.default_rng(11)

    def draw(n):
        h = _noisy(means, n, rng)  # (n, scenes, 3, 3, 128)
        return h.reshape(-1, *means.shape[1:]), np.tile(labels, n)

    return draw(150), draw(40)


@pytest.mark.parametrize("model", ["mlp", pytest.param("cnn1d", marks=pytest.mark.slow)])  # cnn1d ~45 s: CI
def test_ideal_observer_is_at_least_as_accurate_as_trained_classifiers(shape_data, model):
    (x_train, y_train), (x_test, y_test) = shape_data
    trained = train_model(x_train, y_train, model=model, task="shape", width=0.5,
                          config=TrainConfig(max_epochs=40, patience=6, seed=0), classes=[str(i) for i in range(6)])
    scores = trained.predict(x_test)
    acc = classification_metrics(scores, y_test)["top1_acc"]
    io = ideal_observer("shape", DIM, objects=list(OBJECTS), size="8in", positions=list(POSITIONS), draws=400,
                        seed=1, fidelity=FIDELITY)
    chance = 1 / len(OBJECTS)
    # Both are informative, so the comparison means something.
    assert io.accuracy > chance + 0.4
    assert acc > chance + 0.1
    # Bayes-optimal: no classifier beats it beyond sampling error of the two estimates.
    se_model = math.sqrt(acc * (1 - acc) / len(y_test))
    print(f"{model}: top-1 {acc:.3f}; ideal observer {io.accuracy:.3f} {io.ci}")
    assert acc <= io.ci[1] + 2 * se_model, (acc, io.accuracy, io.ci)
    assert io.fidelity == FIDELITY and io.seconds > 0
