"""The benchmark table: tidy rows, breakdowns, n/a entries, the report formats and ``nlosplan benchmark``."""

import json

import pandas as pd
import pytest
import torch
from synthetic_tasks import synthetic_dataset

from nlosplan.cli import benchmark as benchmark_cli
from nlosplan.cli.common import Parser
from nlosplan.errors import UserError
from nlosplan.reports.benchmark_table import benchmark_markdown, benchmark_table, benchmark_text, write_benchmark
from nlosplan.tasks.benchmark import run_benchmark


pytestmark = pytest.mark.usefixtures("one_torch_thread")


@pytest.fixture(scope="module")
def ds():
    return synthetic_dataset(n_side=5, bins=32, repeats=2)  # 300 scenes, 2 repeats each


@pytest.fixture(scope="module")
def result(ds):
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        return run_benchmark(ds, models=("mlp", "cnn1d"), epochs=15, width=0.25)
    finally:
        torch.set_num_threads(before)


def test_rows_are_tidy_and_complete(result):
    rows = pd.DataFrame(result["rows"])
    assert set(rows.columns) == {"model", "task", "metric", "group_by", "group", "value", "n"}
    assert not rows.duplicated(["model", "task", "metric", "group"]).any()
    for task, groups in {"loc": {"all", "4in", "8in", "numbers", "letters", "shapes"},
                         "shape": {"all", "near", "far", "4in", "8in"},
                         "size": {"all", "near", "far", "numbers", "letters", "shapes"}}.items():
        assert set(rows.query("task == @task")["group"]) == groups
    n = rows.query("model == 'mlp' and task == 'loc' and metric == 'loc_rmse'").set_index("group")["n"]
    assert n["all"] == 90 == n["4in"] + n["8in"] == n["numbers"] + n["letters"] + n["shapes"]  # 30 % of 300 scenes
    quad = rows.query("model == 'mlp' and task == 'size' and metric == 'top1_acc'").set_index("group")["n"]
    assert 0 < quad["near"] < 45 and 0 < quad["far"] < 45
    assert result["config"]["n_rows"] == 300 and result["config"]["n_rows_given"] == 600  # repeats averaged


def test_models_learn_and_times_are_recorded(result):
    value = {(r["model"], r["task"], r["metric"], r["group"]): r["value"] for r in result["rows"]}
    assert value[("mlp", "loc", "loc_rmse", "all")] < 0.04  # label spread ~0.12 m
    assert value[("mlp", "shape", "top1_acc", "all")] > 0.8  # 6 classes
    assert value[("mlp", "size", "top1_acc", "all")] > 0.9
    runs = pd.DataFrame(result["runs"])
    assert len(runs) == 6 and (runs["status"] == "ok").all()
    assert (runs["train_seconds"] > 0).all() and (runs["epochs_run"] <= 15).all()
    assert (runs["n_train"] + runs["n_val"] + runs["n_test"] == 300).all()


def test_pivot_to_the_papers_layout(result):
    table = benchmark_table(result)
    assert list(table.index) == ["mlp", "cnn1d"]
    assert table.columns.names == ["task", "metric", "group"]
    assert table.columns[0] == ("loc", "loc_rmse", "all") and ("size", "macro_recall", "shapes") in table.columns
    assert not table.isna().any().any()
    wide = pd.DataFrame(result["rows"]).pivot_table(index="model", columns=["task", "metric", "group"], values="value")
    assert wide.loc["cnn1d", ("shape", "macro_f1", "near")] == table.loc["cnn1d", ("shape", "macro_f1", "near")]


def test_text_markdown_and_files(result, tmp_path):
    text = benchmark_text(result)
    for needle in ("Localization", "Shape classification (6-way)", "Size classification", "RMSE", "Top-5", "Recall",
                   "near", "numbers", "cnn1d", "train s"):
        assert needle in text
    md = benchmark_markdown(result)
    assert md.startswith("# DENALI benchmark") and "| model | RMSE | MAE |" in md and "## Training runs" in md
    files = write_benchmark(result, tmp_path / "out")
    csv = pd.read_csv(files["csv"], index_col="model")
    assert list(csv.index) == ["mlp", "cnn1d"] and "loc/loc_rmse/all" in csv.columns and "shape/train_seconds" in csv
    assert json.loads(open(files["json"]).read())["config"]["models"] == ["mlp", "cnn1d"]


