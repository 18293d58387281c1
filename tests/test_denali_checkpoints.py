"""DENALI's real-trained checkpoints: read safely and strictly, refused when they are not DENALI's (never unpickled),
run with BatchNorm input statistics, and their stored real predictions broken down."""

import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import torch

from nlosplan.errors import UserError
from nlosplan.tasks.denali_checkpoints import (CHECKPOINTS, bn_input_statistics, evaluate_checkpoints,
                                               load_checkpoint_dir, load_denali_checkpoint)

pytestmark = pytest.mark.usefixtures("one_torch_thread")


@pytest.fixture(scope="module")
def ckpt_dir():
    path = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "denali" / "checkpoints"
    if not path.is_dir():
        pytest.skip(f"DENALI's checkpoints not found at {path}")
    return path


@pytest.fixture(scope="module")
def checkpoints(ckpt_dir):
    return load_checkpoint_dir(ckpt_dir)


def test_all_four_load_strictly_with_their_real_scores(checkpoints):
    got = {c.name: c for c in checkpoints}
    assert list(got) == list(CHECKPOINTS)
    assert got["reg_1dcnn"].real == pytest.approx(0.045630, abs=1e-6)      # sqrt(test_mse) = Table 1's 0.0456
    assert got["obj_1dcnn"].real == pytest.approx(0.387685, abs=1e-6)
    assert got["size_1dcnn"].real == pytest.approx(0.946852, abs=1e-6)
    assert got["obj_mlp"].real == pytest.approx(0.078333, abs=1e-6)
    assert got["obj_1dcnn"].classes[22] == "halfcircle" and got["size_1dcnn"].classes == ("4inch", "8inch")
    assert got["obj_1dcnn"].test_predictions.shape == (10_800,) and got["reg_1dcnn"].test_predictions is None
    assert [got[n].epoch for n in CHECKPOINTS] == [66, 74, 77, 98]
    # every weight of the file is in the network, and the network has no other
    from nlosplan.tasks.denali_checkpoints import read_checkpoint_payload

    payload_keys = set(read_checkpoint_payload(got["reg_1dcnn"].path)["model_state_dict"])
    assert payload_keys == set(got["reg_1dcnn"].net.state_dict())
    assert not any(m.training for m in got["obj_mlp"].net.modules())


def test_files_that_are_not_denalis_networks_are_refused_in_one_line(tmp_path, ckpt_dir):
    from synthetic_tasks import synthetic_dataset

    from nlosplan.tasks.training import TrainConfig, save_checkpoint, train_model

    ds = synthetic_dataset(n_side=3, bins=128)
    trained = train_model(ds.histograms, ds.labels["size"], model="cnn1d", task="size",
                          config=TrainConfig(max_epochs=1))
    ours = save_checkpoint(tmp_path / "size_1dcnn.pth", trained)
    random_sd = tmp_path / "obj_1dcnn.pth"
    torch.save({"model_state_dict": {"conv1.weight": torch.zeros(3, 3)}}, random_sd)
    wrong_net = tmp_path / "obj_mlp.pth"      # a real DENALI file under another cell's name
    shutil.copy(ckpt_dir / "obj_1dcnn.pth", wrong_net)
    cases = [(ours, "not one of DENALI's checkpoints (an nlosplan checkpoint)"),
             (random_sd, "is not DENALI's obj_1dcnn: its weights do not fit"),
             (wrong_net, "is not DENALI's obj_mlp: its weights do not fit")]
    for path, msg in cases:
        with pytest.raises(UserError, match=msg.replace("(", r"\(").replace(")", r"\)")) as err:
            load_denali_checkpoint(path)
        assert "\n" not in str(err.value)
    with pytest.raises(UserError, match="no DENALI checkpoint is called 'mine'"):
        load_denali_checkpoint(tmp_path / "mine.pth")
    (tmp_path / "reg_1dcnn.pth").write_bytes(b"not a torch file")
    with pytest.raises(UserError, match="is not a readable torch file"):
        load_denali_checkpoint(tmp_path / "reg_1dcnn.pth")
    with pytest.raises(UserError, match="does not exist"):
        load_denali_checkpoint(tmp_path / "missing" / "obj_1dcnn.pth")


class _Marker:
    """Unpickling this would create the marker file: a file that runs code when loaded."""

    def __init__(self, path):
        self.path = str(path)

    def __reduce__(self):
        return (open, (self.path, "w"))


def test_unexpected_globals_are_refused_and_never_unpickled(tmp_path):
    marker = tmp_path / "UNPICKLED"
    bad = tmp_path / "obj_1dcnn.pth"
    torch.save({"model_state_dict": {}, "payload": _Marker(marker)}, bad)
    with pytest.raises(UserError, match=r"refused, it needs the Python object \S*open\S* to load") as err:
        load_denali_checkpoint(bad)
    assert "\n" not in str(err.value) and "nothing was unpickled" in str(err.value)
    assert not marker.exists()
    torch.load(bad, weights_only=False)  # the file does run code when trusted: the test's own check
    assert marker.exists()


