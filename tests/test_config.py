"""SensorConfig: validation, round trips, immutability."""

from __future__ import annotations

import dataclasses
import json
import math
import tomllib

import numpy as np
import pytest

from nlosplan.errors import UserError
from nlosplan.sensor_models.config import SensorConfig
from nlosplan.sensor_models.presets import load_sensor_file, preset

PULSE = (0.0, 1.0, 4.0, 6.0, 3.0, 1.0)  # sums to 15, not normalised


def _full_config(**over):
    kw = dict(
        name="tmf8828-like",
        zones_rows=4,
        zones_cols=4,
        n_bins=256,
        bin_width_ps=250.0,
        start_offset_ps=-3250.0,
        fov_x_deg=41.0,
        fov_y_deg=52.0,
        flash_profile="uniform",
        flash_fwhm_x_deg=25.5,
        flash_fwhm_y_deg=33.25,
        sensitivity_cos_power=1.5,
        pulse_fwhm_ps=333.3,
        jitter_fwhm_ps=123.456,
        photon_scale=2.5e-3,
        iterations=1_100_000,
        ambient_rate_hz=1.25e6,
        dark_rate_hz=321.0,
        crosstalk=0.07,
        pileup=True,
        saturation=False,
        notes="values from a datasheet",
    )
    kw.update(over)
    return SensorConfig(**kw)


CONFIGS = {
    "default": SensorConfig(),
    "full": _full_config(),
    "pulse": _full_config(pulse_shape=PULSE, pulse_shape_step_ps=50.0, pulse_shape_t0_ps=-125.0),
}


def _assert_same(a: SensorConfig, b: SensorConfig):
    assert a == b
    assert a.to_dict() == b.to_dict()  # includes notes (compare=False in ==)


# -------------------------------------------------------------- round trips
@pytest.mark.parametrize("key", sorted(CONFIGS))
def test_toml_round_trip(key):
    cfg = CONFIGS[key]
    text = cfg.to_toml()
    assert "pulse_shape =" in text if cfg.pulse_shape is not None else "pulse_shape =" not in text
    tomllib.loads(text)  # valid TOML
    _assert_same(SensorConfig.from_toml(text), cfg)


@pytest.mark.parametrize("key", sorted(CONFIGS))
def test_json_round_trip(key):
    cfg = CONFIGS[key]
    text = cfg.to_json()
    data = json.loads(text)
    assert data["pulse_shape"] == (None if cfg.pulse_shape is None else list(cfg.pulse_shape))
    _assert_same(SensorConfig.from_json(text), cfg)


@pytest.mark.parametrize("suffix", [".toml", ".json"])
@pytest.mark.parametrize("key", sorted(CONFIGS))
def test_file_round_trip(tmp_path, key, suffix):
    cfg = CONFIGS[key]
    path = tmp_path / f"sensor{suffix}"
    cfg.save(path)
    _assert_same(load_sensor_file(path), cfg)
    _assert_same(load_sensor_file(str(path)), cfg)
    assert not [p for p in tmp_path.iterdir() if p != path]  # written atomically: no temporary file left


def test_dict_round_trip_and_types():
    cfg = CONFIGS["pulse"]
    d = cfg.to_dict()
    assert isinstance(d["pulse_shape"], list)
    assert set(d) == {f.name for f in dataclasses.fields(SensorConfig)}
    _assert_same(SensorConfig.from_dict(d), cfg)


@pytest.mark.parametrize("seed", range(12))
def test_round_trip_is_exact_for_arbitrary_pulse_shapes(seed):
    """Re-normalising an already normalised pulse must not change it (idempotent)."""
    shape = tuple(np.random.default_rng(seed).random(3 + seed))
    cfg = SensorConfig(pulse_shape=shape)
    again = SensorConfig(pulse_shape=cfg.pulse_shape)
    assert again.pulse_shape == cfg.pulse_shape
    assert SensorConfig.from_json(cfg.to_json()) == cfg
    assert SensorConfig.from_toml(cfg.to_toml()) == cfg
    assert cfg.replace(name="renamed").pulse_shape == cfg.pulse_shape