def test_ill_posed_split_gives_na_entries(ds):
    res = run_benchmark(ds, models=("mlp",), tasks=("loc", "shape"), split="objects", epochs=2, width=0.125)
    runs = {r["task"]: r for r in res["runs"]}
    assert runs["shape"]["status"] == "n/a" and runs["loc"]["status"] == "ok"
    assert {r["task"] for r in res["rows"]} == {"loc"}
    assert "shape: n/a" in benchmark_text(res)
    test_objects = set(runs["loc"]["split_info"]["test_objects"])
    assert len(test_objects) == 2  # 30 % of 6 classes


def test_bad_arguments(ds):
    with pytest.raises(UserError, match="unknown model"):
        run_benchmark(ds, models=("mlp", "svm"))
    with pytest.raises(UserError, match="unknown split"):
        run_benchmark(ds, split="diagonal")
    with pytest.raises(UserError, match="epochs"):
        run_benchmark(ds, epochs=0)


# ------------------------------------------------------------------------------------------------- CLI
def _parser():
    p = Parser(prog="nlosplan")
    sub = p.add_subparsers(dest="command", parser_class=Parser)
    benchmark_cli.add(sub)
    return p


@pytest.fixture
def fake_store(monkeypatch):
    """The CLI's loader, answered from a synthetic dataset; records the filters it was given."""
    calls = []
    small = synthetic_dataset(objects=("1", "A", "circle"), n_side=4, bins=32)

    def load(store, where):
        calls.append((store, where))
        return small.where(**where) if where else small

    monkeypatch.setattr(benchmark_cli, "_load_dataset", load)
    return calls


def test_cli_prints_the_table_and_writes_files(fake_store, tmp_path, capsys):
    out = tmp_path / "bench"
    args = _parser().parse_args(["benchmark", "--store", "s.sqlite", "--models", "mlp,cnn1d", "--tasks", "loc,size",
                                 "--epochs", "2", "--width", "0.125", "--where", "lights=off,zones=3x3,object=1|A",
                                 "--out", str(out), "--save-models"])
    assert args.func(args) == 0
    assert fake_store == [("s.sqlite", {"lights": "off", "zones": "3x3", "object": ["1", "A"]})]
    text = capsys.readouterr().out
    assert "Localization" in text and "Size classification" in text and "Shape" not in text
    assert "wrote csv" in text
    assert {p.name for p in out.iterdir()} == {"benchmark.csv", "benchmark.md", "benchmark.json", "models"}
    assert {p.name for p in (out / "models").iterdir()} == {"mlp_loc.pt", "cnn1d_loc.pt", "mlp_size.pt",
                                                            "cnn1d_size.pt"}


def test_cli_json(fake_store, tmp_path, capsys):
    args = _parser().parse_args(["benchmark", "--store", "s.sqlite", "--models", "mlp", "--tasks", "shape", "--small",
                                 "--split", "positions", "--out", str(tmp_path), "--json"])
    args.func(args)
    data = json.loads(capsys.readouterr().out)
    assert data["config"]["split"] == "positions" and data["config"]["width"] == 0.125
    assert data["config"]["epochs"] == 5 and data["files"]["csv"].endswith("benchmark.csv")
    assert {r["metric"] for r in data["rows"]} == {"top1_acc", "top5_acc", "macro_f1"}


@pytest.mark.parametrize("argv,match", [
    (["--models", "mlp,svm"], "unknown model"),
    (["--tasks", "depth"], "unknown task"),
    (["--split", "diagonal"], "invalid choice"),
    (["--epochs", "0"], "must be > 0"),
    (["--width", "-1"], "must be > 0"),
    (["--patience", "x"], "not an integer"),
    ([], "required"),
])
def test_cli_bad_options_are_one_line_errors(argv, match):
    base = [] if argv == [] else ["--store", "s.sqlite"]
    with pytest.raises(UserError, match=match) as err:
        _parser().parse_args(["benchmark", *base, *argv])
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("where,match", [("lights", "column=value"), ("position=a", "integers")])
def test_cli_bad_where_is_one_line(fake_store, tmp_path, where, match):
    args = _parser().parse_args(["benchmark", "--store", "s.sqlite", "--where", where, "--out", str(tmp_path)])
    with pytest.raises(UserError, match=match) as err:
        args.func(args)
    assert "\n" not in str(err.value)


def test_cli_reads_a_real_store_path_error(tmp_path):
    """Without the monkeypatch a missing store is one line (the store room's message)."""
    pytest.importorskip("nlosplan.data.store")
    args = _parser().parse_args(["benchmark", "--store", str(tmp_path / "none.sqlite"), "--out", str(tmp_path)])
    with pytest.raises(UserError, match="does not exist"):
        args.func(args)
