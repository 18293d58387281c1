"""The training budget of the design's learners (``nlosplan design --train-captures N``): checked before any work,
reaching every trained evaluation, recorded in result.json, and part of what a resume must match."""

import json
from dataclasses import replace

import numpy as np
import pandas as pd
import pytest

from nlosplan.cli import build_parser, main
from nlosplan.errors import UserError
from nlosplan.planner.design.budget import (TRAIN_CAPTURES, budget_statement, default_captures, real_capacity,
                                            training_set)
from nlosplan.planner.design.data import REFERENCE_COLUMNS, ReferenceData, SceneSet
from nlosplan.planner.design.evaluators import DEFAULT_FIDELITY, evaluate
from nlosplan.planner.design.jobs import DesignJob
from nlosplan.planner.design.run import CHECKPOINT, EVALUATIONS, DesignConfig, check_inputs, read_evaluations, \
    run_design
from nlosplan.planner.design.search import SearchConfig
from nlosplan.planner.design.space import DesignSpace
from nlosplan.planner.design.worlds import WorldsConfig

GENERIC = "tmf8828-3x3-short"


def one_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "Traceback" not in err[0], err
    return err[0]


# ----------------------------------------------------------------------------- bad input: exit 2, one line
@pytest.mark.parametrize("value, words", [
    ("0", "argument --train-captures: 0 is out of range; allowed: 2 to 100000"),
    ("-25", "argument --train-captures: -25 is out of range"),
    ("1", "argument --train-captures: 1 is out of range"),
    ("100001", "argument --train-captures: 100001 is out of range"),
    ("2.5", "argument --train-captures: '2.5' is not an integer"),
    ("many", "argument --train-captures: 'many' is not an integer"),
])
def test_bad_budgets_exit_2_with_one_line(capsys, tmp_path, value, words):
    assert main(["design", "--quick", "--train-captures", value, "--out", str(tmp_path / "o")]) == 2
    assert words in one_line(capsys)
    assert not (tmp_path / "o").exists()


def test_a_budget_the_memory_cannot_hold_exits_2_before_any_work(capsys, tmp_path):
    out = tmp_path / "o"
    # 100,000 captures of 3x3 x 128 bins on 256 workers at once: hundreds of GB
    assert main(["design", "--quick", "--train-captures", "100000", "--workers", "256", "--out", str(out)]) == 2
    line = one_line(capsys)
    assert "--train-captures 100,000 on 256 worker(s) needs about" in line and "give a smaller N" in line
    assert not out.exists()


def test_a_bad_budget_in_a_toml_file_is_one_line_naming_the_key(capsys, tmp_path):
    bad = tmp_path / "bad.toml"
    for value, words in (("0", "train_captures = 0 must be an integer from 2 to 100000"),
                         ('"lots"', 'train_captures = "lots" must be an integer')):
        bad.write_text(f"[search.fidelity.trained]\ntrain_captures = {value}\n")
        assert main(["design", "--quick", "--config", str(bad), "--out", str(tmp_path / "o")]) == 2
        line = one_line(capsys)
        assert words in line and str(bad) in line and "[search.fidelity.trained]" in line
    with pytest.raises(UserError, match=r"\[search.fidelity.trained\] train_captures=1 must be a whole number"):
        SearchConfig(fidelity={**DEFAULT_FIDELITY, "trained": {**DEFAULT_FIDELITY["trained"], TRAIN_CAPTURES: 1}})


def fake_store(path, repeats=(2,)):
    """A capture store of 3 objects x 2 sizes x 10 positions, ``repeats`` captures per scene (cycled)."""
    from nlosplan.data.store import CaptureStore
    from nlosplan.denali import class_group, positions_xy
    from nlosplan.sensor_models import preset

    sensor = preset(GENERIC)
    rng = np.random.default_rng(0)
    xy = positions_xy()
    items, i = [], 0
    for o in ("A", "S", "circle"):
        for s in ("4in", "8in"):
            for p in range(0, 100, 10):
                for r in range(repeats[i % len(repeats)]):
                    items.append((rng.poisson(20.0, (3, 3, sensor.n_bins)),
                                  {"object": o, "size": s, "position": p, "lights": "off", "repeat": r,
                                   "source": "test", "class_group": class_group(o), "x": float(xy[p, 0]),
                                   "y": float(xy[p, 1])}))
                i += 1
    with CaptureStore(path) as st:
        st.put_many(items, sensor=sensor)
    return path


def test_a_budget_above_what_a_real_store_holds_exits_2_before_any_work(capsys, tmp_path):
    store = fake_store(tmp_path / "real.sqlite")
    # 60 scenes x 2 captures: the 70/30 split by scene trains on 42 scenes, 84 captures
    out = tmp_path / "o"
    assert main(["design", "--quick", "--real", str(store), "--train-captures", "85", "--out", str(out)]) == 2
    line = one_line(capsys)
    assert "train_captures=85 (--train-captures) is more than the 84 training captures in" in line
    assert "give at most 84" in line and not out.exists()
    args = build_parser().parse_args(["design", "--quick", "--real", str(store), "--train-captures", "84"])
    from nlosplan.cli.design import build_config

    check_inputs(build_config(args))  # exactly what the store holds: accepted


