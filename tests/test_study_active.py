"""``nlosplan study active-vs-raster`` at small size: JSON contract, invariants, files, bad input."""

import json

import pytest

from nlosplan.cli import main
from nlosplan.experiments.active_vs_raster import ActiveStudy, summarise, to_target
from nlosplan.errors import UserError


def run(capsys, *argv):
    code = main(list(argv))
    out = capsys.readouterr()
    return code, out.out, out.err


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    out = tmp_path_factory.mktemp("active")
    code = main(["study", "active-vs-raster", "--grid", "5", "--test-points", "6", "--budget", "10", "--batch", "5",
                 "--strategies", "raster,active-motion,doptimal", "--seeds", "0,1", "--target-rmse", "0.3",
                 "--out", str(out), "--quiet"])
    assert code == 0
    return out, json.loads((out / "active_vs_raster.json").read_text())


def test_json_contract_and_curves(small):
    out, res = small
    assert [s["name"] for s in res["strategies"]] == ["raster", "active-motion", "doptimal"]
    for s in res["strategies"]:
        assert {"name", "captures_to_target", "gantry_seconds_to_target", "interval"} <= set(s)
        lo, hi = s["interval"]
        if s["captures_to_target"] is not None:
            assert lo <= s["captures_to_target"] <= hi and s["captures_to_target"] % 5 == 0
        assert [t["target_rmse_m"] for t in s["targets"]] == [0.03, 0.04, 0.3]
        reached = [t["captures_to_target"] for t in s["targets"] if t["captures_to_target"] is not None]
        assert reached == sorted(reached, reverse=True)  # a looser target is never reached later
    assert set(res["ratio_best_to_raster"]) == {"0.03", "0.04", "0.3"}
    assert len(res["runs"]) == 6 and res["candidates"] == 25
    for r in res["runs"]:
        caps = [row["captures"] for row in r["curve"]]
        secs = [row["gantry_seconds"] for row in r["curve"]]
        assert caps == sorted(caps) and caps[-1] <= 10 and secs == sorted(secs) and secs[0] > 0
        assert len({tuple(p) for p in r["positions_mm"]}) == len(r["positions_mm"])  # no position twice
    raster = [r for r in res["runs"] if r["strategy"] == "raster"]
    assert raster[0]["positions_mm"][:3] == [[0.0, 0.0], [0.0, 80.0], [0.0, 160.0]]  # DENALI's snake: y first
    assert (out / "active_vs_raster.png").stat().st_size > 10_000
    assert "| strategy |" in (out / "active_vs_raster.md").read_text()
    assert res["versions"]["casadi"] and res["config"]["seeds"] == [0, 1]


def test_to_target_and_summary_intervals():
    curve = [{"captures": 5, "gantry_seconds": 10.0, "rmse_m": 0.1, "calibration_error": 3.0},
             {"captures": 10, "gantry_seconds": 22.0, "rmse_m": 0.02, "calibration_error": 0.5}]
    assert to_target(curve, "rmse_m", 0.03) == (10, 22.0)
    assert to_target(curve, "rmse_m", 0.01) == (None, None)
    study = ActiveStudy(strategies=("raster",), seeds=(0, 1), target_rmse_m=0.05)
    never = [dict(row, rmse_m=1.0) for row in curve]
    s = summarise([{"strategy": "raster", "curve": curve, "seconds": 1.0},
                   {"strategy": "raster", "curve": never, "seconds": 1.0}], study)[0]
    assert s["captures_to_target"] is None and s["interval"] == [10.0, None] and s["seeds_reached"] == 1
    assert study.more_targets_m == (0.03, 0.04)
    assert s["calibration"]["captures_to_target"] == 10.0
    assert [t["captures_to_target"] for t in s["targets"]] == [None, None, None]  # 0.03, 0.04 and the 0.05 target
    assert s["targets"][0]["interval"] == [10.0, None]
    with pytest.raises(UserError, match="more_targets_m must all be > 0"):
        ActiveStudy(more_targets_m=(0.0,))


def test_settings_and_cli_errors(capsys, tmp_path):
    with pytest.raises(UserError, match="unknown study setting"):
        ActiveStudy.from_dict({"speed": 1})
    bad = tmp_path / "bad.toml"
    bad.write_text("[study\n")
    code, _, err = run(capsys, "study", "active-vs-raster", "--config", str(bad))
    assert code == 2 and err.count("\n") == 1 and "study config" in err and "is not valid TOML" in err
    code, _, err = run(capsys, "study", "active-vs-raster", "--seeds", "a,b")
    assert code == 2 and "seeds are comma-separated integers" in err
    code, _, err = run(capsys, "study", "active-vs-raster", "--object", "Q", "--grid", "2", "--quiet")
    assert code == 2 and "unknown DENALI object 'Q'" in err
