"""``nlosplan simulate``: DENALI, corner and wall scenes; arrays, summaries, plan, warnings and one-line errors.

Every NLOS run uses ``--fidelity draft`` and the 3x3 preset: JAX compiles each
new plan shape once per process, so the DENALI default capture is simulated
once (module fixture) and its shape is reused.
"""

import contextlib
import io
import json

import numpy as np
import pytest

from nlosplan.cli import main

DRAFT = ("--fidelity", "draft")


def run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def outputs(tmp_path, name="h"):
    """``--out`` a folder (fixed file names inside) and ``--plot`` (OUT/histograms.png)."""
    return ("--out", str(tmp_path / name), "--plot")


@pytest.fixture(scope="module")
def denali(tmp_path_factory):
    """The default (DENALI) scene, draft fidelity, two noisy captures, JSON summary with the plan."""
    folder = tmp_path_factory.mktemp("denali")
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(["simulate", *DRAFT, "--repeats", "2", "--seed", "1", "--explain", "--json",
                     *outputs(folder)])
    return {"code": code, "summary": json.loads(out.getvalue()), "err": err.getvalue(), "dir": folder}


def test_denali_is_the_default_and_writes_every_array(denali):
    assert denali["code"] == 0 and denali["err"] == ""
    d = denali["dir"] / "h"
    expected, background, signal = (np.load(d / f) for f in ("expected.npy", "background.npy", "signal.npy"))
    counts, bg_counts = np.load(d / "counts.npy"), np.load(d / "background_counts.npy")
    for arr in (expected, background, signal):
        assert arr.shape == (3, 3, 128) and arr.dtype == np.float32
    assert counts.shape == bg_counts.shape == (2, 3, 3, 128)
    assert counts.dtype == bg_counts.dtype == np.int64 and counts.min() >= 0 and bg_counts.min() >= 0
    np.testing.assert_array_equal(signal, expected - background)
    # the object adds light late in the window, never removes any (beyond float32 rounding of the direct peak)
    assert signal.min() >= -4 * np.finfo(np.float32).eps * expected.max() and signal.sum() > 0
    assert signal[..., :64].sum() < 1e-3 * signal.sum()
    png = d / "histograms.png"
    assert png.read_bytes()[:4] == b"\x89PNG" and png.stat().st_size > 20_000
    assert sorted(p.name for p in d.iterdir()) == ["background.npy", "background_counts.npy", "counts.npy",
                                                   "expected.npy", "histograms.png", "signal.npy"]


def test_denali_json_summary(denali):
    s, d = denali["summary"], denali["dir"] / "h"
    signal, expected = np.load(d / "signal.npy"), np.load(d / "expected.npy")
    assert s["scene"]["kind"] == "denali"
    assert (s["scene"]["object"], s["scene"]["size"], s["scene"]["position"]) == ("A", "8in", 19)
    assert s["scene"]["lights"] == "off" and s["scene"]["reflectance"] == "retroreflective"
    assert s["sensor"] == "denali-tmf8828-3x3" and s["shape"] == [3, 3, 128] and s["zones"] is None
    # DENALI's calibrated unit brings the scene it was fitted with (Table 2): albedo, diffuse base, mount in signal
    assert s["scene"]["albedo"] == pytest.approx(0.3667) and s["scene"]["diffuse_albedo"] == pytest.approx(0.2)
    assert s["scene"]["mount"] is True and s["scene"]["mount_in_background"] is False
    assert s["totals"]["signal"] > 0
    assert s["totals"]["signal"] == pytest.approx(float(signal.sum(dtype=np.float64)), rel=1e-9)
    assert s["totals"]["expected"] == pytest.approx(float(expected.sum(dtype=np.float64)), rel=1e-9)
    assert s["totals"]["expected"] == pytest.approx(s["totals"]["background"] + s["totals"]["signal"], rel=1e-5)
    assert s["signal_peak_bin_per_zone"] == signal.argmax(-1).tolist()
    assert set(s["files"]) == {"expected", "background", "signal", "counts", "background_counts", "plot"}
    assert s["warnings"] == [] and s["seconds"] > 0 and s["repeats"] == 2 and s["seed"] == 1
    plan = s["plan"]
    left_out = {t["name"]: t["reason"] for t in plan["left_out"]}
    assert left_out["ambient light"] == "lights off"
    assert any(t["name"] == "object 'A_8in'" for t in plan["computed"])


