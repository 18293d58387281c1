"""``nlosplan design`` and its studies on the command line: errors are one line with exit code 2."""

import pytest

from nlosplan.cli import main


@pytest.mark.parametrize("argv, words", [
    (["design", "--requirement", "speed<=3"], "must look like loc<=0.05"),
    (["design", "--requirement", "shape>=2"], "in (0, 1]"),
    (["design", "--seeds", "0"], "0 is out of range"),
    (["design", "--workers", "0"], "0 is out of range"),
    (["design", "--quick", "--config", "/nonexistent/space.toml"], "does not exist"),
    (["design", "--quick", "--real", "/nonexistent/store.sqlite"], "capture store /nonexistent/store.sqlite does not exist"),
    (["study", "resolution", "--requirement", "loc"], "must look like"),
    (["design", "--cluster", "localhost:8786"], "give tcp://HOST:PORT"),
    (["design", "--cluster", "local:0"], "local:N (N >= 1)"),
])
def test_bad_inputs_exit_2_with_one_line(capsys, argv, words):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) >= 1 and words in err[-1] and "Traceback" not in "\n".join(err)


def test_bad_config_table_and_cluster_exit_2(capsys, tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[space]\nzones = ['3x3']\naxes = ['speed']\n")
    assert main(["design", "--quick", "--config", str(bad), "--out", str(tmp_path / "o")]) == 2
    assert "unknown design axis speed" in capsys.readouterr().err
    bad.write_text("[space\n")
    assert main(["design", "--quick", "--config", str(bad), "--out", str(tmp_path / "o")]) == 2
    assert "is not valid TOML" in capsys.readouterr().err


def test_help_teaches_with_examples(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["design", "--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    assert "nlosplan design --quick --json" in out and "--resume" in out and "--cluster" in out
    assert "least sensor hardware" in out