def test_folder_checks_name_what_is_missing(tmp_path, ckpt_dir):
    shutil.copy(ckpt_dir / "obj_1dcnn.pth", tmp_path / "obj_1dcnn.pth")
    with pytest.raises(UserError, match="lacks reg_1dcnn.pth, size_1dcnn.pth, obj_mlp.pth"):
        load_checkpoint_dir(tmp_path)
    with pytest.raises(UserError, match="no such folder"):
        load_checkpoint_dir(tmp_path / "nope")


def _labels(n, rng):
    from nlosplan.denali import DENALI_OBJECTS, positions_xy

    pos = rng.integers(0, 100, n)
    xy = positions_xy()[pos]
    return pd.DataFrame({"object": rng.choice(DENALI_OBJECTS, n), "size": rng.choice(["4in", "8in"], n),
                         "lights": np.where(np.arange(n) % 2, "on", "off"), "position": pos,
                         "x": xy[:, 0], "y": xy[:, 1]})


def test_evaluation_scores_every_network_and_its_batchnorm_inputs(checkpoints):
    rng = np.random.default_rng(0)
    n = 64
    x = rng.poisson(1200.0, (n, 3, 3, 128)).astype(np.float32)     # a flat floor: nothing to recognise
    scored = []
    res = evaluate_checkpoints(checkpoints, x, _labels(n, rng), rows={"shape": np.arange(32)}, on_done=scored.append)
    by = {r["name"]: r for r in res}
    assert scored == [r["name"] for r in res] == [c.name for c in checkpoints]  # a progress step per network
    assert by["obj_1dcnn"]["n"] == 32 and by["size_1dcnn"]["n"] == n
    for r in res:
        ck = next(c for c in checkpoints if c.name == r["name"])
        assert r["real"] == ck.real and r["ratio"] == pytest.approx(r["simulated"] / ck.real)
        assert set(r["by_lights"]) == {"on", "off"}
    assert by["reg_1dcnn"]["simulated"] > 0.02 and by["reg_1dcnn"]["chance"] > 0.05
    assert set(by["reg_1dcnn"]["bn"]) == {"bn1", "bn2", "bn3"} and by["obj_mlp"]["bn"] == {}
    assert by["size_1dcnn"]["chance"] == 0.5 and 0 < by["size_1dcnn"]["modal_share"] <= 1
    with pytest.raises(UserError, match=r"take \(N, 3, 3, 128\) histograms"):
        evaluate_checkpoints(checkpoints, x[:, :, :, :64], _labels(n, rng))


def test_batchnorm_distance_is_zero_on_the_statistics_it_keeps():
    """Set each BatchNorm's running statistics to its input's moments: z and the log variance ratio vanish."""
    from nlosplan.tasks.models import CNN1D

    torch.manual_seed(0)
    net = CNN1D(9, 2, width=0.25).eval()
    x = np.random.default_rng(1).normal(100.0, 10.0, (40, 3, 3, 32)).astype(np.float32)
    for layer in ("bn1", "bn2", "bn3"):       # in order: each layer's input depends on the ones before
        s = bn_input_statistics(net, x, batch=16)[layer]
        bn = getattr(net, layer)
        z, lr = np.asarray(s["z"]), np.asarray(s["log_var_ratio"])
        bn.running_mean += torch.from_numpy(z).float() * bn.running_var.sqrt()
        bn.running_var *= torch.from_numpy(np.exp(lr)).float()
    stats = bn_input_statistics(net, x, batch=7)
    for s in stats.values():
        assert s["median_abs_z"] < 1e-4 and abs(s["mean_log_var_ratio"]) < 1e-4 and s["rms_log_var_ratio"] < 1e-4
    # by hand for the first layer: moments over batch and time of conv1's output
    with torch.no_grad():
        h = net.conv1(torch.from_numpy(x).flatten(1, 2)).double()
    mean = h.mean(dim=(0, 2))
    z = ((mean - net.bn1.running_mean.double()) / net.bn1.running_var.double().sqrt()).numpy()
    assert np.allclose(stats["bn1"]["z"], z, atol=1e-4)


def test_real_breakdown_of_the_stored_predictions(checkpoints):
    from nlosplan.tasks.denali_breakdown import real_breakdown

    bd = real_breakdown(checkpoints)
    assert set(bd) == {"obj_1dcnn", "size_1dcnn"}
    shape, size = bd["obj_1dcnn"], bd["size_1dcnn"]
    assert shape["accuracy"] == shape["stored_top1"]
    assert shape["by_lights"] == pytest.approx({"on": 0.41599, "off": 0.35934}, abs=5e-6)
    assert shape["by_size"] == pytest.approx({"4in": 0.36722, "8in": 0.40764}, abs=5e-6)
    assert size["by_lights"] == pytest.approx({"on": 0.92944, "off": 0.96408}, abs=5e-6)
    assert shape["purity"]["folders"] == 120
    assert shape["purity"]["median_modal_share"] == pytest.approx(0.4919, abs=5e-5)
    assert shape["purity"]["wrong_modal_share"] == pytest.approx(0.5083, abs=5e-5)
    assert set(shape["by_half"]) == {"near", "far"} and len(shape["by_quadrant"]) == 4
