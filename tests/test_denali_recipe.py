"""DENALI's recipe (nlosplan.tasks.denali_recipe): it learns what is learnable, stays at chance on noise, picks its
epochs as documented, is deterministic, leaves the caller's generator alone and refuses bad input in one line."""

import numpy as np
import pytest
import torch
from synthetic_tasks import synthetic_dataset

from nlosplan.errors import UserError
from nlosplan.tasks.denali_recipe import (VALIDATION_FRACTION, cell_settings, denali_model, resolve_device,
                                          train_denali_cell)

pytestmark = pytest.mark.usefixtures("one_torch_thread")


@pytest.fixture(scope="module")
def ds():
    return synthetic_dataset(n_side=6, bins=32, objects=("1", "7", "A", "S"))  # 4 objects x 2 sizes x 36 = 288 rows


def _targets(ds, task):
    return ds.labels[["x", "y"]].to_numpy() if task == "loc" else \
        ds.labels["object" if task == "shape" else "size"].to_numpy()


@pytest.mark.parametrize("task", ["size", "shape"])
def test_the_1d_cnn_learns_a_learnable_set(ds, task):
    res = train_denali_cell(ds.histograms, _targets(ds, task), task, "cnn1d", epochs=8)
    assert res.metric == "top1_acc" and res.mode == "denali" and res.n_test == int(np.ceil(0.3 * len(ds)))
    assert res.predicted_last_epoch >= 0.95 and res.predicted >= res.predicted_last_epoch
    tests = [h["test"]["top1_acc"] for h in res.history]
    assert res.best_epoch == 1 + int(np.argmax(tests))          # DENALI keeps the first epoch of the best top-1
    assert res.predicted == max(tests)
    assert res.predictions["best"].shape == (res.n_test,) and res.classes == tuple(sorted(set(_targets(ds, task))))


def test_noise_stays_at_chance_and_best_on_test_is_the_optimistic_one(ds):
    y = np.random.default_rng(0).permutation(_targets(ds, "size"))   # labels that the histograms do not carry
    res = train_denali_cell(ds.histograms, y, "size", "cnn1d", epochs=6, validation=True)
    sd = np.sqrt(0.25 / res.n_test)
    for v in (res.predicted_last_epoch, res.predicted_validation_epoch):
        assert abs(v - 0.5) < 3 * sd, v
    assert res.predicted >= max(res.predicted_last_epoch, res.predicted_validation_epoch)


def test_validation_mode_trains_on_nine_tenths_and_picks_its_epoch_on_the_held_out_tenth(ds):
    plain = train_denali_cell(ds.histograms, _targets(ds, "shape"), "shape", "mlp", epochs=4)
    res = train_denali_cell(ds.histograms, _targets(ds, "shape"), "shape", "mlp", epochs=4, validation=True)
    assert plain.n_val == 0 and plain.validation_epoch is None and plain.predicted_validation_epoch is None
    assert res.mode == "validation" and res.n_train + res.n_val == plain.n_train
    assert res.n_val == round(VALIDATION_FRACTION * plain.n_train) and res.n_test == plain.n_test
    vals = [h["val"]["top1_acc"] for h in res.history]
    assert res.validation_epoch == 1 + int(np.argmax(vals))
    assert res.predicted_validation_epoch == res.history[res.validation_epoch - 1]["test"]["top1_acc"]
    assert np.array_equal(res.test_index, plain.test_index)      # the same test set as DENALI's split


def test_localization_keeps_the_epoch_of_least_test_mae_and_reports_denalis_rmse(ds):
    xy = _targets(ds, "loc")
    res = train_denali_cell(ds.histograms, xy, "loc", "cnn1d", epochs=5)
    maes = [h["test"]["mae"] for h in res.history]
    assert res.metric == "loc_rmse" and res.selection == "mae" and res.best_epoch == 1 + int(np.argmin(maes))
    pred = res.predictions["best"]
    truth = xy[res.test_index]
    assert res.predicted == pytest.approx(np.sqrt(np.mean((pred - truth) ** 2)), rel=1e-12)   # x and y pooled
    assert res.history[-1]["test"]["loc_rmse"] < res.history[0]["test"]["loc_rmse"]   # it learns (raw metres)


def test_same_seed_same_run_and_the_callers_generator_untouched(ds):
    torch.manual_seed(123)
    before = torch.random.get_rng_state()
    a = train_denali_cell(ds.histograms, _targets(ds, "size"), "size", "mlp", epochs=3)
    assert torch.equal(torch.random.get_rng_state(), before)
    b = train_denali_cell(ds.histograms, _targets(ds, "size"), "size", "mlp", epochs=3)
    assert [h["test"] for h in a.history] == [h["test"] for h in b.history]
    assert [h["train_loss"] for h in a.history] == [h["train_loss"] for h in b.history]
    c = train_denali_cell(ds.histograms, _targets(ds, "size"), "size", "mlp", epochs=3, seed=7)
    assert [h["train_loss"] for h in c.history] != [h["train_loss"] for h in a.history]