def test_a_generic_sensor_keeps_the_scene_defaults_and_flags_override_the_scene_model(capsys, tmp_path):
    code, out, _ = run(capsys, "simulate", *DRAFT, "--repeats", "0", "--sensor", "tmf8828-3x3-short", "--json",
                       "--out", str(tmp_path / "g"))
    scene = json.loads(out)["scene"]
    assert code == 0 and scene["albedo"] == 0.5 and scene["diffuse_albedo"] == 0.0 and scene["mount"] is False
    code, out, _ = run(capsys, "simulate", *DRAFT, "--repeats", "0", "--no-mount", "--object-albedo", "0.3", "--json",
                       "--out", str(tmp_path / "n"))
    scene = json.loads(out)["scene"]
    assert code == 0 and scene["mount"] is False and scene["albedo"] == 0.3 and scene["diffuse_albedo"] == 0.2
    code, out, _ = run(capsys, "simulate", *DRAFT, "--repeats", "0", "--mount-in-background", "--json",
                       "--out", str(tmp_path / "b"))
    background_mount = json.loads(out)
    assert code == 0 and background_mount["scene"]["mount"] is True
    assert background_mount["scene"]["mount_in_background"] is True
    code, out, _ = run(capsys, "simulate", *DRAFT, "--repeats", "0", "--json", "--out", str(tmp_path / "s"))
    signal_mount = json.loads(out)
    # the mount in the signal (the scene model) adds its Lambertian return to the object's
    assert signal_mount["totals"]["signal"] > 1.05 * background_mount["totals"]["signal"]


@pytest.mark.parametrize("flags, words", [
    (("--mount", "--no-mount"), "--mount and --no-mount contradict"),
    (("--mount-in-signal", "--mount-in-background"), "contradict each other"),
    (("--sensor", "tmf8828-3x3-short", "--mount-in-signal"), "--mount-in-signal needs the mount"),
])
def test_contradicting_mount_flags_are_one_line(capsys, tmp_path, flags, words):
    code, out, err = run(capsys, "simulate", *DRAFT, "--repeats", "0", *flags, "--out", str(tmp_path / "x"))
    assert code == 2 and words in err and len(err.strip().splitlines()) == 1 and not (tmp_path / "x").exists()


def test_explain_text_and_no_noisy_captures(capsys, tmp_path, denali):
    code, out, err = run(capsys, "simulate", *DRAFT, "--repeats", "0", "--explain", "--out", str(tmp_path / "h"))
    assert code == 0 and err == ""
    assert "left out" in out and "ambient light" in out and "computed" in out
    assert "signal peak bin per zone" in out and "wrote signal:" in out
    peaks = np.load(denali["dir"] / "h" / "signal.npy").argmax(-1)
    assert " ".join(str(p) for p in peaks[0]) in " ".join(out.split())
    assert sorted(p.name for p in (tmp_path / "h").iterdir()) == ["background.npy", "expected.npy", "signal.npy"]


def test_explain_alone_explains_without_simulating_or_writing(capsys, tmp_path, monkeypatch):
    """``--explain`` alone (no --out, no --plot): the plan, no simulation, no file (not even the default folder)."""
    import nlosplan.simulators as simulators

    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(simulators, "simulate", lambda *a, **k: pytest.fail("--explain alone must not simulate"))
    code, out, err = run(capsys, "simulate", *DRAFT, "--explain", "--json")
    assert code == 0 and err == ""
    plan = json.loads(out)["plan"]
    assert any(t["name"] == "object 'A_8in'" for t in plan["computed"]) and plan["paths_per_scene"] > 0
    assert list(tmp_path.iterdir()) == []


