"""Training: models learn learnable data, seeds reproduce, early stopping restores, checkpoints are safe."""

import os

import numpy as np
import pytest
import torch
from synthetic_tasks import synthetic_dataset

from nlosplan.errors import UserError
from nlosplan.tasks.metrics import regression_metrics
from nlosplan.tasks.models import MODEL_NAMES
from nlosplan.tasks.benchmark import denali_config
from nlosplan.tasks.splits import make_split
from nlosplan.tasks.training import (Preprocessing, TrainConfig, apply_histogram_transform,
                                     load_checkpoint, save_checkpoint, train_model)


pytestmark = pytest.mark.usefixtures("one_torch_thread")


@pytest.fixture(scope="module")
def ds():
    return synthetic_dataset(n_side=6, bins=32)  # 6 objects x 2 sizes x 36 positions


def _fit(ds, task, model="mlp", **cfg):
    sp = make_split(ds, "random", task)
    train, test = ds.take(sp.train), ds.take(sp.test)
    y_train = train.labels[["x", "y"]].to_numpy() if task == "loc" else \
        train.labels["object" if task == "shape" else "size"].to_numpy()
    config = TrainConfig(**({"max_epochs": 30, "patience": 6} | cfg))
    return train_model(train.histograms, y_train, model=model, task=task, config=config, width=0.25), train, test


def test_mlp_localizes(ds):
    trained, _, test = _fit(ds, "loc")
    true = test.labels[["x", "y"]].to_numpy()
    rmse = regression_metrics(trained.predict(test.histograms), true)["loc_rmse"]
    spread = np.sqrt(np.mean((true - true.mean(axis=0)) ** 2))  # RMSE of always guessing the mean
    assert rmse < 0.35 * spread, (rmse, spread)


@pytest.mark.parametrize("model,task,floor", [("mlp", "shape", 0.8), ("cnn1d", "shape", 0.5), ("mlp", "size", 0.9)])
def test_classifiers_beat_chance_by_far(ds, model, task, floor):
    trained, _, test = _fit(ds, task, model=model)
    col = "object" if task == "shape" else "size"
    assert trained.classes == tuple(sorted(ds.labels[col].unique()))
    pred = trained.predict_labels(test.histograms)
    acc = float(np.mean(pred == test.labels[col].to_numpy()))
    chance = 1 / len(trained.classes)
    assert acc > floor >= chance + 0.3, acc


@pytest.mark.parametrize("model", MODEL_NAMES)
def test_every_model_reduces_its_loss(model):
    small = synthetic_dataset(objects=("1", "A", "circle"), n_side=4, bins=32)
    trained = train_model(small.histograms, small.labels["object"], model=model, task="shape",
                          config=TrainConfig(max_epochs=6, patience=None, lr=3e-3, batch_size=16), width=0.125)
    losses = [h["train_loss"] for h in trained.history]
    assert len(losses) == 6 and losses[-1] < 0.8 * losses[0], losses


def test_same_seed_same_weights_and_global_rng_untouched(ds):
    sub = ds.take(np.arange(0, len(ds), 3))
    state = torch.get_rng_state()
    runs = [train_model(sub.histograms, sub.labels["size"], model="cnn1d", task="size", width=0.125,
                        config=TrainConfig(max_epochs=3, seed=seed)) for seed in (5, 5, 6)]
    assert torch.equal(state, torch.get_rng_state())
    a, b, c = (r.model.state_dict() for r in runs)
    assert all(torch.equal(a[k], b[k]) for k in a)
    assert not all(torch.equal(a[k], c[k]) for k in a)
    assert runs[0].history[-1]["train_loss"] == runs[1].history[-1]["train_loss"]


def test_early_stopping_stops_and_restores_the_best_epoch(ds):
    rng = np.random.default_rng(0)
    noise_targets = rng.normal(size=(len(ds), 2))  # nothing to learn: validation loss soon rises
    cfg = TrainConfig(max_epochs=60, patience=3, lr=1e-2, standardize_targets=False)
    trained = train_model(ds.histograms, noise_targets, model="mlp", task="loc", config=cfg, width=0.5)
    val_losses = [h["val_loss"] for h in trained.history]
    assert trained.stopped == "early" and len(val_losses) < 60
    assert trained.best_epoch == int(np.argmin(val_losses)) + 1 == len(val_losses) - 3
    rows = np.asarray(trained.val_rows)
    pred = trained.predict(ds.histograms[rows])
    mse = float(np.mean((pred - noise_targets[rows]) ** 2))
    assert mse == pytest.approx(val_losses[trained.best_epoch - 1], rel=1e-4)


