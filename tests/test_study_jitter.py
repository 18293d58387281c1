"""DENALI's jitter study: the declarative config, the runner (centre zone -> jitter -> benchmark), its
report (tables, figure, files) and ``nlosplan study jitter`` (files, JSON, progress, one-line errors, help)."""

import json

import numpy as np
import pandas as pd
import pytest
import torch
from synthetic_tasks import synthetic_dataset

from nlosplan.cli import main
from nlosplan.cli.common import examples
from nlosplan.errors import UserError
from nlosplan.experiments import JitterStudy, load_study_dataset, run_jitter_study
from nlosplan.reports.jitter_plot import jitter_markdown, jitter_table, jitter_text, write_jitter
from nlosplan.sensor_models import preset
from nlosplan.tasks.benchmark import run_benchmark
from nlosplan.data.store import CaptureStore

#: A quick study: two levels (none and DENALI's largest), two models, every task.
STUDY = JitterStudy(jitter_ps=(600, 0), models=("mlp", "cnn1d"), epochs=3, width=0.125)


pytestmark = pytest.mark.usefixtures("one_torch_thread")


@pytest.fixture(scope="module")
def ds():
    return synthetic_dataset(n_side=4, bins=32, repeats=2)  # 6 objects x 2 sizes x 16 positions = 192 scenes


@pytest.fixture(scope="module")
def study(ds):
    """The study's result and the events its progress hook saw."""
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    events = []
    try:
        result = run_jitter_study(ds, STUDY, progress=events.append)
    finally:
        torch.set_num_threads(before)
    return result, events


# ----------------------------------------------------------------- config
def test_config_sorts_levels_and_rejects_bad_settings():
    assert STUDY.jitter_ps == (0.0, 600.0)
    assert JitterStudy().jitter_ps == (0.0, 50.0, 100.0, 600.0) and JitterStudy().zone == "centre"
    assert JitterStudy(jitter_ps=[100, 0, 100]).jitter_ps == (0.0, 100.0)
    small = JitterStudy.small(models=["mlp"])
    assert (small.epochs, small.width, small.models) == (5, 0.125, ("mlp",))
    assert JitterStudy.from_dict(small.to_dict()) == small
    for bad, needle in (({"jitter_ps": (0, -50)}, "-50"), ({"jitter_ps": (float("nan"),)}, "nan"),
                        ({"jitter_ps": ()}, "no jitter levels"), ({"models": ("mlp", "resnet")}, "'resnet'"),
                        ({"tasks": ("depth",)}, "'depth'"), ({"zone": "corner"}, "'corner'"),
                        ({"width": 0}, "width"), ({"epochs": 0}, "epochs")):
        with pytest.raises(UserError, match=needle) as err:
            JitterStudy(**bad)
        assert "\n" not in str(err.value)
    with pytest.raises(UserError, match="unknown jitter-study setting"):
        JitterStudy.from_dict({"jitter": [0]})


# ----------------------------------------------------------------- runner
def test_rows_cover_every_level_model_task_and_record_the_run(study, ds):
    result, _ = study
    rows = pd.DataFrame(result["rows"])
    overall = rows[rows["group"] == "all"]
    assert set(zip(overall["jitter_ps"], overall["model"], overall["task"])) == {
        (j, m, t) for j in (0.0, 600.0) for m in ("mlp", "cnn1d") for t in ("loc", "shape", "size")}
    assert not rows.duplicated(["jitter_ps", "model", "task", "metric", "group"]).any()
    assert {"loc_rmse", "mae", "top1_acc", "top5_acc", "macro_f1", "macro_precision", "macro_recall"} <= set(rows["metric"])
    assert len(result["runs"]) == 12 and all(r["status"] == "ok" and r["train_seconds"] > 0 for r in result["runs"])
    assert [lv["jitter_ps"] for lv in result["levels"]] == [0.0, 600.0]
    assert all(lv["n_rows"] == 192 and lv["seconds"] >= lv["train_seconds"] > 0 for lv in result["levels"])
    c = result["config"]
    assert result["n_scenes"] == c["n_scenes"] == 192 and c["n_captures"] == len(ds) == 384
    assert c["histogram_shape_given"] == [3, 3, 32] and c["histogram_shape"] == [1, 1, 32]
    assert c["jitter_ps"] == [0.0, 600.0] and c["zone"] == "centre" and c["n_classes"] == {"shape": 6, "size": 2}
    json.dumps(result, default=float)  # the whole result is JSON-ready


def test_jitter_zero_is_the_plain_centre_zone_benchmark(study, ds):
    result, _ = study
    plain = run_benchmark(ds.centre_zone(), models=("mlp", "cnn1d"), epochs=3, width=0.125, seed=42)
    at_zero = [{k: v for k, v in r.items() if k != "jitter_ps"} for r in result["rows"] if r["jitter_ps"] == 0.0]
    assert at_zero == plain["rows"]  # same split, same seed, same data: identical numbers


