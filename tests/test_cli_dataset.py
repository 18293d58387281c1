"""``nlosplan dataset``: build, info, import-denali, export-denali through argparse; exit codes and one-line errors.

The parser is built here (the ``dataset`` module's ``add``), the way the
``nlosplan`` entry point builds it; UserError maps to exit code 2.
"""

import json

import numpy as np
import pytest

from nlosplan.cli import build_parser, main
from nlosplan.cli.common import EXAMPLES
from nlosplan.data.store import CaptureStore


def run(capsys, *argv):
    """Exit code, stdout, stderr of one ``nlosplan`` command."""
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


BUILD = ("dataset", "build", "--objects", "A", "--sizes", "4in", "--positions", "0,1", "--repeats", "2",
         "--fidelity", "draft")


def test_build_json_then_resume_then_info(capsys, tmp_path):
    store = str(tmp_path / "s.sqlite")
    code, out, err = run(capsys, *BUILD, "--store", store, "--json")
    assert code == 0, err
    s = json.loads(out)
    assert (s["captures_added"], s["captures_total"], s["positions"]) == (4, 4, [0, 1])
    assert s["sensor"] == "denali-tmf8828-3x3"  # DENALI's calibrated unit, with the scene it was fitted with
    assert s["scene_options"]["mount"] is True and s["scene_options"]["albedo"] == pytest.approx(0.3667)
    assert s["scene_options"]["mount_in_background"] is False and s["scene_options"]["diffuse_albedo"] == 0.2
    code, out, _ = run(capsys, *BUILD, "--store", store)
    assert code == 0 and out.startswith("stored 0 new captures") and "4 of 4 were there already" in out
    code, out, _ = run(capsys, "dataset", "info", "--store", store, "--json")
    info = json.loads(out)
    assert info["captures"] == 4 and info["groups"] == [dict(source="sim:fast", zones="3x3", lights="off", size="4in",
                                                              objects=1, positions=2, repeats=2, captures=4)]
    assert info["sensors"][0]["name"] == "denali-tmf8828-3x3" and info["sensors"][0]["captures"] == 4
    code, out, _ = run(capsys, "dataset", "info", "--store", store, "--by-object")
    assert code == 0 and "4 captures" in out and "sim:fast" in out and "object" in out


def test_build_with_a_generic_sensor_keeps_the_scene_defaults(capsys, tmp_path):
    code, out, err = run(capsys, *BUILD, "--sensor", "tmf8828-3x3-short", "--store", str(tmp_path / "g.sqlite"),
                         "--json")
    s = json.loads(out)
    assert code == 0, err
    assert s["sensor"] == "tmf8828-3x3-short" and s["scene_options"] == {"reflectance": "retroreflective"}


def test_import_export_round_trip(capsys, tmp_path):
    root = tmp_path / "data"
    d = root / "S_8inch_3x3_lighton_NLOSdata" / "spad_histogram"
    d.mkdir(parents=True)
    arrays = {p: np.random.default_rng(p).integers(0, 1000, (3, 3, 3, 128)) for p in (4, 9)}
    for p, a in arrays.items():
        np.save(d / f"{p:03d}.npy", a)
    (root / "stray").mkdir()
    store = str(tmp_path / "s.sqlite")
    code, out, err = run(capsys, "dataset", "import-denali", str(root), "--store", store)
    assert code == 0, err
    assert out.startswith("imported 6 captures from 2 files in 1 folders") and "skipped stray: not <object>_" in out
    code, out, _ = run(capsys, "dataset", "export-denali", "--store", store, "--out", str(tmp_path / "out"),
                       "--objects", "S", "--lights", "on", "--positions", "0-9", "--json")
    assert code == 0 and json.loads(out)["files_written"] == 2
    for p, a in arrays.items():
        assert np.array_equal(np.load(tmp_path / "out" / "S_8inch_3x3_lighton_NLOSdata" / "spad_histogram" /
                                      f"{p:03d}.npy"), a)
    code, _, err = run(capsys, "dataset", "export-denali", "--store", store, "--out", str(tmp_path / "o2"),
                       "--lights", "off")
    assert code == 2 and err.count("\n") == 1 and "no captures to export" in err


def test_pickle_refusal_is_one_line(capsys, tmp_path):
    d = tmp_path / "data" / "A_4inch_3x3_lightoff_NLOSdata" / "spad_histogram"
    d.mkdir(parents=True)
    (d / "000.joblib").write_bytes(b"anything")
    store = str(tmp_path / "s.sqlite")
    code, _, err = run(capsys, "dataset", "import-denali", str(tmp_path / "data"), "--store", store)
    assert code == 2 and err.count("\n") == 1
    assert "000.joblib: refusing to load" in err and "may run code" in err and "--trust-pickle" in err
    with CaptureStore(tmp_path / "s.sqlite") as st:
        assert st.count() == 0


@pytest.mark.parametrize("argv, msg", [
    (("--objects", "A,mug"), "unknown object 'mug'; allowed: all, numbers, letters, shapes, 0, 1"),
    (("--positions", "9-3"), "range '9-3' goes down"),
    (("--positions", "0-100"), "'0-100' is out of range; allowed: positions 0 to 99"),
    (("--positions", "a-b"), "'a-b' is not a position N or a range N-M"),
    (("--sizes", "6in"), "6in not allowed; allowed: 4in, 8in"),
    (("--lights", "dim"), "dim not allowed; allowed: on, off"),
    (("--repeats", "0"), "0 must be >= 1"),
    (("--fidelity", "ultra"), "unknown fidelity 'ultra'"),
    (("--sensor", "tmf9999"), "unknown sensor preset 'tmf9999'"),
])
def test_build_bad_values_are_one_line_errors(capsys, tmp_path, argv, msg):
    code, out, err = run(capsys, "dataset", "build", "--store", str(tmp_path / "s.sqlite"), *argv)
    assert code == 2 and out == "" and err.count("\n") == 1 and msg in err


def test_unreadable_or_missing_stores(capsys, tmp_path):
    text = tmp_path / "notes.txt"
    text.write_text("hello " * 200)
    for argv in (("dataset", "build", *BUILD[2:], "--store", str(text)), ("dataset", "info", "--store", str(text))):
        code, _, err = run(capsys, *argv)
        assert code == 2 and err.count("\n") == 1 and "is not an nlosplan capture store" in err
    code, _, err = run(capsys, "dataset", "info", "--store", str(tmp_path / "none.sqlite"))
    assert code == 2 and "does not exist" in err and not (tmp_path / "none.sqlite").exists()
    code, _, err = run(capsys, "dataset", "import-denali", str(tmp_path / "nowhere"), "--store",
                       str(tmp_path / "s.sqlite"))
    assert code == 2 and "does not exist or is not a folder" in err


@pytest.mark.parametrize("name", ["build", "import-denali", "export-denali", "info"])
def test_help_shows_the_examples(capsys, name):
    with pytest.raises(SystemExit) as e:
        build_parser().parse_args(["dataset", name, "--help"])
    out = capsys.readouterr().out
    assert e.value.code == 0 and "example" in out
    examples = EXAMPLES[f"dataset {name}"]
    for line in examples if isinstance(examples, tuple) else (examples,):
        assert line in out