def test_real_capacity_counts_the_training_side_s_captures():
    rows = [{"object": o, "size": "4in", "position": p, "lights": "off", "repeat": r, "zones": "3x3", "source": "t"}
            for o in ("A", "S") for p in range(5) for r in range(3 if p == 0 else 1)]
    labels = pd.DataFrame(rows)
    cap = real_capacity(labels)
    # 10 scenes: 7 train; the two 3-repeat scenes may both be on the training side: at most 7 + 4 captures
    assert (cap.scenes, cap.total, cap.captures) == (7, 14, 11)


# ----------------------------------------------------------------------------- the training set at a budget
def test_training_set_takes_a_subset_or_draws_more_and_says_when_it_cannot():
    x = np.arange(40, dtype=np.float32).reshape(40, 1, 1, 1)
    y = np.array(["a", "b"] * 20)
    same = training_set(x, y, None, seed=1, stratify=True)
    assert same[0] is x and same[2] == ""
    sub, ys, note = training_set(x, y, 10, seed=1, stratify=True)
    assert len(sub) == len(ys) == 10 and note == "" and sorted(ys) == ["a"] * 5 + ["b"] * 5
    assert set(sub.ravel()) <= set(x.ravel()) and len(set(sub.ravel())) == 10
    assert np.array_equal(sub, training_set(x, y, 10, seed=1, stratify=True)[0])  # seeded
    asked = []

    def more(rows):
        asked.append(rows)
        return 1000.0 + x[rows]  # a fresh capture of row i: 1000 + i

    big, yb, note = training_set(x, y, 100, seed=2, stratify=True, more=more)
    assert len(big) == len(yb) == 100 and note == ""
    assert np.array_equal(big[:40], x) and np.all(big[40:] >= 1000)
    rows = asked[0]
    assert len(rows) == 60 and np.array_equal(yb[40:], y[rows]) and np.array_equal(big[40:, 0, 0, 0] - 1000, rows)
    assert sorted(np.bincount(rows, minlength=40)) == [1] * 20 + [2] * 20  # spread evenly: once or twice again
    real, yr, note = training_set(x, y, 100, seed=2, stratify=True)
    assert real is x and "holds 40 real captures, fewer than the 100 asked" in note


def tiny_reference(tmp_path):
    """A saved 1x1 reference of 2 objects x 2 sizes x 50 positions whose histograms carry the position."""
    from nlosplan.denali import class_group, positions_xy

    space = DesignSpace(reference=GENERIC, zones=((1, 1),), axes=("zones",))
    sensor = space.layout_sensor((1, 1))
    xy = positions_xy()
    rows = [{"object": o, "size": s, "class_group": class_group(o), "position": p, "x": float(xy[p, 0]),
             "y": float(xy[p, 1]), "lights": "off"}
            for o in ("A", "S") for s in ("4in", "8in") for p in range(0, 100, 2)]
    labels = pd.DataFrame(rows, columns=list(REFERENCE_COLUMNS))
    bins = np.arange(sensor.n_bins)
    centre = 40 + 60 * np.hypot(labels["x"], labels["y"]).to_numpy()[:, None]
    means = 5.0 + 200.0 * np.exp(-0.5 * ((bins[None] - centre) / 3.0) ** 2)
    ref = ReferenceData(sensor, labels, means=means.reshape(len(rows), 1, 1, -1).astype(np.float32), source="test")
    return space, ref.save(tmp_path / "1x1_test.npz")


@pytest.mark.parametrize("n", [None, 60, 500])
def test_the_budget_reaches_the_trained_evaluator_and_sets_n_train(tmp_path, n):
    space, path = tiny_reference(tmp_path)
    fid = {**DEFAULT_FIDELITY["trained"], "epochs": 2, "bootstrap": 20}
    if n is not None:
        fid[TRAIN_CAPTURES] = n
    job = DesignJob("trained", "loc", space.layout_design((1, 1)), 3, fid, None, str(path), space.sensor.to_dict())
    out = evaluate(job)
    assert out["status"] == "ok", out["reason"]
    extra = out["extra"]
    want = default_captures(200) if n is None else n  # 200 scenes: 140 on the training side
    assert extra[TRAIN_CAPTURES] == n and extra["n_train"] == want and extra["n_fit"] + extra["n_val"] == want
    assert "train_note" not in extra and extra["n_test"] == 60
    assert default_captures(200) == 140