def test_shape_mlp_takes_log1p_zscored_over_all_captures_the_others_raw_counts(ds):
    res = train_denali_cell(ds.histograms, _targets(ds, "shape"), "shape", "mlp", epochs=1)
    x = np.log1p(np.clip(ds.histograms.astype(np.float32), 0, None))
    assert res.preprocessing["mean"] == pytest.approx(float(x.mean()), rel=1e-6)   # train and test rows, as DENALI
    assert res.preprocessing["std"] == pytest.approx(float(x.std()) + 1e-6, rel=1e-6)
    assert cell_settings("mlp", "shape") == {"lr": 1e-5, "epochs": 100, "batch_size": 256, "log_zscore": True}
    assert cell_settings("cnn1d", "loc") == {"lr": 1e-3, "epochs": 60, "batch_size": 64, "log_zscore": False}
    raw = train_denali_cell(ds.histograms, _targets(ds, "size"), "size", "cnn1d", epochs=1)
    assert raw.preprocessing == {"input": "raw counts"}


def test_models_are_denalis_by_their_layer_names():
    reg = denali_model("cnn1d", "loc", (3, 3, 128), 2)
    assert [k for k in reg.state_dict() if not k.startswith(("conv", "bn"))] == [
        "mlp.0.weight", "mlp.0.bias", "out_linear.weight", "out_linear.bias", "out_tanh.weight", "out_tanh.bias"]
    cls = denali_model("cnn1d", "shape", (3, 3, 128), 30)
    assert cls.conv1.weight.shape == (128, 9, 5) and cls.conv3.weight.shape == (64, 128, 3)
    assert cls.head[5].weight.shape == (30, 32)
    mlp = denali_model("mlp", "shape", (3, 3, 128), 30)
    assert [tuple(mlp.get_submodule(f"fc{i}").weight.shape) for i in (1, 2, 3, 4)] == [
        (512, 1152), (256, 512), (128, 256), (30, 128)]


def test_bad_input_is_one_line(ds):
    y = _targets(ds, "size")
    cases = [
        (dict(task="size", model="cnn3d"), "no cell 'cnn3d'"),
        (dict(task="size", model="mlp", train_index=[0, 1]), "give both train_index and test_index"),
        (dict(task="size", model="mlp", train_index=[0, 1], test_index=[1, 2]), "share rows"),
        (dict(task="size", model="mlp", train_index=[0, 1], test_index=[len(y)]), "test_index must be"),
        (dict(task="size", model="mlp", epochs=0), "epochs=0 must be >= 1"),
    ]
    for kw, msg in cases:
        with pytest.raises(UserError, match=msg) as err:
            train_denali_cell(ds.histograms, y, **kw)
        assert "\n" not in str(err.value)
    with pytest.raises(UserError, match="at least 2 classes"):
        train_denali_cell(ds.histograms, np.full(len(y), "4in"), "size", "mlp")
    with pytest.raises(UserError, match="localization targets"):
        train_denali_cell(ds.histograms, y, "loc", "mlp")
    with pytest.raises(UserError, match="unknown device 'tpu'"):
        resolve_device("tpu")
    if not torch.cuda.is_available():
        with pytest.raises(UserError, match="--device cuda: torch sees no CUDA GPU") as err:
            resolve_device("cuda")
        assert "\n" not in str(err.value)
    assert resolve_device("auto") == ("cuda" if torch.cuda.is_available() else "cpu")


@pytest.mark.parametrize("model, old", [("mlp", {"fc1.": "net.1.", "fc4.": "net.10."}),
                                        ("cnn1d", {"conv1.": "features.0.", "bn3.": "features.7."})])
def test_checkpoints_written_before_the_layers_took_denalis_names_still_load(tmp_path, ds, model, old):
    from nlosplan.tasks.checkpoints import _LEGACY_KEYS
    from nlosplan.tasks.training import TrainConfig, load_checkpoint, save_checkpoint, train_model

    trained = train_model(ds.histograms, ds.labels["size"], model=model, task="size", width=0.25,
                          config=TrainConfig(max_epochs=1))
    path = save_checkpoint(tmp_path / "m.pt", trained)
    payload = torch.load(path, weights_only=True)
    back = {v: k for k, v in _LEGACY_KEYS[model].items()}
    payload["state_dict"] = {next((back[n] + k[len(n):] for n in back if k.startswith(n)), k): v
                             for k, v in payload["state_dict"].items()}
    assert all(any(k.startswith(o) for k in payload["state_dict"]) for o in old.values())   # written the old way
    torch.save(payload, path)
    again = load_checkpoint(path)
    assert np.array_equal(again.predict(ds.histograms[:5]), trained.predict(ds.histograms[:5]))
