"""The design report's "How real is this model" section, from the shipped bench-real scores."""

from __future__ import annotations

import pytest

from nlosplan.calibration.realism import shipped_realism
from nlosplan.reports.realism_section import realism_rows, realism_section


def test_shipped_scores_are_the_presets_and_their_verdicts_follow_the_targets():
    sh = shipped_realism()
    t2 = sh["table2"]
    assert sh["plane"]["sensor"] == "tmf8828-3x3-plane-unit" and t2["sensor"] == "denali-tmf8828-3x3"
    tg = t2["targets"]
    for r in t2["rows"]:  # every shipped verdict is what the targets say of the shipped numbers
        assert r["meets"]["total"] == (abs(r["total"] / r["real"]["total"] - 1) <= tg["total_rel"])
        assert r["meets"]["centroid"] == (abs(r["centroid"] - r["real"]["centroid"]) <= tg["centroid_bins"])
        assert r["meets"]["spread"] == (abs(r["spread"] / r["real"]["spread"] - 1) <= tg["spread_rel"])
        assert r["meets"]["skew"] == ((r["skew"] > 0) == (r["real"]["skew"] > 0))
    assert t2["meets"] == {"statistics": 13, "statistics_of": 16, "ratios": 4, "ratios_of": 4}


def test_section_table_counts_and_names_the_reference_sensor():
    title, text, df = realism_section("tmf8828-3x3-short")
    assert title == "How real is this model"
    assert len(df) == 4 + 16 + 4 + 6 + 4 and set(df["met"]) == {"yes", "NO"}
    issue16 = df[df["check"].str.startswith(("plane", "DENALI Table 2"))]
    assert (issue16["met"] == "NO").sum() == 3 and set(issue16[issue16["met"] == "NO"]["figure"]) == {"centroid"}
    assert "21 of 24 figures" in text and "tmf8828-3x3-short, is not one of them" in text
    _, text, _ = realism_section("denali-tmf8828-3x3")
    assert "is one of them" in text
    # the real Table 1 and the real-trained networks, beside Table 2: the gap is in the report, not only the docs
    assert "full budget) is within the band in 4 of 6 cells" in text and "0 of 4 of DENALI's networks" in text
    assert "(loc: DENALI's learner is further from its real figure here than its band)" in text


def test_table_1_and_checkpoint_rows_follow_issue_35_s_bands():
    from nlosplan.reports.realism_section import checkpoint_verdict, table1_verdict

    sh = shipped_realism()
    t1, ck = sh["table1"], sh["checkpoints"]
    assert t1["sensor"] == ck["sensor"] == "denali-tmf8828-3x3"
    tg = t1["targets"]
    rows = {(r["task"], r["model"]): r for r in t1["rows"]}
    loc = rows[("loc", "cnn1d")]  # four seeds of DENALI's recipe, their mean 1.40x Table 1's 4.56 cm
    assert loc["seeds"] == [42, 43, 44, 45] and loc["real"] == 0.0456
    assert sum(loc["predicted"]) / 4 == pytest.approx(0.0637, abs=5e-4) and not table1_verdict(loc, tg)
    assert table1_verdict(rows[("size", "cnn1d")], tg) and table1_verdict(rows[("shape", "cnn1d")], tg)
    # the bands themselves: size in absolute points, the others relative
    assert table1_verdict({"task": "size", "predicted": [0.927], "real": 0.9468}, tg)
    assert not table1_verdict({"task": "size", "predicted": [0.926], "real": 0.9468}, tg)
    assert table1_verdict({"task": "loc", "predicted": [0.0524], "real": 0.0456}, tg)
    assert not table1_verdict({"task": "loc", "predicted": [0.0525], "real": 0.0456}, tg)
    # the real-trained networks: at chance here, below issue 35's floor, which never asks more than their real score
    for r in ck["rows"]:
        assert not checkpoint_verdict(r, ck["targets"])
    mlp = {"task": "shape", "simulated": 0.079, "real": 0.0783}
    assert checkpoint_verdict(mlp, ck["targets"])  # 7.9 % passes for a network whose real score is 7.8 %
    _, _, df = realism_section("denali-tmf8828-3x3")
    assert list(df[df["check"] == "DENALI's real-trained networks here"]["real or target"])[0] == \
        "<= 7.00 cm (real 4.56 cm)"


def test_a_missed_plane_target_reads_no():
    sh = shipped_realism()
    sh["plane"]["summary"]["l1_max"] = 0.2
    df = realism_rows({"plane": sh["plane"]})
    assert list(df["met"]) == ["yes", "yes", "NO", "yes"]


@pytest.mark.slow
def test_shipped_table2_scores_are_what_bench_real_measures_today():
    from nlosplan.cli.bench.real import run_table2

    now = run_table2("denali-table2", "denali-tmf8828-3x3", 10)
    old = shipped_realism()["table2"]
    assert now["meets"] == old["meets"]
    for a, b in zip(now["rows"], old["rows"]):
        assert a["total"] == pytest.approx(b["total"], rel=0.01) and a["centroid"] == pytest.approx(b["centroid"], abs=0.05)


@pytest.mark.slow
def test_shipped_checkpoint_scores_are_what_bench_real_measures_today(shared_data):
    """DENALI's checkpoints from ../shared/data; simulates DENALI's 36,000 captures when not cached (~30 s)."""
    from nlosplan.cli.bench.real import run_checkpoints

    folder = shared_data / "denali" / "checkpoints"
    now = {c["name"]: c for c in run_checkpoints(folder, "denali-tmf8828-3x3", "full")["checkpoints"]}
    for r in shipped_realism()["checkpoints"]["rows"]:
        assert now[r["name"]]["simulated"] == pytest.approx(r["simulated"], rel=1e-6), r["name"]
