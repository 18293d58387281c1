"""``nlosplan bench denali`` and the checkpoints part of ``bench real``: end to end, JSON contract, bad input."""

import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import torch
from synthetic_tasks import synthetic_dataset

from nlosplan.cli import main

pytestmark = pytest.mark.usefixtures("one_torch_thread")

CHECKPOINTS = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "denali" / "checkpoints"


def _no_work(*a, **k):
    raise AssertionError("work started before the inputs were checked")


def _one_line_error(capsys, argv, *needles):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    for n in needles:
        assert n in err, err
    return err


def test_bad_input_is_one_line_and_exit_2_before_any_work(capsys, monkeypatch, tmp_path):
    from nlosplan.tasks import denali_bench

    for name in ("run_denali_bench", "load_protocol_captures", "estimate_seconds"):
        monkeypatch.setattr(denali_bench, name, _no_work)
    _one_line_error(capsys, ["bench", "denali", "--budget", "huge"], "--budget", "huge")
    if not torch.cuda.is_available():
        _one_line_error(capsys, ["bench", "denali", "--device", "cuda"], "--device cuda", "no CUDA GPU")
    _one_line_error(capsys, ["bench", "denali", "--sensor", "no-such-sensor"], "no-such-sensor")
    _one_line_error(capsys, ["bench", "denali", "--models", "cnn3d"], "cnn3d")
    _one_line_error(capsys, ["bench", "denali", "--tasks", "colour"], "colour")
    _one_line_error(capsys, ["bench", "denali", "--positions", "0-100"], "0-100")
    _one_line_error(capsys, ["bench", "denali", "--epochs", "0"], "--epochs")
    _one_line_error(capsys, ["bench", "denali", "--seeds", "42,42"], "--seeds", "42 given twice")
    _one_line_error(capsys, ["bench", "denali", "--seeds", "4x"], "--seeds", "4x")
    _one_line_error(capsys, ["bench", "denali", "--seeds", "-1"], "--seeds")
    _one_line_error(capsys, ["bench", "denali", "--seeds", ","], "--seeds", "no seed given")
    (tmp_path / "adir").mkdir()
    _one_line_error(capsys, ["bench", "denali", "--store", str(tmp_path / "adir")], "--store")


@pytest.fixture
def synthetic_captures(monkeypatch):
    """``load_protocol_captures`` replaced by a learnable synthetic set in DENALI's order (no simulation)."""
    from nlosplan.tasks import denali_bench
    from nlosplan.tasks.denali_protocol import capture_order

    seen = {}

    def fake(sensor_spec, protocol, *, store=None, fidelity="default", progress=None):
        seen.update(sensor=sensor_spec, protocol=protocol, store=store)
        ds = synthetic_dataset(objects=protocol.objects, n_side=3, bins=128)
        on = ds.labels.assign(lights="on")
        labels = pd.concat([ds.labels, on], ignore_index=True)
        hist = np.concatenate([ds.histograms, ds.histograms])
        order = capture_order(labels)
        info = {"store": str(store or "cache"), "sensor": sensor_spec, "scene_options": {}, "captures": len(labels),
                "captures_added": 0, "build_seconds": 0.0, "variant": "synthetic", "fidelity": fidelity,
                "build_seed": 0}
        return hist[order], labels.iloc[order].reset_index(drop=True), info

    monkeypatch.setattr(denali_bench, "load_protocol_captures", fake)
    return seen


def test_bench_denali_end_to_end_json(capsys, synthetic_captures):
    argv = ["bench", "denali", "--device", "cpu", "--objects", "1,7,A,S", "--positions", "0-8", "--epochs", "8",
            "--models", "cnn1d,mlp", "--tasks", "size", "--json"]
    assert main(argv) == 0
    out = json.loads(capsys.readouterr().out)
    assert synthetic_captures["protocol"].objects == ("1", "7", "A", "S")
    assert synthetic_captures["protocol"].positions == tuple(range(9))
    rows = {(r["task"], r["model"]): r for r in out["rows"]}
    assert set(rows) == {("size", "cnn1d"), ("size", "mlp")}
    for r in rows.values():
        assert {"task", "model", "metric", "predicted", "predicted_last_epoch", "predicted_validation_epoch", "real",
                "budget", "device", "seconds", "best_epoch", "epochs", "predicted_by_lights"} <= set(r)
        assert r["budget"] == "custom" and r["device"] == "cpu" and r["metric"] == "top1_acc" and r["epochs"] == 8
        assert r["n_train"] + r["n_test"] == 4 * 2 * 9 * 2
        assert r["predicted_validation_epoch"] is not None and r["n_train_validation_run"] < r["n_train"]
        assert set(r["predicted_by_lights"]) == {"on", "off"}
    assert rows[("size", "cnn1d")]["real"] == 0.9468 and rows[("size", "mlp")]["real"] == 0.5363
    assert rows[("size", "cnn1d")]["predicted"] >= 0.9     # the synthetic sizes are learnable
    assert len(out["cells"]) == 4 and {c["mode"] for c in out["cells"]} == {"denali", "validation"}
    assert len(out["cells"][0]["history"]) == 8
    assert out["protocol"]["budget"] == "custom" and out["validation"] is True


