"""``nlosplan bench real``: the realism table of the plane captures against the targets."""

import json
from pathlib import Path

import pytest

from nlosplan.cli import main

PLANE = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "tmf882x_distance" / "distance_data_even.json"


def test_missing_plane_data_is_one_line_before_any_work(tmp_path, capsys, monkeypatch):
    from nlosplan.cli.bench import real as bench_real

    def no_work(*a, **k):
        raise AssertionError("the Table-2 part ran before the inputs were checked")

    monkeypatch.setattr(bench_real, "run_table2", no_work)
    assert main(["bench", "real", "--plane", str(tmp_path / "none.json")]) == 2
    err = capsys.readouterr().err.strip()
    assert "plane captures not found at" in err and "give --plane PATH" in err and len(err.splitlines()) == 1


@pytest.mark.slow
def test_bench_real_json_contract_and_targets(capsys):
    if not PLANE.is_file():
        pytest.skip(f"plane data not found at {PLANE}")
    assert main(["bench", "real", "--plane", str(PLANE), "--folds", "3", "--json"]) == 0
    plane = json.loads(capsys.readouterr().out)["plane"]
    assert [z["zone"] for z in plane["zones"]] == list(range(9))
    for z in plane["zones"]:
        assert {"zone", "subbin_err_mean", "l1_mean", "l1_max", "amp_ratio_min", "amp_ratio_max"} <= set(z)
        assert all(z["meets"].values()), z
    s = plane["summary"]
    assert s["subbin_err_mean"] < 0.1 and s["l1_mean"] < 0.07 and s["l1_max"] < 0.15
    assert 0.85 < s["amp_ratio_min"] and s["amp_ratio_max"] < 1.2