def test_deprecated_npy_out_still_writes_beside_it_with_one_warning(capsys, tmp_path):
    code, out, err = run(capsys, "simulate", "--scene", "wall", "--repeats", "1", "--out", str(tmp_path / "h.npy"))
    assert code == 0
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("nlosplan: warning: --out") and "deprecated" in lines[0]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["h.npy", "h_counts.npy"]


def test_zones_on_a_preset_of_another_zone_mode_warns_what_it_keeps(capsys):
    code, out, err = run(capsys, "simulate", *DRAFT, "--zones", "8x8", "--explain")
    assert code == 0
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("nlosplan: warning: --zones 8x8 changes only the zone grid")
    from nlosplan.sensor_models import preset

    three = preset("denali-tmf8828-3x3")  # the default sensor: DENALI's unit
    assert f"keeps its 41x52 deg field of view and {three.iterations} iterations" in lines[0]
    assert "--sensor denali-tmf8828-8x8" in lines[0]


def test_explain_says_what_the_mixture_and_the_mount_compute(capsys, tmp_path):
    code, out, err = run(capsys, "simulate", "--explain", "--fidelity", "draft", "--only-zones", "1,1",
                         "--diffuse-albedo", "0.2", "--object-albedo", "0.4", "--mount", "--mount-in-signal",
                         "--plot", "", "--out", str(tmp_path / "m.npy"))
    assert code == 0, err
    lines = [" ".join(line.split()) for line in out.splitlines()]
    assert any(line.startswith("computed object 'A_8in': diffuse base Lambertian (albedo 0.2)") for line in lines)
    assert any(line.startswith("computed object 'object mount' Lambertian") for line in lines)
    assert any(line.startswith("computed object 'mount plate' Lambertian") for line in lines)
    assert not any("fixture" in line for line in lines)  # in the signal: not a fixture


def test_only_zones_gives_those_zones_of_the_full_grid(capsys, tmp_path, denali):
    code, out, _ = run(capsys, "simulate", *DRAFT, "--only-zones", "1,1;0,2", "--dtype", "float64", "--json",
                       *outputs(tmp_path))
    assert code == 0
    s = json.loads(out)
    assert s["zones"] == [[1, 1], [0, 2]] and s["shape"] == [2, 128] and s["dtype"] == "float64"
    sub = np.load(tmp_path / "h" / "expected.npy")
    assert sub.shape == (2, 128) and sub.dtype == np.float64
    assert np.load(tmp_path / "h" / "counts.npy").shape == (1, 2, 128)
    full = np.load(denali["dir"] / "h" / "expected.npy")
    np.testing.assert_allclose(sub, full[[1, 0], [1, 2]], rtol=2e-4, atol=1e-3)
    assert len(s["signal_peak_bin_per_zone"]) == 2


def test_corner_scene_is_lambertian_by_default(capsys, tmp_path):
    code, out, err = run(capsys, "simulate", "--scene", "corner", *DRAFT, "--repeats", "0", "--json",
                         *outputs(tmp_path))
    assert code == 0 and err == ""
    s = json.loads(out)
    assert s["scene"]["kind"] == "corner" and s["scene"]["reflectance"] == "lambertian"
    assert s["scene"]["object"] == "patch" and s["scene"]["object_xy"] == [0.45, 0.30]
    signal = np.load(tmp_path / "h" / "signal.npy")
    assert signal.shape == (3, 3, 128) and s["totals"]["signal"] > 0
    # the patch sits to the LiDAR's right (+x): the right-hand zone column sees more of its light
    assert signal[:, 2].sum() > signal[:, 0].sum()


def test_object_in_direct_view_warns_in_one_line_and_succeeds(capsys, tmp_path):
    code, out, err = run(capsys, "simulate", "--scene", "corner", "--object-xy", "0,0.2", *DRAFT, "--repeats", "0",
                         "--json", "--out", str(tmp_path / "h"))
    assert code == 0
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("nlosplan: warning:") and "direct field of view" in lines[0]
    assert "Traceback" not in err
    assert json.loads(out)["warnings"] == [lines[0].removeprefix("nlosplan: warning: ")]


