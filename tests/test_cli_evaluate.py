"""``nlosplan evaluate``: crlb and observer through argparse; JSON, exit codes and one-line errors.

The parser is built the way the ``nlosplan`` entry point builds it; UserError maps to exit code 2.
Runs are small (draft fidelity, one or two objects, a few positions).
"""

import json
import math

import pytest

from nlosplan.cli import build_parser, main
from nlosplan.cli.common import EXAMPLES
from nlosplan.sensor_models import preset

CRLB = ("evaluate", "crlb", "--objects", "A", "--positions", "0,45,99", "--fidelity", "draft")
OBSERVER = ("evaluate", "observer", "shape", "--objects", "A,circle", "--positions", "0,45,99", "--fidelity", "draft",
            "--draws", "40")


def run(capsys, *argv):
    """Exit code, stdout, stderr of one ``nlosplan`` command."""
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def crlb_json():
    """The crlb JSON of the small run (computed once)."""
    import contextlib
    import io

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main([*CRLB, "--json"]) == 0
    return json.loads(buf.getvalue())


def test_crlb_json_rms_is_the_rms_of_the_scene_bounds(crlb_json):
    d = crlb_json
    assert [s["position"] for s in d["scenes"]] == [0, 45, 99]
    assert all(s["object"] == "A" and s["size"] == "8in" and s["identifiable"] for s in d["scenes"])
    bounds = [s["rmse_bound_m"] for s in d["scenes"]]
    assert all(0 < b < 1 for b in bounds)
    assert d["rms_bound_m"] == pytest.approx(math.sqrt(sum(b * b for b in bounds) / len(bounds)), rel=1e-9)
    known = [s["rmse_bound_known_m"] for s in d["scenes"]]
    assert d["rms_bound_known_m"] == pytest.approx(math.sqrt(sum(k * k for k in known) / len(known)), rel=1e-9)
    assert all(b >= k * (1 - 1e-9) for b, k in zip(bounds, known))  # estimating nuisances never helps
    # the bound set beside DENALI's pooled loc_rmse: the 2-D bound with its trace halved under the root
    assert d["loc_rmse_bound_m"] == pytest.approx(d["rms_bound_m"] / math.sqrt(2), rel=1e-12)
    assert [s["loc_rmse_bound_m"] for s in d["scenes"]] == pytest.approx([b / math.sqrt(2) for b in bounds])
    assert d["unidentifiable"] == [] and d["fidelity"] == "draft" and d["seconds"] > 0


def test_crlb_more_photons_give_a_smaller_bound(capsys, crlb_json):
    code, out, _ = run(capsys, *CRLB, "--photon-scale", "100", "--json")
    assert code == 0
    d = json.loads(out)
    # the signal grows s times (the dark counts stay): the information grows between s and s^2 times
    s = 100 / preset("tmf8828-3x3-short").photon_scale
    base = crlb_json["rms_bound_known_m"]
    assert base / s * 0.99 <= d["rms_bound_known_m"] <= base / math.sqrt(s) * 1.01
    assert d["rms_bound_m"] < crlb_json["rms_bound_m"] / math.sqrt(s) * 1.01
    assert "photon scale 100" in d["sensor"]


def test_crlb_text_table_and_summary(capsys):
    code, out, _ = run(capsys, *CRLB[:-4], "--positions", "0,45", "--fidelity", "draft", "--objects", "A,S")
    assert code == 0
    assert "RMS bound mm" in out and "unidentifiable" in out
    assert "CRLB RMS over 4 scenes >=" in out and "fidelity draft" in out
    assert "NOT IDENTIFIABLE" not in out


def test_crlb_zero_photons_print_not_identifiable_and_null(capsys):
    code, out, _ = run(capsys, *CRLB, "--photon-scale", "0")
    assert code == 0
    assert "NOT IDENTIFIABLE" in out and "zero information" in out
    assert "e+" not in out  # no huge number in place of the bound
    code, out, _ = run(capsys, *CRLB, "--photon-scale", "0", "--json")
    assert code == 0
    assert "Infinity" not in out and "NaN" not in out
    d = json.loads(out)
    assert d["rms_bound_m"] is None
    assert all(s["rmse_bound_m"] is None and not s["identifiable"] and s["reason"] for s in d["scenes"])
    assert len(d["unidentifiable"]) == 3


def test_observer_json_accuracy_within_its_interval_and_high_for_distinct_objects(capsys):
    code, out, _ = run(capsys, *OBSERVER, "--json")
    assert code == 0
    d = json.loads(out)
    lo, hi = d["ci"]
    assert lo - 1e-9 <= d["accuracy"] <= hi + 1e-9  # the Wilson upper end of 100 % is 1 up to rounding
    assert d["chance"] == pytest.approx(0.5)
    assert d["n"] == 80 and d["fidelity"] == "draft"
    assert d["accuracy"] >= 0.95  # A vs circle at full photons: nearly noise-free


def test_observer_text(capsys):
    code, out, _ = run(capsys, *OBSERVER)
    assert code == 0
    assert "accuracy" in out and "chance   0.500" in out and "n 80" in out and "fidelity draft" in out


@pytest.mark.parametrize("argv, words", [
    (("evaluate", "crlb", "--objects", "nosuch"), "unknown object"),
    (("evaluate", "crlb", "--positions", "5-2"), "goes down"),
    (("evaluate", "crlb", "--positions", "100"), "out of range"),
    (("evaluate", "crlb", "--nuisance", "wind"), "not allowed"),
    (("evaluate", "crlb", "--nuisance", "none,dark"), "cannot be combined"),
    (("evaluate", "crlb", "--photon-scale", "-1"), "must be >= 0"),
    (("evaluate", "crlb", "--sensor", "nosuch-sensor"), "nosuch-sensor"),
    (("evaluate", "observer", "shape", "--draws", "0"), "must be >= 1"),
    (("evaluate", "observer", "shape", "--objects", "A"), "at least two objects"),
    (("evaluate", "observer", "colour"), "invalid choice"),
    (("evaluate", "observer", "shape", "--shape-known"), "size task"),
])
def test_bad_inputs_exit_2_with_one_line(capsys, argv, words):
    code, out, err = run(capsys, *argv)
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and err.startswith("nlosplan: error:") and words in err
    assert "Traceback" not in err


def test_main_maps_errors_to_exit_2(capsys):
    assert main(["evaluate", "observer", "shape", "--draws", "0"]) == 2
    assert capsys.readouterr().err.count("\n") == 1


@pytest.mark.parametrize("name, key, words", [
    ("crlb", "evaluate crlb", ("UNBIASED", "NOT IDENTIFIABLE", "Cost", "discrete")),
    ("observer", "evaluate observer", ("Bayes-optimal", "SAME model", "Cost", "chance")),
])
def test_help_teaches_and_shows_examples(capsys, name, key, words):
    with pytest.raises(SystemExit) as exc:
        build_parser().parse_args(["evaluate", name, "--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    assert "example" in out
    for e in EXAMPLES[key]:
        assert e in out
    for w in words:
        assert w in out


def test_crlb_text_says_which_nuisances_were_left_out(capsys):
    code, out, _ = run(capsys, *CRLB[:4], "--positions", "0", "--fidelity", "draft", "--nuisance", "photon_scale,ambient")
    assert code == 0
    assert "note: ambient left out: it does not change the counts (lights off)" in out