def test_time_budget_stops_training(ds):
    trained = train_model(ds.histograms, ds.labels["size"], model="mlp", task="size", width=0.125,
                          config=TrainConfig(max_epochs=50, max_seconds=1e-3))
    assert trained.stopped == "time" and len(trained.history) == 1


def test_preprocessing_is_denalis_with_training_statistics():
    x = np.random.default_rng(1).poisson(30, size=(20, 3, 3, 16)).astype(np.float32)
    x[0, 0, 0, 0] = -3  # negative counts are clipped before log1p
    out, stats = apply_histogram_transform(x)
    logx = np.log1p(np.clip(x, 0, None))
    assert stats.mean == pytest.approx(logx.mean(), rel=1e-6)
    assert np.allclose(out, (logx - logx.mean()) / (logx.std() + 1e-6), atol=1e-5)
    raw = Preprocessing.fit(x, log_transform=False, normalize=False)
    assert np.array_equal(raw.apply(x), x)
    again, same = apply_histogram_transform(x[:5] * 2, stats=stats)
    assert same is stats and np.allclose(again, stats.apply(x[:5] * 2))


def test_denali_config_mirrors_its_cells():
    c = denali_config("transformer", "shape")
    assert (c.lr, c.max_epochs, c.batch_size, c.log_transform, c.normalize) == (1e-5, 50, 256, True, True)
    assert denali_config("cnn3d", "size", max_epochs=3).max_epochs == 3
    with pytest.raises(UserError, match=r"val_fraction=1.0 must be in \[0, 1\)"):
        TrainConfig(val_fraction=1.0)


@pytest.mark.parametrize("task", ["loc", "shape"])
def test_checkpoint_round_trip(tmp_path, ds, task):
    trained, _, test = _fit(ds, task, model="cnn1d", max_epochs=2)
    path = save_checkpoint(tmp_path / "m.pt", trained)
    assert os.listdir(tmp_path) == ["m.pt"]  # no temporary file left behind
    back = load_checkpoint(path)
    assert np.array_equal(back.predict(test.histograms), trained.predict(test.histograms))
    assert back.spec == trained.spec and back.preprocessing == trained.preprocessing
    assert back.classes == trained.classes and back.history == trained.history and back.config == trained.config
    assert back.target_mean == trained.target_mean and back.val_rows == trained.val_rows


class _Payload:  # an arbitrary object: loading it needs pickle to run code
    def __init__(self):
        self.weights = torch.zeros(3)


def test_load_refuses_files_that_need_pickle(tmp_path):
    bad = tmp_path / "evil.pt"
    torch.save(_Payload(), bad)
    with pytest.raises(UserError, match="needs pickle") as err:
        load_checkpoint(bad)
    assert "\n" not in str(err.value)
    plain = tmp_path / "plain.pt"
    torch.save({"state_dict": {"w": torch.zeros(2)}}, plain)
    with pytest.raises(UserError, match="not an nlosplan checkpoint"):
        load_checkpoint(plain)
    with pytest.raises(UserError, match="does not exist"):
        load_checkpoint(tmp_path / "missing.pt")
    (tmp_path / "junk.pt").write_bytes(b"not a torch file")
    with pytest.raises(UserError, match="refused: only checkpoints written by nlosplan are read") as err:
        load_checkpoint(tmp_path / "junk.pt")
    assert "\n" not in str(err.value)


def test_interrupted_save_keeps_the_previous_checkpoint(tmp_path, ds, monkeypatch):
    trained, _, test = _fit(ds, "size", max_epochs=1)
    path = save_checkpoint(tmp_path / "m.pt", trained)
    before = path.read_bytes()

    def dies_halfway(obj, fh, *a, **k):
        fh.write(b"half a checkpoint")
        raise KeyboardInterrupt

    monkeypatch.setattr(torch, "save", dies_halfway)
    with pytest.raises(KeyboardInterrupt):
        save_checkpoint(path, trained)
    assert path.read_bytes() == before and os.listdir(tmp_path) == ["m.pt"]