def test_wall_scene_writes_what_it_did_before(capsys, tmp_path):
    from nlosplan.sensor_models import preset
    from nlosplan.simulators import WallScene, simulate_wall

    code, out, _ = run(capsys, "simulate", "--scene", "wall", "--repeats", "0", "--json", "--out", str(tmp_path / "h"))
    assert code == 0
    s = json.loads(out)
    assert s["scene"]["kind"] == "wall" and s["files"] == {"expected": str(tmp_path / "h" / "expected.npy")}
    np.testing.assert_array_equal(np.load(tmp_path / "h" / "expected.npy"),
                                  simulate_wall(WallScene(), preset("tmf8828-3x3-short")))
    assert [p.name for p in (tmp_path / "h").iterdir()] == ["expected.npy"]


@pytest.mark.parametrize(
    "argv, names",
    [
        (["--object", "Q"], "'Q'"),
        (["--object", "A_8in"], "'A_8in'"),
        (["--position", "100"], "position=100"),
        (["--size", "5in"], "'5in'"),
        (["--fidelity", "ultra"], "'ultra'"),
        (["--reflectance", "mirror"], "'mirror'"),
        (["--object-albedo", "2"], "--object-albedo: 2 is out of range; allowed: 0 to 1"),
        (["--only-zones", "5,5"], "(5,5)"),
        (["--only-zones", "one"], "'one'"),
        (["--scene", "corner", "--object-xy", "1;2"], "'1;2'"),
        (["--scene", "corner", "--object-xy", "0.3,-0.2"], "y=-0.2"),
        (["--scene", "corner", "--object", "Z_8in"], "'Z_8in'"),
        (["--scene", "corner", "--object", "/nonexistent/thing.obj"], "/nonexistent/thing.obj"),
        (["--scene", "corner", "--wall-distance", "0"], "--wall-distance: 0 is out of range"),
        (["--scene", "wall", "--position", "5"], "--position 5"),
        (["--scene", "wall", "--mount"], "--mount"),
        (["--scene", "wall", "--fidelity", "draft"], "--fidelity draft"),
        (["--scene", "wall", "--only-zones", "1,1"], "--only-zones 1,1"),
        (["--scene", "corner", "--size", "4in"], "--size 4in"),
        (["--distance", "0.3"], "--distance 0.3"),
        (["--scene", "denali", "--object-yaw", "10"], "--object-yaw 10.0"),
        (["--diffuse-albedo", "0.9"], "their sum must be <= 1"),
        (["--reflectance", "lambertian", "--diffuse-albedo", "0.2"], "diffuse albedo is its albedo"),
        (["--sensor", "tmf8828-3x3-short", "--mount-in-signal"], "--mount-in-signal needs the mount"),
        (["--scene", "wall", "--diffuse-albedo", "0.1"], "--diffuse-albedo"),
    ],
)
def test_bad_input_exits_2_with_one_line_naming_it(capsys, argv, names):
    code, out, err = run(capsys, "simulate", *argv, "--out", "/nonexistent-dir/never")
    assert code == 2 and out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("nlosplan: error:") and names in lines[0]


def test_unreadable_obj_is_one_line(capsys, tmp_path):
    bad = tmp_path / "bad.obj"
    bad.write_bytes(b"\xff\xfe\x00not an obj")
    code, out, err = run(capsys, "simulate", "--scene", "corner", "--object", str(bad), "--plot", "")
    assert code == 2 and out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("nlosplan: error:") and str(bad) in lines[0]


def test_help_shows_a_denali_a_corner_and_a_wall_example(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["simulate", "--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    assert "examples:" in out
    examples = out.split("examples:")[1]
    assert "nlosplan simulate --object A" in examples
    assert "nlosplan simulate --scene corner" in examples and "nlosplan simulate --scene wall" in examples
