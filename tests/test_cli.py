"""CLI behaviour: exit codes, one-line errors, JSON outputs, files written."""

import json

import numpy as np
import pytest

from nlosplan.cli import main


def run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.parametrize(
    "argv, must_contain",
    [
        (["sensor", "show", "tmf9999"], "tmf8828-3x3-short"),
        (["simulate", "--jitter-ps", "-5"], "argument --jitter-ps: -5 must be >= 0"),
        (["simulate", "--bins", "0"], "argument --bins: 0 is out of range"),
        (["simulate", "--zones", "3by3"], "--zones"),
        (["simulate", "--distance", "abc"], "argument --distance: 'abc' is not a number"),
        (["simulate", "--scene", "wall", "--albedo", "2"], "albedo"),
        (["sensor", "show", "/nonexistent/sensor.toml"], "sensor file /nonexistent/sensor.toml does not exist"),
        (["bogus-command"], "invalid choice"),
    ],
)
def test_user_errors_exit_2_with_one_line(capsys, argv, must_contain):
    code, out, err = run(capsys, *argv)
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("nlosplan: error:")
    assert must_contain in lines[0]
    assert "Traceback" not in err


def test_unreadable_sensor_file_is_a_user_error(tmp_path, capsys):
    bad = tmp_path / "s.toml"
    bad.write_text("zones_rows = = 3")
    code, _, err = run(capsys, "sensor", "show", str(bad))
    assert code == 2 and "not valid TOML" in err


def test_sensor_show_json_round_trips(capsys, tmp_path):
    code, out, _ = run(capsys, "sensor", "show", "tmf8828-3x3-short", "--json")
    assert code == 0
    data = json.loads(out)
    assert data["name"] == "tmf8828-3x3-short" and data["n_bins"] == 128
    assert (data["zones_rows"], data["zones_cols"]) == (3, 3)
    # the printed TOML is a valid sensor file for --sensor
    code, out, _ = run(capsys, "sensor", "show", "tmf8828-8x8-short", "--toml")
    path = tmp_path / "s.toml"
    path.write_text(out)
    code, out, _ = run(capsys, "sensor", "show", str(path), "--json")
    assert json.loads(out)["zones_rows"] == 8


def test_sensor_list_json_names_all_presets(capsys):
    code, out, _ = run(capsys, "sensor", "list", "--json")
    names = [r["name"] for r in json.loads(out)["presets"]]
    assert names == ["tmf8828-3x3-short", "tmf8828-3x3-plane-unit", "denali-tmf8828-3x3", "denali-tmf8828-8x8",
                     "tmf8828-4x4-short", "tmf8828-8x8-short", "tmf8828-3x3-long", "vl53l8ch-8x8"]
    data = json.loads(out)
    assert data["default"] == "denali-tmf8828-3x3"
    assert [r["name"] for r in data["presets"] if r["scene"] == "fitted"] == ["denali-tmf8828-3x3", "denali-tmf8828-8x8"]


def test_simulate_writes_npy_and_png(capsys, tmp_path):
    out_npy, out_png = tmp_path / "h.npy", tmp_path / "h.png"
    code, out, _ = run(capsys, "simulate", "--scene", "wall", "--distance", "0.3", "--zones", "4x4",
                       "--out", str(out_npy), "--plot", str(out_png), "--json", "--repeats", "2", "--seed", "3")
    assert code == 0
    summary = json.loads(out)
    mean = np.load(out_npy)
    counts = np.load(tmp_path / "h_counts.npy")
    assert mean.shape == (4, 4, 128) and counts.shape == (2, 4, 4, 128)
    assert counts.dtype == np.int64 and np.all(counts >= 0)
    assert out_png.stat().st_size > 10_000 and out_png.read_bytes()[:4] == b"\x89PNG"
    assert summary["files"]["expected"] == str(out_npy)
    assert abs(summary["total_expected_counts"] - float(mean.sum())) < 1e-6 * mean.sum()


def test_help_has_examples(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["simulate", "--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    assert "examples:" in out and "nlosplan simulate --scene wall --sensor" in out


@pytest.mark.slow  # the whole catalog (~90 s); every case also has its own test in tests/test_stability_*.py
def test_check_json_passes_at_least_20_cases(capsys):
    code, out, _ = run(capsys, "check", "--json")
    data = json.loads(out)
    assert len(data["cases"]) >= 20
    failed = [c for c in data["cases"] if not c["passed"]]
    assert not failed, failed
    assert code == 0
    assert all(set(c) >= {"name", "passed", "detail"} for c in data["cases"])


@pytest.mark.parametrize("group, sub", [("sensor", "list"), ("bench", "histogram"), ("dataset", "build"),
                                        ("study", "jitter"), ("evaluate", "crlb")])
def test_a_command_group_alone_names_its_subcommands_in_one_line(capsys, group, sub):
    assert main([group]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and err.startswith(f"nlosplan: error: nlosplan {group}: give a ")
    assert sub in err and f"see 'nlosplan {group} --help'" in err
