"""``nlosplan bench fidelity``: the equal-error speed-up and a small run of both backends."""

import json

import pytest

from nlosplan.cli import main
from nlosplan.simulators.mitsuba.bench import bench_fidelity, twin_time_at_error

TWIN = [{"rel_l1_error": 0.08, "seconds": 1.0}, {"rel_l1_error": 0.04, "seconds": 4.0},
        {"rel_l1_error": 0.02, "seconds": 16.0}]


def test_twin_time_at_error_interpolates_and_extrapolates_with_the_monte_carlo_slope():
    assert twin_time_at_error(TWIN, 0.04) == pytest.approx(4.0)
    assert twin_time_at_error(TWIN, 0.04 * 2**-0.5) == pytest.approx(8.0)  # log-log between rows
    assert twin_time_at_error(TWIN, 0.01) == pytest.approx(64.0)  # beyond the best: t ~ e^-2
    assert twin_time_at_error(TWIN, 0.16) == pytest.approx(0.25)


@pytest.mark.slow
def test_small_bench_rows_and_speedup():
    r = bench_fidelity(fast_levels=("draft", "default"), twin_levels=("draft", "low"), scenes=(("A", "8in", 19),),
                       reference_spp=2048)
    assert [(x["backend"], x["fidelity"]) for x in r["rows"]] == [("fast", "draft"), ("fast", "default"),
                                                                  ("mitsuba", "draft"), ("mitsuba", "low")]
    twin = {x["fidelity"]: x for x in r["rows"] if x["backend"] == "mitsuba"}
    assert twin["low"]["rel_l1_error"] < twin["draft"]["rel_l1_error"]  # more samples, less error
    assert r["speedup_level"] == "default" and r["speedup_at_equal_error"] > 1
    assert 0 < r["reference"]["rel_l1_self_error"] < 0.2


def test_bench_fidelity_bad_option_is_one_line(capsys):
    assert main(["bench", "fidelity", "--reference-spp", "10"]) == 2
    err = capsys.readouterr().err.strip()
    assert "10 is out of range; allowed: 256 to 1048576" in err and len(err.splitlines()) == 1