def test_each_level_trains_on_the_blurred_centre_zone(study, ds):
    result, events = study
    fed = {e["jitter_ps"]: e["dataset"] for e in events if e["event"] == "level"}
    assert sorted(fed) == [0.0, 600.0]
    centre = ds.centre_zone()
    assert np.array_equal(fed[0.0].histograms, centre.histograms)
    assert np.allclose(fed[600.0].histograms, centre.with_jitter(600.0).histograms)  # per capture, before averaging
    lv = {v["jitter_ps"]: v for v in result["levels"]}
    assert lv[600.0]["peak_counts"] < 0.3 * lv[0.0]["peak_counts"]  # 600 ps ~ 6.5 bins of 92.8 ps
    assert lv[600.0]["peak_width_ps"] > 3 * lv[0.0]["peak_width_ps"]
    assert 0.8 * lv[0.0]["total_counts"] < lv[600.0]["total_counts"] <= lv[0.0]["total_counts"] * (1 + 1e-6)
    kinds = [e["event"] for e in events if e["jitter_ps"] == 600.0]
    assert kinds[0] == "level" and kinds[-1] == "level_done" and kinds.count("done") == 6


def test_even_grids_and_empty_data_are_refused(ds):
    with pytest.raises(UserError, match=r"odd zone grid.*2x2") as err:
        run_jitter_study(synthetic_dataset(n_side=2, bins=16, zones=(2, 2)), STUDY)
    assert "\n" not in str(err.value)
    with pytest.raises(UserError, match="empty"):
        run_jitter_study(ds.where(object="nope"), STUDY)


# ----------------------------------------------------------------- report
def test_tables_text_markdown_and_files(study, tmp_path):
    result, _ = study
    table = jitter_table(result)
    assert list(table.index) == [0.0, 600.0] and table.columns.names == ["model", "task", "metric"]
    assert table.columns[0] == ("mlp", "loc", "loc_rmse") and ("cnn1d", "size", "macro_recall") in table.columns
    assert not table.isna().any().any()
    value = {(r["jitter_ps"], r["model"], r["task"], r["metric"]): r["value"] for r in result["rows"]
             if r["group"] == "all"}
    assert table.loc[600.0, ("cnn1d", "shape", "top1_acc")] == value[(600.0, "cnn1d", "shape", "top1_acc")]
    text = jitter_text(result)
    for needle in ("centre zone (1x1x32 of 3x3x32)", "192 scenes", "loc RMSE m", "shape top-5 %", "size rec %",
                   "peak counts", "mlp", "cnn1d"):
        assert needle in text
    assert "## cnn1d" in jitter_markdown(result, figure="jitter.png") and "![jitter study](jitter.png)" in \
        jitter_markdown(result, figure="jitter.png")
    files = write_jitter(result, tmp_path / "o")
    assert set(files) == {"csv", "markdown", "json", "plot"}
    csv = pd.read_csv(files["csv"], index_col="jitter_ps")
    assert list(csv.index) == [0.0, 600.0] and csv.loc[0.0, "mlp/loc/loc_rmse"] == pytest.approx(
        value[(0.0, "mlp", "loc", "loc_rmse")])
    assert json.loads(open(files["json"]).read())["config"]["models"] == ["mlp", "cnn1d"]
    from PIL import Image

    with Image.open(files["plot"]) as im:
        assert im.size[0] > 2 * im.size[1] > 600  # three panels side by side


# ----------------------------------------------------------------- CLI
def _put(store, ds, sensor):
    items = [(h.astype(np.int64), {k: row[k] for k in ("object", "size", "position", "x", "y", "lights", "repeat",
                                                         "source", "class_group")})
             for h, (_, row) in zip(np.rint(ds.histograms), ds.labels.iterrows())]
    with CaptureStore(store, synchronous="NORMAL") as st:
        st.put_many(items, sensor=sensor)


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    """3x3 captures to study, plus 8x8 ones the default zones=3x3 filter leaves out."""
    path = tmp_path_factory.mktemp("jit") / "s.sqlite"
    _put(path, synthetic_dataset(n_side=4, bins=128, repeats=1), preset("tmf8828-3x3-short"))
    _put(path, synthetic_dataset(objects=("A", "S"), n_side=2, bins=128, zones=(8, 8)), preset("tmf8828-8x8-short"))
    return str(path)


