"""``nlosplan bench simulate``: error against run time of the fast simulator."""

import argparse
import json
import math
import os

import numpy as np
import pytest

from nlosplan.errors import UserError
from nlosplan.cli import bench as cli_bench
from nlosplan.reports import bench_text
from nlosplan.simulators.fast import bench, bench_metrics
from nlosplan.simulators.fast.fidelity import FIDELITY_LEVELS, Fidelity

SMALL_REFERENCE = Fidelity(zone_sub=4, flash_sub=6, flash_outer=6, object_samples=1024, time_oversample=4)
LEVELS = ("draft", "low")
#: Scene models of the small run (the mount's model costs two more Lambertian terms: left out here).
MODELS = ("retroreflective", "mixed")
REQUIRED = {"fidelity", "knobs", "seconds_single", "seconds_per_scene_batched", "scenes_per_second",
            "compile_seconds", "rel_l1_error", "centroid_shift_bins"}


def _parser() -> argparse.ArgumentParser:
    return cli_bench.add_arguments(argparse.ArgumentParser(prog="nlosplan bench simulate"))


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """One small run through the CLI glue: 6 positions, reference at position 0 with a small reference level."""
    plot = tmp_path_factory.mktemp("bench") / "bench_simulate.png"
    args = _parser().parse_args(["--levels", ",".join(LEVELS), "--positions", "6", "--reference-positions", "0",
                                 "--repeats", "1", "--plot", str(plot), "--baseline"])
    steps = []
    with pytest.MonkeyPatch.context() as mp:
        mp.setitem(FIDELITY_LEVELS, "reference", SMALL_REFERENCE)
        # the pruning study on the cheapest level: its compiled code is shared with that level's run
        result, text = cli_bench.run_from_args(args, steps.append, study_level="draft", matmul_n=256, min_seconds=0.0,
                                               models=MODELS)
    return result, text, plot, steps


@pytest.mark.slow  # one bench simulate run shared by the module (~2 min); CI runs it
def test_json_has_the_required_keys_and_types(run):
    result, _, _, steps = run
    assert {"levels", "reference", "pruning", "arithmetic", "machine", "config"} <= set(result)
    assert [r["fidelity"] for r in result["levels"]] == list(LEVELS)
    for r in result["levels"]:
        assert REQUIRED <= set(r)
        assert r["knobs"] == FIDELITY_LEVELS[r["fidelity"]].to_dict()
        for k in REQUIRED - {"fidelity", "knobs"}:
            assert isinstance(r[k], float) and math.isfinite(r[k]) and r[k] >= 0, k
        assert r["seconds_single"] > 0 and r["seconds_per_scene_batched"] > 0
        assert r["scenes_per_second"] == pytest.approx(1.0 / r["seconds_per_scene_batched"])
        # the batched timing covers the 6 positions; the error is the worst of the reference positions
        assert r["rel_l1_error"] == max(e["rel_l1_error"] for e in r["errors_per_position"])
    assert result["reference"]["knobs"] == SMALL_REFERENCE.to_dict()
    assert result["reference"]["half_knobs"]["object_samples"] == SMALL_REFERENCE.object_samples // 2
    assert result["config"]["positions"] == list(range(6)) and result["config"]["reference_positions"] == [0]
    assert result["machine"]["cpu_count"] >= 1 and result["machine"]["jax_devices"]
    # the levels ran with the compiled kernels (the test machines have a C++ compiler) on the usable cores'
    # threads, and the run says so
    kernel, threads = result["config"]["kernels"], result["config"]["threads"]
    assert result["config"]["deposit"] == "kernel" and kernel["available"] and kernel["why"].endswith(".so")
    assert threads == len(os.sched_getaffinity(0)) or "NLOSPLAN_SIM_THREADS" in os.environ
    assert f"deposit: kernel (the compiled kernels, {kernel['why']}); chunks on {threads} thread(s)" in run[1]
    assert len(steps) == bench.bench_steps(LEVELS, (0,), MODELS, baseline=True) and all(isinstance(s, str) and s for s in steps)
    json.dumps(result, allow_nan=False)  # strict JSON: no NaN or infinity


@pytest.mark.slow  # one bench simulate run shared by the module (~2 min); CI runs it
def test_errors_are_finite_and_reflect_the_levels(run):
    result, _, _, _ = run
    ref = result["reference"]
    assert 0 <= ref["reference_self_error"] < 0.05
    for r in result["levels"]:
        # a cheap level is a few % off, not orders of magnitude; the centroid (timing) is well inside a bin
        assert 0 < r["rel_l1_error"] < 0.5
        assert 0 <= r["centroid_shift_bins"] < 1.0
        # the levels are coarser than the reference, whose own error (half the samples) is the smaller
        assert r["rel_l1_error"] > ref["reference_self_error"]