def test_bench_denali_text_says_what_it_is(capsys, synthetic_captures):
    argv = ["bench", "denali", "--device", "cpu", "--objects", "1,7", "--positions", "0-8", "--epochs", "2",
            "--models", "mlp", "--tasks", "shape,loc", "--no-validation"]
    assert main(argv) == 0
    out = capsys.readouterr()
    assert "NOT DENALI's protocol" in out.out and "6.65 %" in out.out and "10.45 cm" in out.out
    assert "validation-chosen: not run (--no-validation)" in out.out


def test_bench_denali_knn_cell_on_denalis_split(capsys, synthetic_captures):
    from nlosplan.tasks.denali_protocol import denali_split

    argv = ["bench", "denali", "--device", "cpu", "--objects", "1,7,A,S", "--positions", "0-8", "--models", "knn",
            "--tasks", "loc,size", "--no-validation", "--json"]
    assert main(argv) == 0
    out = json.loads(capsys.readouterr().out)
    rows = {r["task"]: r for r in out["rows"]}
    assert set(rows) == {"loc", "size"} and {r["model"] for r in out["rows"]} == {"knn"}
    for r in rows.values():
        # one test-blind figure in every column, no epochs, no Table 1 figure
        assert r["predicted"] == r["predicted_last_epoch"] == r["predicted_validation_epoch"]
        assert r["real"] is None and r["epochs"] == 0 and set(r["predicted_by_lights"]) == {"on", "off"}
    # DENALI's split, not another: 70/30 of the 144 captures
    n = 4 * 2 * 9 * 2
    train, test = denali_split("size", np.array(["x"] * n))
    assert rows["size"]["n_test"] == len(test) and rows["size"]["n_train"] == len(train)
    assert rows["size"]["predicted"] >= 0.75         # the synthetic sizes are learnable (chance 50 %)
    assert rows["loc"]["predicted"] < 0.5 * 0.105     # far better than predicting the mean position
    cell = next(c for c in out["cells"] if c["task"] == "size")
    assert cell["settings"]["k"] in cell["settings"]["k_choices"] and len(cell["history"]) >= 1
    assert cell["settings"]["components"] in cell["settings"]["component_choices"]
    argv[argv.index("--json")] = "--quiet"
    assert main(argv[:-1]) == 0
    text = capsys.readouterr().out
    assert "knn: k nearest neighbours on principal components of square-root counts" in text and "Table 1 has no such learner" in text


def test_bench_denali_seeds_train_each_cell_per_seed_and_say_the_spread(capsys, synthetic_captures):
    from nlosplan.errors import UserError
    from nlosplan.tasks.denali_bench import check_seeds, seed_spread

    argv = ["bench", "denali", "--device", "cpu", "--objects", "1,7,A,S", "--positions", "0-8", "--epochs", "3",
            "--models", "cnn1d,knn", "--tasks", "loc", "--no-validation", "--seeds", "5,6,7", "--json"]
    assert main(argv) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["seeds"] == [5, 6, 7]
    cnn = [r for r in out["rows"] if r["model"] == "cnn1d"]
    assert [r["seed"] for r in cnn] == [5, 6, 7] and [r["seed"] for r in out["rows"] if r["model"] == "knn"] == [None]
    assert len({r["predicted"] for r in cnn}) == 3       # each seed its own draw of the recipe
    assert [c["seed"] for c in out["cells"] if c["model"] == "cnn1d"] == [5, 6, 7]
    (g,) = out["spread"]                                 # knn has no training seed: no spread row
    v = np.array([r["predicted"] for r in cnn])
    assert g["task"] == "loc" and g["model"] == "cnn1d" and g["seeds"] == [5, 6, 7] and g["real"] == 0.0456
    assert g["mean"] == pytest.approx(v.mean()) and g["sd"] == pytest.approx(v.std(ddof=1))
    assert (g["min"], g["max"]) == (v.min(), v.max()) and g["real_in_range"] == bool(v.min() <= 0.0456 <= v.max())
    # the same seed gives the same figure: a seed is a draw, not noise of the machine
    argv[argv.index("5,6,7")] = "6"
    assert main(argv) == 0
    one = json.loads(capsys.readouterr().out)
    assert one["spread"] == []
    assert [r["predicted"] for r in one["rows"] if r["model"] == "cnn1d"] == [cnn[1]["predicted"]]
    argv[argv.index("6")] = "5,6"
    argv.remove("--json")
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert "Over the training seeds" in text and "real between" in text and " seed" in text.splitlines()[3]
    # the rows' real figure lies between the seeds' exactly when real_in_range says so
    rows = [{"task": "size", "model": "cnn1d", "metric": "top1_acc", "predicted": p, "predicted_last_epoch": 0.5,
             "real": 0.9468, "seed": s} for s, p in ((1, 0.93), (2, 0.95))]
    (g,) = seed_spread(rows)
    assert g["real_in_range"] is True and g["sd"] == pytest.approx(0.01 * 2 ** 0.5)
    assert seed_spread(rows[:1]) == []
    assert seed_spread(rows[:1] + [{**rows[1], "predicted": 0.94}])[0]["real_in_range"] is False
    with pytest.raises(UserError, match="distinct"):
        check_seeds([1, 1])
    with pytest.raises(UserError, match="integer"):
        check_seeds([1.5])
    with pytest.raises(UserError, match="integer from 0 to 4294967295"):
        check_seeds([2 ** 32])


