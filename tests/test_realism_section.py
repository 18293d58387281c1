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
    assert len(df) == 4 + 16 + 4 and set(df["met"]) == {"yes", "NO"}
    assert (df["met"] == "NO").sum() == 3 and set(df[df["met"] == "NO"]["figure"]) == {"centroid"}
    assert "21 of 24 figures" in text and "tmf8828-3x3-short, is not one of them" in text
    _, text, _ = realism_section("denali-tmf8828-3x3")
    assert "is one of them" in text


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