@pytest.mark.slow  # one bench simulate run shared by the module (~2 min); CI runs it
def test_scene_models_are_timed_and_scored_in_the_same_run(run):
    result = run[0]
    rows = {r["model"]: r for r in result["models"]}
    assert list(rows) == list(MODELS)
    draft = next(r for r in result["levels"] if r["fidelity"] == "draft")
    # the retroreflective model is the study level's own scenes against the same reference
    assert rows["retroreflective"]["rel_l1_error"] == pytest.approx(draft["rel_l1_error"], rel=1e-9)
    assert rows["retroreflective"]["speed_ratio_vs_retroreflective"] == 1.0
    for r in rows.values():
        assert r["level"] == "draft" and 0 < r["rel_l1_error"] < 0.5 and 0 <= r["centroid_shift_bins"] < 1.0
        assert r["scenes_per_second"] > 0 and math.isfinite(r["speed_ratio_vs_retroreflective"])
    # the diffuse base costs paths of its own
    assert rows["retroreflective"]["paths_per_scene"] < rows["mixed"]["paths_per_scene"]
    assert bench.MODEL_OPTIONS["mixed+mount"] == {**bench.MODEL_OPTIONS["mixed"], "mount": True,
                                                  "mount_in_background": False}
    assert "model mixed (albedo=0.36, diffuse_albedo=0.2; draft, batched)" in run[1]
    # --baseline: the path of before issue 20 timed beside the current one, same results within float32 rounding
    for r in rows.values():
        b = r["baseline"]
        assert b["deposit"] == "scatter" and b["cache_chunks"] is False and b["threads"] == 1 and b["scenes_per_second"] > 0 and b["single_call_ms"] > 0
        assert r["single_call_ms"] > 0 and r["speed_ratio_vs_baseline"] == pytest.approx(
            b["scenes_per_second"] and r["scenes_per_second"] / b["scenes_per_second"])
        assert b["max_rel_diff_vs_new"] < 1e-5
        assert b["rel_l1_error"] == pytest.approx(r["rel_l1_error"], rel=1e-3, abs=1e-6)
    assert run[1].count("vs the path before issue 20 (scatter deposit, chunks gathered per call, same run)") == len(MODELS)


def test_unknown_scene_model_is_rejected():
    with pytest.raises(UserError, match="unknown scene model 'glossy'; allowed: retroreflective, mixed, mixed\\+mount"):
        bench.bench_simulate(levels=("draft",), positions=range(3), reference_positions=(0,), models=("glossy",))


@pytest.mark.slow  # one bench simulate run shared by the module (~2 min); CI runs it
def test_pruned_equals_unpruned_and_does_less(run):
    pr = run[0]["pruning"]
    assert pr["pruned_vs_full_max_rel_diff_counts"] < 1e-5
    assert pr["centre_vs_all_max_rel_diff"] < 1e-5
    assert pr["paths_pruned"] < pr["paths_full"] and pr["paths_centre_zone"] < pr["paths_pruned"]
    for k in ("prune_speedup", "centre_zone_speedup", "lights_off_speedup"):
        assert math.isfinite(pr[k]) and pr[k] > 0


@pytest.mark.slow  # one bench simulate run shared by the module (~2 min); CI runs it
def test_arithmetic_estimate(run):
    ar = run[0]["arithmetic"]
    assert ar["flops_per_scene"] == pytest.approx(sum(ar["flops_breakdown"].values()))
    assert ar["flops_breakdown"]["paths"] >= ar["paths_per_scene"] * 30
    assert ar["achieved_gflops"] > 0 and ar["matmul_peak"]["gflops"] > 0 and ar["fraction_of_peak"] > 0


@pytest.mark.slow  # one bench simulate run shared by the module (~2 min); CI runs it
def test_plot_is_a_png(run):
    result, text, plot, _ = run
    assert plot.is_file() and plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert result["plot"] == str(plot) and str(plot) in text


@pytest.mark.slow  # one bench simulate run shared by the module (~2 min); CI runs it
def test_text_names_every_level_and_the_verdict(run):
    _, text, _, _ = run
    for name in LEVELS:
        assert name in text
    assert "target (<= 1 % rel. L1 at >= 200" in text and "stretch" in text


# ---------------------------------------------------------------- cheap checks
def test_rel_l1_and_centroid_shift():
    rng = np.random.default_rng(0)
    ref = np.zeros((3, 3, 128))
    ref[..., 40:60] = rng.uniform(1, 2, (3, 3, 20))
    assert bench_metrics.rel_l1(1.02 * ref, ref) == pytest.approx(0.02)
    assert bench_metrics.rel_l1(ref, ref) == 0.0
    shifted = np.roll(ref, 3, axis=-1)
    assert bench_metrics.centroid_shift_bins(shifted, ref) == pytest.approx(3.0)
    assert bench_metrics.centroid_shift_bins(2.0 * ref, ref) == pytest.approx(0.0, abs=1e-12)
    # a zone with the reference's light but none in h: the whole window
    empty = ref.copy()
    empty[0, 0] = 0.0
    assert bench_metrics.centroid_shift_bins(empty, ref) == 128
    # zones without reference light do not count
    faint = ref.copy()
    faint[2, 2] = 0.0
    wrong = faint.copy()
    wrong[2, 2, 120] = 1e-9
    assert bench_metrics.centroid_shift_bins(wrong, faint) == pytest.approx(0.0, abs=1e-12)