def test_full_budget_on_the_cpu_warns_how_long_before_any_work(capsys, monkeypatch):
    from nlosplan.tasks import denali_bench

    class Started(Exception):
        pass

    def started(*a, **k):
        raise Started

    monkeypatch.setattr(denali_bench, "run_denali_bench", started)
    with pytest.raises(Started):
        main(["bench", "denali", "--device", "cpu", "--budget", "full", "--models", "cnn1d", "--tasks", "size"])
    err = capsys.readouterr().err
    assert "warning: bench denali: 36,000 captures" in err and "of training on this machine now" in err
    assert "8-14 min each on 2 idle cores" in err and "--budget quick" in err


@pytest.mark.slow
def test_bench_denali_simulates_and_reuses_its_store(capsys, tmp_path):
    """The real thing on a tiny protocol: simulated captures into a store, a second run reuses them."""
    store = tmp_path / "bench.sqlite"
    argv = ["bench", "denali", "--device", "cpu", "--objects", "A,S", "--positions", "0,50", "--epochs", "2",
            "--models", "mlp", "--tasks", "size", "--no-validation", "--store", str(store), "--json"]
    assert main(argv) == 0
    first = json.loads(capsys.readouterr().out)
    assert store.is_file() and first["captures"]["captures"] == 2 * 2 * 2 * 2 * 3
    assert first["captures"]["captures_added"] == 48
    assert main(argv) == 0
    second = json.loads(capsys.readouterr().out)
    assert second["captures"]["captures_added"] == 0 and second["rows"] == [
        {**r, "seconds": s["seconds"]} for r, s in zip(first["rows"], second["rows"])]


@pytest.fixture
def random_captures(monkeypatch):
    """A few random 3x3 captures of DENALI's labels instead of the simulation (the part's plumbing only)."""
    from nlosplan.denali import DENALI_OBJECTS, positions_xy
    from nlosplan.tasks import denali_bench

    def fake(sensor_spec, protocol, *, store=None, fidelity="default", progress=None):
        rng = np.random.default_rng(0)
        rows = [(o, s, "3x3", li, p, 0) for o in DENALI_OBJECTS[:4] for s in ("4in", "8in") for li in ("on", "off")
                for p in (0, 50)]
        lab = pd.DataFrame(rows, columns=["object", "size", "zones", "lights", "position", "repeat"])
        xy = positions_xy()[lab["position"]]
        lab["x"], lab["y"] = xy[:, 0], xy[:, 1]
        hist = rng.poisson(1200.0, (len(lab), 3, 3, 128)).astype(np.float32)
        return hist, lab, {"store": "none", "sensor": sensor_spec, "scene_options": {}, "captures": len(lab)}

    monkeypatch.setattr(denali_bench, "load_protocol_captures", fake)