@pytest.mark.parametrize(
    "field, value",
    [("n_bins", np.int64(64)), ("iterations", np.int64(1000)), ("bin_width_ps", np.float32(62.5))],
)
def test_numpy_scalars_accepted_by_validation_can_be_saved(tmp_path, field, value):
    """Values built with numpy (sweeps) pass validation, so they must also serialise."""
    cfg = SensorConfig(**{field: value})
    assert SensorConfig.from_json(cfg.to_json()) == cfg
    assert SensorConfig.from_toml(cfg.to_toml()) == cfg


def test_save_and_load_reject_other_suffixes(tmp_path):
    with pytest.raises(UserError, match=r"\.toml or \.json"):
        SensorConfig().save(tmp_path / "sensor.yaml")
    (tmp_path / "sensor.txt").write_text("n_bins = 3\n")
    with pytest.raises(UserError, match=r"\.toml or \.json"):
        load_sensor_file(tmp_path / "sensor.txt")


def test_load_missing_file_and_bad_syntax(tmp_path):
    with pytest.raises(UserError, match="nope.toml does not exist"):
        load_sensor_file(tmp_path / "nope.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("n_bins = = 3\n")
    with pytest.raises(UserError, match="not valid TOML"):
        load_sensor_file(bad)
    with pytest.raises(UserError, match="not valid JSON"):
        SensorConfig.from_json("{n_bins: 3")
    with pytest.raises(UserError, match="table/object"):
        SensorConfig.from_json("[1, 2]")


def test_partial_file_uses_defaults():
    cfg = SensorConfig.from_toml('name = "x"\nn_bins = 64\n')
    assert cfg == SensorConfig(name="x", n_bins=64)


def test_invalid_value_in_file_names_field():
    with pytest.raises(UserError, match="n_bins"):
        SensorConfig.from_toml("n_bins = 0\n")
    with pytest.raises(UserError, match="jitter_fwhm_ps"):
        SensorConfig.from_json('{"jitter_fwhm_ps": -5}')


# ----------------------------------------------------------------- validation
INVALID = [
    ("jitter_fwhm_ps", -1.0),
    ("pulse_fwhm_ps", -0.5),
    ("n_bins", 0),
    ("n_bins", 4097),
    ("n_bins", 128.0),
    ("zones_rows", 17),
    ("zones_cols", 17),
    ("zones_cols", 0),
    ("bin_width_ps", 0.0),
    ("bin_width_ps", -10.0),
    ("bin_width_ps", math.nan),
    ("bin_width_ps", math.inf),
    ("photon_scale", math.nan),
    ("start_offset_ps", math.nan),
    ("fov_x_deg", 0.0),
    ("fov_x_deg", 170.0),
    ("fov_y_deg", 0.0),
    ("fov_y_deg", 170.0),
    ("fov_y_deg", "33"),
    ("flash_profile", "lambertian"),
    ("flash_fwhm_x_deg", 0.0),
    ("iterations", -1),
    ("iterations", True),
    ("zones_rows", True),
    ("n_bins", False),
    ("bin_width_ps", True),
    ("pileup", 1),
    ("saturation", "yes"),
    ("ambient_rate_hz", -1.0),
    ("dark_rate_hz", math.nan),
    ("crosstalk", -0.1),
    ("pulse_shape_step_ps", 0.0),
    ("pulse_shape", (1.0, -1.0)),
    ("pulse_shape", (0.0, 0.0)),
    ("pulse_shape", (1.0, math.nan)),
    ("pulse_shape", ()),
    ("pulse_shape", (1.0,) * 513),
]


@pytest.mark.parametrize("field, value", INVALID, ids=[f"{f}={v!r}"[:40] for f, v in INVALID])
def test_invalid_values_raise_user_error_naming_field(field, value):
    with pytest.raises(UserError) as info:
        SensorConfig(**{field: value})
    msg = str(info.value)
    assert field in msg
    assert "\n" not in msg  # one line
    # the same through replace() and from_dict()
    with pytest.raises(UserError, match=field):
        SensorConfig().replace(**{field: value})
    with pytest.raises(UserError, match=field):
        SensorConfig.from_dict({field: list(value) if isinstance(value, tuple) else value})


@pytest.mark.parametrize("value", [5, "abc", [1.0, "a"], {"a": 1}])
def test_malformed_pulse_shape_in_dict_raises_user_error(value):
    """A bad pulse_shape from a user file is a UserError, not a TypeError/ValueError traceback."""
    with pytest.raises(UserError, match="pulse_shape"):
        SensorConfig.from_dict({"pulse_shape": value})


def test_error_message_shows_bad_value():
    with pytest.raises(UserError, match=r"n_bins=0 .*1 to 4096"):
        SensorConfig(n_bins=0)
    with pytest.raises(UserError, match=r"flash_profile='lambertian'.*gaussian, uniform"):
        SensorConfig(flash_profile="lambertian")
    with pytest.raises(UserError, match=r"fov_x_deg=170\.0"):
        SensorConfig(fov_x_deg=170)


@pytest.mark.parametrize("build", ["replace", "from_dict"])
def test_unknown_field_names_it(build):
    with pytest.raises(UserError) as info:
        if build == "replace":
            SensorConfig().replace(jitter_fwhm=10.0)
        else:
            SensorConfig.from_dict({"jitter_fwhm": 10.0, "n_bins": 64})
    msg = str(info.value)
    assert "jitter_fwhm" in msg and "allowed" in msg and "jitter_fwhm_ps" in msg
    assert "\n" not in msg


def test_boundary_values_are_valid():
    cfg = SensorConfig(
        zones_rows=1, zones_cols=16, n_bins=4096, iterations=0, fov_x_deg=169.9, fov_y_deg=1e-3,
        jitter_fwhm_ps=0.0, photon_scale=0.0, flash_fwhm_x_deg=360.0,
    )
    assert cfg.n_zones == 16 and cfg.window_ps == 4096 * 100.0
    assert SensorConfig(n_bins=np.int64(7), zones_rows=np.int32(2)).n_bins == 7


def test_replace_validates_and_returns_new_object():
    base = SensorConfig()
    new = base.replace(n_bins=64, jitter_fwhm_ps=50.0)
    assert new is not base and new.n_bins == 64 and new.jitter_fwhm_ps == 50.0
    assert base.n_bins == 128 and base.jitter_fwhm_ps == 0.0
    with pytest.raises(UserError, match="n_bins"):
        base.replace(n_bins=0)
    with pytest.raises(UserError, match="fov_x_deg"):
        base.replace(fov_x_deg=float("nan"))


def test_pulse_shape_normalised_to_unit_sum():
    cfg = SensorConfig(pulse_shape=PULSE)
    assert isinstance(cfg.pulse_shape, tuple)
    assert all(isinstance(v, float) for v in cfg.pulse_shape)
    assert math.isclose(sum(cfg.pulse_shape), 1.0, rel_tol=1e-15)
    np.testing.assert_allclose(cfg.pulse_shape, np.array(PULSE) / 15.0, rtol=1e-15)
    # from a list / ndarray, too
    assert SensorConfig(pulse_shape=list(PULSE)).pulse_shape == cfg.pulse_shape
    assert SensorConfig(pulse_shape=np.array(PULSE)).pulse_shape == cfg.pulse_shape


def test_frozen():
    cfg = SensorConfig()
    with pytest.raises(dataclasses.FrozenInstanceError):
        cfg.n_bins = 5
    with pytest.raises(dataclasses.FrozenInstanceError):
        cfg.pulse_shape = (1.0,)
    assert cfg.n_bins == 128
    hash(cfg)  # usable as a dict key / cache key


def test_derived_quantities():
    cfg = SensorConfig(n_bins=10, bin_width_ps=50.0, start_offset_ps=-100.0, pulse_fwhm_ps=300.0, jitter_fwhm_ps=400.0)
    np.testing.assert_allclose(cfg.bin_edges_ps(), -100.0 + 50.0 * np.arange(11), rtol=0, atol=0)
    assert cfg.bin_edges_ps().dtype == np.float64
    assert cfg.window_ps == 500.0
    assert cfg.impulse_sigma_ps == pytest.approx(500.0 / 2.3548200450309493, rel=1e-15)
    assert cfg.max_count == 2**24 - 1


def test_notes_do_not_affect_equality():
    assert SensorConfig(notes="a") == SensorConfig(notes="b")
    assert SensorConfig(notes="a").to_dict()["notes"] == "a"


# -------------------------------------------------------------- sensor files: base preset or every field
def test_a_file_names_its_base_preset_or_gives_every_field(tmp_path):
    """No silent fallback: an empty or partial file without ``base`` is refused, not filled with class defaults."""
    empty = tmp_path / "empty.toml"
    empty.write_text("")
    with pytest.raises(UserError, match="empty.toml: the file is empty; name the preset it refines"):
        load_sensor_file(empty)
    partial = tmp_path / "partial.json"
    partial.write_text('{"n_bins": 64}')
    with pytest.raises(UserError, match=r"partial.json: the file misses ambient_rate_hz, bin_width_ps"):
        load_sensor_file(partial)
    based = tmp_path / "mine.toml"
    based.write_text('base = "tmf8828-3x3-short"\nn_bins = 64\n')
    got = load_sensor_file(based)
    want = preset("tmf8828-3x3-short").replace(n_bins=64, name="mine (tmf8828-3x3-short)")
    assert got == want and got.name == "mine (tmf8828-3x3-short)" and got.bin_width_ps == want.bin_width_ps


@pytest.mark.parametrize("text, words", [
    ('base = "tmf9999"\n', "base = 'tmf9999' is not a sensor preset"),
    ('base = 3\n', "base = 3 is not a sensor preset"),
    ('base = "tmf8828-3x3-short"\njiter_fwhm_ps = 3.0\n', "unknown field(s) jiter_fwhm_ps"),
    ('base = "tmf8828-3x3-short"\nn_bins = "many"\n', "n_bins='many' must be an integer"),
    ('base = "tmf8828-3x3-short"\npileup = 1\n', "pileup=1 must be true or false"),
])
def test_bad_sensor_file_fields_are_named(tmp_path, text, words):
    path = tmp_path / "s.toml"
    path.write_text(text)
    with pytest.raises(UserError) as exc:
        load_sensor_file(path)
    assert str(exc.value).startswith(f"sensor file {path}: ") and words in str(exc.value)


def test_binary_and_undecodable_sensor_files_are_one_line(tmp_path):
    binary = tmp_path / "bin.toml"
    binary.write_bytes(bytes(range(256)) * 4)
    with pytest.raises(UserError, match="is a binary file, not text"):
        load_sensor_file(binary)
    latin = tmp_path / "latin.json"
    latin.write_bytes('{"name": "caf\xe9"}'.encode("latin-1"))
    with pytest.raises(UserError, match=r"is not UTF-8 text \(byte 0xe9 at offset 13\)"):
        load_sensor_file(latin)


def test_saved_file_carries_its_base_and_loads_back(tmp_path):
    cfg = preset("tmf8828-8x8-short").replace(jitter_fwhm_ps=120.0, name="fitted")
    path = tmp_path / "fitted.toml"
    cfg.save(path, base="tmf8828-8x8-short")
    assert path.read_text().startswith('base = "tmf8828-8x8-short"')
    _assert_same(load_sensor_file(path), cfg)