def test_a_budget_is_part_of_every_trained_job_s_key(tmp_path):
    space, path = tiny_reference(tmp_path)
    base = {**DEFAULT_FIDELITY["trained"]}
    keys = {DesignJob("trained", "loc", space.layout_design((1, 1)), 0, f, None, str(path),
                      space.sensor.to_dict()).key for f in (base, {**base, TRAIN_CAPTURES: 60},
                                                            {**base, TRAIN_CAPTURES: 61})}
    assert len(keys) == 3


# ----------------------------------------------------------------------------- a run with a budget
def tiny_config(n: int | None) -> DesignConfig:
    fid = {k: dict(v) for k, v in DEFAULT_FIDELITY.items()}
    fid["bound"]["draws"] = 40
    fid["trained"].update(epochs=2, bootstrap=20)
    if n is not None:
        fid["trained"][TRAIN_CAPTURES] = n
    return DesignConfig(
        space=DesignSpace(reference=GENERIC, zones=((3, 3),), bin_factors=(1,), axes=("jitter_fwhm_ps",)),
        search=SearchConfig(grid_points=2, refine_steps=0, seeds=1, candidates=1, optimize_evals=2, fidelity=fid,
                            max_seeds=1, budget=0, models=("mlp",)),
        scenes=SceneSet(objects=("A", "S"), positions=tuple(range(0, 100, 10)), crlb_objects=("A",), crlb_stride=5,
                        fidelity="draft"),
        worlds=WorldsConfig(count=1, candidates=1), label="quick")


def test_a_run_records_its_budget_and_a_resume_with_another_is_refused(tmp_path):
    from nlosplan.reports.design_report import minimum_hardware_text, write_design_report

    out = tmp_path / "o"
    result = run_design(tiny_config(50), out, workers=1)  # 40 scenes, 28 training scenes: more captures drawn
    trained = [r for r in read_evaluations(out / EVALUATIONS) if r["evaluator"] == "trained" and r["status"] == "ok"]
    assert trained and all(r["extra"]["n_train"] == 50 and r["extra"][TRAIN_CAPTURES] == 50 for r in trained)
    assert all(r["fidelity"][TRAIN_CAPTURES] == 50 for r in trained)
    budget = result["train_captures"]
    assert budget["requested"] == 50 and budget["default"] is False and budget["learner"] == {
        "loc": "mlp", "shape": "mlp", "size": "mlp"} and budget["models"] == ["mlp"] and budget["epochs"] == 2
    assert budget["rule"] == ("--train-captures 50: one per training scene (28) and 22 more noisy ones drawn; each the "
                              "mean of 2 noisy captures of its scene") and budget["captures"] == "simulated"
    assert json.loads((out / CHECKPOINT).read_text())["config"]["search"]["fidelity"]["trained"][TRAIN_CAPTURES] == 50
    assert all(r["train_captures"] == 50 for r in result["denali_point"] if r["verdict"] is not None)
    text = minimum_hardware_text(result, result["reference_bin_ps"])
    assert ("Training budget: 50 simulated training captures per learner at a design (--train-captures 50: one per "
            "training scene (28) and 22 more noisy ones drawn; each the mean of 2 noisy captures of its scene), "
            "at most 2 epochs; learners loc MLP, shape MLP, size MLP (the best of MLP on the reference design).") in text
    assert "with an MLP trained on 50 captures" in text
    write_design_report(result, out)
    assert "with an MLP trained on 50 captures" in (out / "report.md").read_text()
    with pytest.raises(UserError, match="another configuration"):
        run_design(tiny_config(60), out, resume=True, workers=1)
    with pytest.raises(UserError, match="another configuration"):
        run_design(tiny_config(None), out, resume=True, workers=1)


def test_the_default_budget_is_stated():
    full = budget_statement(None, default=default_captures(3000), learners={"loc": "mlp"}, models=("mlp", "cnn1d"),
                            epochs=30, repeats=2)
    assert full["requested"] == 2100 and full["default"] is True
    assert full["rule"] == ("the default: one per training scene, 70 % of the scenes; each the mean of 2 noisy "
                            "captures of its scene")
    sub = budget_statement(700, default=2100, learners={}, models=("mlp",), epochs=30, repeats=2, real=True)
    assert sub["rule"] == "--train-captures 700: a seeded subset of the 2,100 of one per training scene; real captures"
    assert sub["captures"] == "real" and sub["requested"] == 700 and sub["default"] is False
    assert default_captures(1000) == 700  # --quick
    args = build_parser().parse_args(["design", "--quick"])
    from nlosplan.cli.design import build_config

    assert TRAIN_CAPTURES not in build_config(args).search.fidelity["trained"]  # the default: keys as they were
    args = build_parser().parse_args(["design", "--quick", "--train-captures", "25200"])
    cfg = build_config(args)
    assert cfg.search.fidelity["trained"][TRAIN_CAPTURES] == 25200
    assert cfg.hash() != build_config(build_parser().parse_args(["design", "--quick"])).hash()
