"""End to end, as a user runs it: build a small simulated DENALI store, then the four-model benchmark as JSON."""

from __future__ import annotations

import json

import numpy as np
import pytest

from nlosplan.cli import main

MODELS = ("mlp", "cnn1d", "cnn3d", "transformer")


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    """6 objects (two per class group) x 2 sizes x 8 positions x 2 repeats at draft fidelity (192 captures), on the
    datasheet unit's plain scenes (a third of the DENALI-calibrated default's time; test_cli_dataset covers that)."""
    path = tmp_path_factory.mktemp("e2e") / "small.sqlite"
    assert main(["dataset", "build", "--store", str(path), "--objects", "1,7,A,S,circle,plus",
                 "--positions", "0,3,9,33,66,90,96,99", "--repeats", "2",
                 "--fidelity", "draft", "--sensor", "tmf8828-3x3-short", "--json"]) == 0
    return path


@pytest.mark.slow  # 28 s and its store; tests/test_tasks_benchmark.py covers the table and the CLI fast, CI runs this
def test_benchmark_json_has_the_three_task_table_for_the_four_models(store, tmp_path, capsys):
    capsys.readouterr()
    out = tmp_path / "bm"
    assert main(["benchmark", "--store", str(store), "--small", "--out", str(out), "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["config"]["n_rows"] == 96 and res["config"]["n_rows_given"] == 192  # repeats averaged
    runs = {(r["model"], r["task"]): r for r in res["runs"]}
    assert set(runs) == {(m, t) for m in MODELS for t in ("loc", "shape", "size")}
    assert all(r["status"] == "ok" and r["train_seconds"] > 0 and r["n_test"] in (28, 29, 30)
               and r["n_train"] + r["n_val"] + r["n_test"] == 96 for r in runs.values())

    overall = {(r["model"], r["task"], r["metric"]): r["value"] for r in res["rows"] if r["group_by"] == "all"}
    # localization: every model beats predicting the mean position (the corners are ~0.24 m from the centre)
    for m in MODELS:
        assert 0 < overall[(m, "loc", "mae")] <= overall[(m, "loc", "loc_rmse")] < 0.2
        assert 0 <= overall[(m, "shape", "top1_acc")] <= overall[(m, "shape", "top5_acc")] <= 1
    # the breakdowns partition the test rows: per model and task, the group counts (shape by size, size by
    # class group) add up to the test set
    # and the overall accuracy is their count-weighted mean (for size, what a --small run on 67 training rows
    # reaches need not be much; the learning itself is tested on synthetic data in test_tasks_benchmark.py)
    for m in MODELS:
        for task, by in (("shape", "size"), ("size", "class_group")):
            parts = [(r["n"], r["value"]) for r in res["rows"]
                     if (r["model"], r["task"], r["metric"], r["group_by"]) == (m, task, "top1_acc", by)]
            assert sum(n for n, _ in parts) == runs[(m, task)]["n_test"]
            weighted = sum(n * v for n, v in parts) / runs[(m, task)]["n_test"]
            assert weighted == pytest.approx(overall[(m, task, "top1_acc")], abs=1e-12)
    # the paper's breakdowns are there
    groups = {(r["task"], r["group_by"]) for r in res["rows"]}
    assert {("loc", "size"), ("loc", "class_group"), ("shape", "quadrant"), ("shape", "size"),
            ("size", "quadrant"), ("size", "class_group")} <= groups
    assert {"csv", "markdown", "json"} <= set(res["files"])
    table = (out / "benchmark.md").read_text()
    assert all(m in table for m in MODELS) and np.isfinite(res["seconds"])