def test_verdict_names_the_levels_that_meet_the_target():
    def row(name, err, sps):
        return {"fidelity": name, "rel_l1_error": err, "scenes_per_second": sps}

    res = {"levels": [row("a", 0.05, 5000), row("b", 0.008, 300), row("c", 0.002, 1500)],
           "config": {"zones": "3x3", "n_bins": 128, "target_rel_l1": 0.01, "target_scenes_per_second": 200.0,
                      "stretch_scenes_per_second": 1000.0},
           "reference": {"reference_self_error": 1e-4}}
    line = bench_text.verdict(res)
    assert "met by b, c; stretch (>= 1000/s): met by c" in line and "caution" not in line
    res["reference"]["reference_self_error"] = 0.006
    assert "caution" in bench_text.verdict(res)


def test_arguments_and_user_errors():
    args = _parser().parse_args([])
    assert args.levels == list(bench.DEFAULT_LEVELS) and args.positions == 100 and args.repeats == 3
    assert args.plot is None and not args.json  # plots are opt-in
    assert _parser().parse_args(["--plot"]).plot == "nlosplan-out/bench_simulate.png"
    assert cli_bench.reference_positions_for(100, None) == (0, 21, 47, 73, 99)
    assert cli_bench.reference_positions_for(30, None) == (0, 21)
    assert cli_bench.reference_positions_for(30, [5, 7]) == (5, 7)
    for bad in (["--levels", "reference"], ["--levels", "ultra"], ["--positions", "0"], ["--positions", "101"],
                ["--reference-positions", "a,b"], ["--reference-positions", "100"], ["--repeats", "0"],
                ["--objects", "nope"], ["--sizes", "5in"]):
        with pytest.raises(SystemExit):
            _parser().parse_args(bad)
    with pytest.raises(UserError, match="not among the timed positions"):
        bench.bench_simulate(levels=("draft",), positions=range(3), reference_positions=(50,))
    with pytest.raises(UserError, match="position"):
        bench.bench_simulate(levels=("draft",), positions=[0, 100])
    with pytest.raises(UserError, match="unknown fidelity level"):
        bench.bench_simulate(levels=("fast",))


def test_flop_estimate_counts_every_path():
    from nlosplan.sensor_models.presets import preset
    from nlosplan.simulators.fast.plan import build_plan
    from nlosplan.simulators.presets.denali import denali_scene

    from nlosplan.simulators.presets.corner import corner_scene

    plan = build_plan(denali_scene("A", "8in", 19), preset("tmf8828-3x3-short"), "draft")
    est = bench_metrics.flop_estimate(plan)
    # every path (first bounce or three-bounce) costs at least a deposit and its time
    assert est["paths"] >= plan.paths * (4 + bench_metrics.FLOPS_DEPOSIT)
    assert est["near_field"] == 0 and est["node_matmuls"] > 0  # DENALI's objects are far from the wall
    assert est["flops"] == pytest.approx(sum(v for k, v in est.items() if k != "flops"))
    near = bench_metrics.flop_estimate(build_plan(corner_scene(object_xy=(0.3, 0.01)), preset("tmf8828-3x3-short"),
                                                  "draft"))
    assert near["near_field"] > 0  # an object 1 cm from the wall takes the exact form factor


def test_a_mount_model_is_also_timed_as_denalis_captures_come():
    # every object and size at each position: the mount is computed once per position there, not once per scene
    from nlosplan.reports.bench_text import _model_lines
    from nlosplan.sensor_models.presets import preset

    said = []
    out = bench._layout_rate(bench.MODEL_OPTIONS["mixed+mount"], ("A", "S"), ("8in",), range(6),
                             preset("tmf8828-3x3-short"), "draft", "float32", 1, 0.0, said.append, "mixed+mount")
    lay = out["layout"]
    assert {k: lay[k] for k in ("scenes", "positions", "objects_and_sizes")} == {"scenes": 6, "positions": 3,
                                                                                 "objects_and_sizes": 2}
    assert math.isfinite(lay["scenes_per_second"]) and lay["scenes_per_second"] > 0
    assert said == ["models (draft): mixed+mount, 6 scenes as DENALI's layout (2 objects and sizes at 3 positions)"]
    row = {"model": "mixed+mount", "options": {"mount": True}, "level": "draft", "scenes_per_second": 10.0,
           "speed_ratio_vs_retroreflective": 0.5, "paths_per_scene": 1000, "rel_l1_error": 0.01,
           "centroid_shift_bins": 0.02, **out}
    text = "\n".join(_model_lines([row]))
    assert "as DENALI's captures come (2 objects and sizes at each of 3 positions, the mount computed once per " \
           "position)" in text