def test_bench_real_checkpoints_part_json(capsys, random_captures):
    if not CHECKPOINTS.is_dir():
        pytest.skip(f"DENALI's checkpoints not found at {CHECKPOINTS}")
    assert main(["bench", "real", "--parts", "checkpoints", "--checkpoints", str(CHECKPOINTS), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert [c["name"] for c in out["checkpoints"]] == ["reg_1dcnn", "obj_1dcnn", "size_1dcnn", "obj_mlp"]
    for c in out["checkpoints"]:
        assert {"name", "task", "metric", "simulated", "real", "bn"} <= set(c) and c["n"] == 32
    cnn = out["checkpoints"][1]
    assert set(cnn["bn"]) == {"bn1", "bn2", "bn3"}
    assert {"median_abs_z", "mean_log_var_ratio", "rms_log_var_ratio"} <= set(cnn["bn"]["bn2"])
    assert cnn["real"] == pytest.approx(0.38769, abs=1e-5)
    assert out["real_breakdown"]["obj_1dcnn"]["by_lights"]["on"] == pytest.approx(0.41599, abs=5e-6)
    assert out["checkpoints_run"]["rows_scored"] == "all simulated captures"
    assert "plane" not in out and "table2" not in out


def test_bench_real_checkpoints_part_skipped_says_how(capsys):
    assert main(["bench", "real", "--parts", "checkpoints", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["checkpoints"] == [] and "--checkpoints DIR" in out["checkpoints_skipped"]
    assert "benchmark/main_table/checkpoints" in out["checkpoints_skipped"]


def test_bench_real_refuses_bad_checkpoints_before_any_work(capsys, monkeypatch, tmp_path):
    if not CHECKPOINTS.is_dir():
        pytest.skip(f"DENALI's checkpoints not found at {CHECKPOINTS}")
    from nlosplan.cli.bench import real as bench_real
    from nlosplan.tasks import denali_bench

    monkeypatch.setattr(bench_real, "run_table2", _no_work)
    monkeypatch.setattr(denali_bench, "load_protocol_captures", _no_work)
    folder = tmp_path / "ckpts"
    folder.mkdir()
    for name in ("reg_1dcnn", "obj_1dcnn", "size_1dcnn"):
        shutil.copy(CHECKPOINTS / f"{name}.pth", folder / f"{name}.pth")
    marker = tmp_path / "UNPICKLED"

    class Marker:
        def __reduce__(self):
            return (open, (str(marker), "w"))

    torch.save({"model_state_dict": {}, "x": Marker()}, folder / "obj_mlp.pth")
    _one_line_error(capsys, ["bench", "real", "--parts", "table2,checkpoints", "--checkpoints", str(folder)],
                    "obj_mlp.pth: refused", "nothing was unpickled")
    assert not marker.exists()
    torch.save({"model_state_dict": {"w": torch.zeros(2)}}, folder / "obj_mlp.pth")
    _one_line_error(capsys, ["bench", "real", "--parts", "checkpoints", "--checkpoints", str(folder)],
                    "is not DENALI's obj_mlp")
    (folder / "obj_mlp.pth").unlink()
    _one_line_error(capsys, ["bench", "real", "--parts", "checkpoints", "--checkpoints", str(folder)],
                    "lacks obj_mlp.pth")
    _one_line_error(capsys, ["bench", "real", "--parts", "checkpoints", "--checkpoints", str(CHECKPOINTS),
                             "--denali-sensor", "tmf8828-8x8-short"], "3x3 zones and 128 bins")
    _one_line_error(capsys, ["bench", "real", "--checkpoint-budget", "huge"], "huge")


def test_bench_real_inversion_part_json_and_text(capsys, random_captures, monkeypatch):
    if not CHECKPOINTS.is_dir():
        pytest.skip(f"DENALI's checkpoints not found at {CHECKPOINTS}")
    from nlosplan.tasks import denali_inversion

    fit = denali_inversion.invert_mean_capture
    monkeypatch.setattr(denali_inversion, "invert_mean_capture", lambda cks, h: fit(cks, h, iterations=2))
    assert main(["bench", "real", "--parts", "inversion", "--checkpoints", str(CHECKPOINTS), "--json"]) == 0
    inv = json.loads(capsys.readouterr().out)["inversion"]
    assert np.asarray(inv["mean_real"]).shape == (9, 128) and len(inv["zones_model"]) == 9
    assert [(r["network"], r["layer"]) for r in inv["bn_after"]][:3] == [("reg_1dcnn", "bn1"), ("reg_1dcnn", "bn2"),
                                                                          ("reg_1dcnn", "bn3")]
    assert len(inv["bn_before"]) == 9 and inv["loss_after"] <= inv["loss_before"] and inv["captures"] == 32
    assert [s["name"] for s in inv["scores"]] == ["reg_1dcnn", "obj_1dcnn", "size_1dcnn"]   # the MLP has no BatchNorm
    assert main(["bench", "real", "--parts", "inversion", "--checkpoints", str(CHECKPOINTS)]) == 0
    text = capsys.readouterr().out
    assert "The mean real capture behind DENALI's networks" in text and "(1, 1)" in text and "+0 bins" in text


def test_bench_real_inversion_part_skipped_says_how(capsys):
    assert main(["bench", "real", "--parts", "inversion", "--json"]) == 0
    assert "--checkpoints DIR" in json.loads(capsys.readouterr().out)["inversion"]["skipped"]