def run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_cli_writes_the_four_files_and_json(capsys, tmp_path, store):
    out_dir = tmp_path / "out"
    code, out, err = run(capsys, "study", "jitter", "--store", store, "--jitter-ps", "0,600", "--models", "mlp",
                         "--small", "--epochs", "2", "--threads", "1", "--out", str(out_dir), "--json")
    assert code == 0, err
    res = json.loads(out)
    assert sorted(p.name for p in out_dir.iterdir()) == ["jitter.csv", "jitter.json", "jitter.md", "jitter.png"]
    assert res["files"]["plot"] == str(out_dir / "jitter.png")
    assert res["config"]["where"] == {} and res["config"]["store"] == store and res["n_scenes"] == 192
    assert res["config"]["histogram_shape_given"] == [3, 3, 128]  # the 8x8 captures were left out
    assert {(r["jitter_ps"], r["task"]) for r in res["rows"]} == {(j, t) for j in (0.0, 600.0)
                                                                  for t in ("loc", "shape", "size")}
    assert "[jitter 600 ps, level 2/2] done in" in err and "[jitter 0 ps, level 1/2] mlp shape (2/3): trained and tested in" in err
    code, out, err = run(capsys, "study", "jitter", "--store", store, "--where", "size=8in|4in,object=A|S|1",
                         "--jitter-ps", "100", "--models", "cnn1d", "--tasks", "size", "--small", "--quiet",
                         "--out", str(tmp_path / "o2"), "--plot", str(tmp_path / "fig" / "j.png"))
    assert code == 0 and err == ""
    assert "DENALI jitter study: centre zone" in out and "size acc %" in out and (tmp_path / "fig" / "j.png").is_file()


def test_cli_imports_a_denali_folder(capsys, tmp_path):
    rng = np.random.default_rng(0)
    for obj in ("A", "S"):
        for size in ("4inch", "8inch"):
            d = tmp_path / "data" / f"{obj}_{size}_3x3_lightoff_NLOSdata" / "spad_histogram"
            d.mkdir(parents=True)
            for p in range(8):
                np.save(d / f"{p:03d}.npy", rng.poisson(50.0, (2, 3, 3, 128)))
    code, out, err = run(capsys, "study", "jitter", "--denali", str(tmp_path / "data"), "--jitter-ps", "0,50",
                         "--models", "mlp", "--tasks", "size,loc", "--epochs", "1", "--out", str(tmp_path / "o"),
                         "--json")
    assert code == 0, err
    res = json.loads(out)
    assert res["config"]["store"] == str(tmp_path / "o" / "denali.sqlite")
    assert res["config"]["sources"] == ["real:denali"]
    assert res["n_scenes"] == 32 and res["config"]["n_captures"] == 64 and "imported 64 captures" in err


@pytest.mark.parametrize("argv, needle", [
    (("--jitter-ps", "0,-50"), "jitter -50 ps is not allowed"),
    (("--jitter-ps=-50",), "jitter -50 ps is not allowed"),
    (("--jitter-ps", "0,nan"), "nan ps is not allowed"),
    (("--jitter-ps", "fast"), "'fast' is not a number"),
    (("--models", "mlp,resnet"), "unknown model(s) resnet"),
    (("--where", "object=ZZZ"), "no captures in"),
    (("--where", "zones=8x8"), "odd zone grid (1x1, 3x3, 5x5, ...); the captures are 8x8"),
    (("--where", "lights"), "must look like column=value"),
    (("--trust-pickle",), "--trust-pickle only applies with --denali DIR"),
])
def test_cli_bad_inputs_exit_2_with_one_line(capsys, tmp_path, store, argv, needle):
    code, out, err = run(capsys, "study", "jitter", "--store", store, "--small", "--out", str(tmp_path), *argv)
    assert code == 2 and out == "" and err.count("\n") == 1 and err.startswith("nlosplan: error:")
    assert needle in err
    assert not (tmp_path / "jitter.json").exists()


def test_cli_refuses_missing_data_and_stores_without_3x3(capsys, tmp_path):
    code, _, err = run(capsys, "study", "jitter", "--small")
    assert code == 2 and err.count("\n") == 1 and "give --store PATH" in err and "--denali DIR" in err
    code, _, err = run(capsys, "study", "jitter", "--store", str(tmp_path / "none.sqlite"))
    assert code == 2 and err.count("\n") == 1 and "does not exist" in err
    only8 = tmp_path / "8x8.sqlite"
    _put(only8, synthetic_dataset(objects=("A", "S"), n_side=2, bins=128, zones=(8, 8)), preset("tmf8828-8x8-short"))
    code, _, err = run(capsys, "study", "jitter", "--store", str(only8), "--small")
    assert code == 2 and err.count("\n") == 1
    assert "has no 3x3 captures (it holds 8x8 captures)" in err and "odd zone grid" in err
    path = tmp_path / "bg.sqlite"
    bg = synthetic_dataset(objects=("NOOBJECT",), sizes=("4in",), n_side=2, bins=128)
    bg.labels["class_group"] = "background"
    _put(path, bg, preset("tmf8828-3x3-short"))
    with pytest.raises(UserError, match="only background"):
        load_study_dataset(path)
    assert len(load_study_dataset(path, drop_backgrounds=False)) == 4


def test_help_teaches_design_outputs_cost_and_examples(capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["study", "jitter", "--help"])
    assert exit_.value.code == 0
    out = " ".join(capsys.readouterr().out.split())
    for needle in ("centre zone", "training AND for testing", "jitter.csv", "jitter.md", "jitter.json", "jitter.png",
                   "Cost:", "--denali DIR", "examples:", "default: 0,50,100,600", "default: mlp,cnn1d"):
        assert needle in out, needle
    for line in examples("study jitter"):
        assert " ".join(line.split()) in out
