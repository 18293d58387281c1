"""Sensor presets with their sources.

Sources
-------
- DS: ams TMF8828 datasheet DS000693 v8-00 (2023-08-02): zones, 128 bins of
  24-bit counts, FoV (3x3 SPAD map 33 x 32 deg; 4x4/8x8 maps 41 x 52 deg),
  illuminator 30 x 32 deg FWHM, iterations (3x3: 550k; 8x8: 125k).
- MEAS: measured by nlosplan from real TMF882x 3x3 short-range histograms of a
  plane at 80 known distances (``../shared/data/tmf882x_distance``; method in
  :mod:`nlosplan.calibration.tmf882x_fit`): bin width, time offset, pulse
  shape, photon scale, ambient and dark rates. Figures in :data:`MEASURED`.
- UNIT: the same captures fitted with every zone by the all-zone plane model
  (``nlosplan calibrate``, :mod:`nlosplan.calibration.plane_fit`):
  per-zone time offsets, time scales, gains and near-field overlap, first-photon
  pile-up at the captures' iterations, time walk, pulse with its tail. Values of
  that one unit (:data:`PLANE_UNIT`), in the preset ``tmf8828-3x3-plane-unit``
  only (another TMF8828, DENALI's among them, has its own).
- DRV: the DENALI / cc-hardware driver constant for long range (260 ps bins).
- ST: ST UM3183 and the cc-hardware VL53L8CH driver (compact normalised
  histograms: bins of ~37.5 mm = 250 ps, up to 32 bins, pulse ~10 bins wide).

Where a value has no source it is marked "assumed" in the preset's notes.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from nlosplan.errors import UserError, check_keys
from nlosplan.schema import load_table, shown
from nlosplan.sensor_models.config import ZONE_FIELDS, SensorConfig

#: Values measured from ../shared/data/tmf882x_distance (TMF882x, 3x3, short
#: range). Regenerate with ``nlosplan sensor fit-timebase PATH``.
MEASURED: dict = {
    "bin_width_ps": 92.816,
    "bin_width_se_ps": 0.164,  # line-fit s.e.; curvature of edge vs distance adds ~ +-2 ps systematic
    "start_offset_ps": -1117.17,
    "pulse_shape": [0.000109, 0.0, 0.042784, 0.357911, 0.298036, 0.143762, 0.054704, 0.02763, 0.018867, 0.01379, 0.010314, 0.00767, 0.00579, 0.004357, 0.003276, 0.002475, 0.001873, 0.001441, 0.001086, 0.000855, 0.000662, 0.00052, 0.000413, 0.000329, 0.000279, 0.000226, 0.000189, 0.000161, 0.000138, 0.000129, 0.0001, 0.000126],
    "pulse_shape_t0_ps": -266.79,
    "pulse_core_fwhm_ps": 187.0,
    "residual_rms_bins": 0.1037,
    "n_captures": 69,
    "holdout_peak_bin_error_mean": 0.0571,
    "holdout_l1_mean": 0.0679,
    # photons per iteration per unit transport weight: measured centre-zone signal / wall-model
    # weight (albedo 1) at 0.25-0.40 m, where the bistatic near field no longer matters, / 550k iterations
    "photon_scale": 2.35,
    # floor of the histograms: ~160 counts/bin at 0.4 m (room light) and ~1.1 at 5 mm (plane blocks it)
    "ambient_rate_hz": 3.2e6,
    "dark_rate_hz": 2.2e4,
}


PLANE_UNIT: dict = {
    "bin_width_ps": 99.164,
    "start_offset_ps": -1194.09,
    "pulse_shape": [7e-06, 0.0, 0.019716, 0.311279, 0.312131, 0.165607, 0.067763, 0.032958, 0.022508, 0.016661, 0.012621, 0.009473, 0.007129, 0.005342, 0.004023, 0.003034, 0.002286, 0.001729, 0.001325, 0.001018, 0.00079, 0.00061, 0.000475, 0.000367, 0.000285, 0.000226, 0.000175, 0.000139, 0.000106, 8.7e-05, 7.3e-05, 5.7e-05],
    "pulse_shape_t0_ps": -280.59,
    "pulse_tail_fraction": 0.000501,
    "pulse_tail_decay_ps": 1260.6,
    "photon_scale": 0.3139,
    "iterations": 4218414,
    "time_walk_ps": 92.6,
    "zone_time_offsets_ps": (-37.6, -55.7, -56.6, 0.6, 2.8, 39.2, 1.9, 55.5, 49.7),
    "zone_time_scales": (0.9815, 0.9941, 0.9872, 1.0138, 1.0163, 0.9895, 0.9829, 1.0223, 1.0135),
    "zone_gains": (0.668, 0.757, 1.148, 0.819, 1.095, 1.695, 0.793, 0.961, 1.486),
    "zone_overlap_m": (0.0378, 0.062, 0.0623, 0.0583, 0.0934, 0.083, 0.0429, 0.0712, 0.0712),
}
#: How PLANE_UNIT was made and how well it predicts captures it did not see (docs/sensor-physics.md).
PLANE_UNIT_NOTES = (
    "UNIT: this 3x3 preset is the one TMF882x unit of ../shared/data/tmf882x_distance (80 captures of a plane, "
    "the 69 at 6-40 cm fitted with 'nlosplan calibrate' all-zone model: per-zone time offsets, time scales, gains "
    "and near-field overlap, first-photon pile-up at the captures' {iterations} iterations (the firmware's 4000 "
    "kilo-iterations), time walk {walk} ps per decade of zone light, 32-sample pulse with an exponential tail). "
    "{scores} The per-zone values are this unit's (and this mount's): another TMF8828 has its own, never take "
    "them as facts for it; the 4x4, 8x8 and long-range presets do not carry them."
)
#: Held-out figures of the all-zone model on the plane captures (filled from 'nlosplan bench real').
PLANE_UNIT_SCORES = (
    "Held out by distance (5 folds, 'nlosplan bench real'), all 9 zones at 6-40 cm: sub-bin peak error 0.037 bin "
    "mean, L1 of the shape 4.0 % mean / 10.5 % max, amplitude predicted/measured 0.97-1.12; fitted on these "
    "captures and scored on the other public half (not shipped): 0.036 bin, 4.0 % / 10.1 %, 0.97-1.09. Jackknife "
    "errors: bin width +-0.32 ps, offsets +-1-3 ps, time scales +-0.1-0.2 %, gains +-0.1-0.7 %, overlap +-0.5-1.8 mm, "
    "iterations +-1.3 %."
)


def _tmf8828_short(rows: int, cols: int, fov: tuple[float, float], iterations: int, name: str) -> SensorConfig:
    m = MEASURED
    pulse = m["pulse_shape"]
    return SensorConfig(
        name=name,
        zones_rows=rows,
        zones_cols=cols,
        n_bins=128,
        bin_width_ps=m["bin_width_ps"],
        start_offset_ps=m["start_offset_ps"],
        fov_x_deg=fov[0],
        fov_y_deg=fov[1],
        flash_profile="gaussian",
        flash_fwhm_x_deg=30.0,
        flash_fwhm_y_deg=32.0,
        pulse_fwhm_ps=0.0 if pulse is not None else m["pulse_core_fwhm_ps"],
        pulse_shape=tuple(pulse) if pulse is not None else None,
        pulse_shape_step_ps=m["bin_width_ps"],
        pulse_shape_t0_ps=m["pulse_shape_t0_ps"],
        jitter_fwhm_ps=0.0,
        photon_scale=m["photon_scale"],
        iterations=iterations,
        ambient_rate_hz=m["ambient_rate_hz"],
        dark_rate_hz=m["dark_rate_hz"],
        crosstalk=0.0,
        pileup=False,
        saturation=True,
        notes=(
            f"TMF8828 {rows}x{cols} short range. Zones, 128 bins, 24-bit, FoV {fov[0]}x{fov[1]} deg, "
            f"flash 30x32 deg FWHM, {iterations} iterations: DS. Bin width, offset, pulse shape, "
            "photon scale, ambient and dark rates: MEAS on TMF882x 3x3 data. Jitter beyond the "
            "measured pulse: 0. Crosstalk in zone channels: not visible in MEAS data, 0."
        ),
    )


def _tmf8828_3x3_long() -> SensorConfig:
    base = _tmf8828_short(3, 3, (33.0, 32.0), 550_000, "tmf8828-3x3-long")
    zero_bin = -base.start_offset_ps / base.bin_width_ps
    return base.replace(
        bin_width_ps=260.0,
        start_offset_ps=-zero_bin * 260.0,
        notes=(
            "TMF8828 3x3 long range. 260 ps bins: DRV (not measured; no long-range data). "
            "Zero-distance bin, pulse shape, photon scale: assumed equal to the short-range MEAS "
            "values. Zones, FoV, flash, iterations: DS."
        ),
    )


def _vl53l8ch() -> SensorConfig:
    return SensorConfig(
        name="vl53l8ch-8x8",
        zones_rows=8,
        zones_cols=8,
        n_bins=32,
        bin_width_ps=250.0,
        start_offset_ps=0.0,
        fov_x_deg=45.0,
        fov_y_deg=45.0,
        flash_profile="uniform",
        flash_fwhm_x_deg=45.0,
        flash_fwhm_y_deg=45.0,
        pulse_fwhm_ps=1470.0,
        jitter_fwhm_ps=0.0,
        photon_scale=MEASURED["photon_scale"],
        iterations=100_000,
        ambient_rate_hz=MEASURED["ambient_rate_hz"],
        dark_rate_hz=MEASURED["dark_rate_hz"],
        saturation=True,
        notes=(
            "ST VL53L8CH 8x8 compact normalised histograms. 8x8 zones, 45x45 deg FoV, 32 bins of "
            "~250 ps (37.5 mm): ST. Pulse ~10 bins wide (ST): modelled as a Gaussian whose +-2 sigma "
            "span is 10 bins (FWHM 1470 ps), assumed. Uniform flash over the FoV, iterations, photon "
            "scale and rates: assumed (TMF882x MEAS values)."
        ),
    )


def _plane_unit_3x3() -> SensorConfig:
    """The plane captures' unit: the 3x3 short-range preset with that unit's fitted values (UNIT)."""
    u = PLANE_UNIT
    base = _tmf8828_short(3, 3, (33.0, 32.0), u["iterations"], "tmf8828-3x3-plane-unit")
    notes = PLANE_UNIT_NOTES.format(iterations=f"{u['iterations'] / 1e6:.2f}M", walk=f"{u['time_walk_ps']:g}",
                                    scores=PLANE_UNIT_SCORES)
    return base.replace(
        bin_width_ps=u["bin_width_ps"], start_offset_ps=u["start_offset_ps"], pulse_shape=tuple(u["pulse_shape"]),
        pulse_shape_step_ps=u["bin_width_ps"], pulse_shape_t0_ps=u["pulse_shape_t0_ps"], pulse_fwhm_ps=0.0,
        pulse_tail_fraction=u["pulse_tail_fraction"], pulse_tail_decay_ps=u["pulse_tail_decay_ps"],
        photon_scale=u["photon_scale"], ambient_rate_hz=MEASURED["ambient_rate_hz"] * 550_000 / u["iterations"],
        dark_rate_hz=MEASURED["dark_rate_hz"] * 550_000 / u["iterations"], pileup=True,
        time_walk_ps=u["time_walk_ps"], zone_time_offsets_ps=u["zone_time_offsets_ps"],
        zone_time_scales=u["zone_time_scales"], zone_gains=u["zone_gains"], zone_overlap_m=u["zone_overlap_m"],
        notes=(f"TMF8828 3x3 short range. Zones, 128 bins, 24-bit, FoV 33x32 deg, flash 30x32 deg FWHM: DS "
               f"(550k iterations in the DS's default; this unit's captures used {u['iterations']}). "
               + notes + " Ambient and dark rates: MEAS counts per bin at this unit's iterations."))


def _denali(zones: str) -> SensorConfig:
    """DENALI's unit (:mod:`.presets_denali`): facts of its capture settings plus the Table-2 fit."""
    from nlosplan.sensor_models import presets_denali as d

    rows = int(zones[0])
    it = d.DENALI_ITERATIONS[zones]
    name = f"denali-tmf8828-{zones}"
    base = _tmf8828_short(rows, rows, d.DENALI_FOV_DEG, it, name)
    return base.replace(pulse_tail_fraction=PLANE_UNIT["pulse_tail_fraction"],
                        pulse_tail_decay_ps=PLANE_UNIT["pulse_tail_decay_ps"], **d.DENALI_FIT,
                        notes=d.DENALI_PROVENANCE.format(iterations=f"{it:,}", scores=d.DENALI_SCORES))


def _builders() -> dict:
    return {
        "tmf8828-3x3-short": lambda: _tmf8828_short(3, 3, (33.0, 32.0), 550_000, "tmf8828-3x3-short"),
        "tmf8828-3x3-plane-unit": _plane_unit_3x3,
        "denali-tmf8828-3x3": lambda: _denali("3x3"),
        "denali-tmf8828-8x8": lambda: _denali("8x8"),
        "tmf8828-4x4-short": lambda: _tmf8828_short(4, 4, (41.0, 52.0), 550_000, "tmf8828-4x4-short"),
        "tmf8828-8x8-short": lambda: _tmf8828_short(8, 8, (41.0, 52.0), 125_000, "tmf8828-8x8-short"),
        "tmf8828-3x3-long": _tmf8828_3x3_long,
        "vl53l8ch-8x8": _vl53l8ch,
    }


PRESET_NAMES: tuple[str, ...] = tuple(_builders())


def preset(name: str) -> SensorConfig:
    """Return the named sensor preset.

    Parameters
    ----------
    name : str
        One of :data:`PRESET_NAMES`.

    Raises
    ------
    UserError
        For an unknown name (the message lists the known ones).

    Examples
    --------
    >>> preset("tmf8828-3x3-short").replace(jitter_fwhm_ps=100.0).n_bins
    128
    """
    builders = _builders()
    if name not in builders:
        raise UserError(f"unknown sensor preset {name!r}; allowed: {', '.join(builders)}")
    return builders[name]()


#: Fields a complete sensor file may leave out: the labels, and the optional terms whose unset value (None) means
#: "not modelled" (a measured pulse shape, per-zone terms, dead time), never a generic number.
OPTIONAL_FILE_FIELDS = ("name", "notes") + tuple(f.name for f in dataclasses.fields(SensorConfig) if f.default is None)


def load_sensor_file(path) -> SensorConfig:
    """Read a ``.toml`` or ``.json`` sensor file: its ``base`` preset with the fields it gives, or every field.

    A file either names the preset it refines (``base = "tmf8828-3x3-short"``;
    the fields it gives replace the preset's, so fields added to the model
    later take the preset's values) or gives every field but
    :data:`OPTIONAL_FILE_FIELDS`. Nothing is filled in silently: an empty or
    partial file without ``base``, an unknown or missing field and a wrong
    type are errors naming the file and the field. A ``fitted_to`` record
    (the real data its values were fitted to, :mod:`.fitted_to`) is checked
    here and read by :func:`~.preset_sources.sensor_record`; the sensor does not
    carry it.

    Raises
    ------
    UserError
        The file cannot be read as text or does not parse, or its
        configuration is incomplete or invalid (one line).
    """
    path = Path(path)
    data = load_table(path, "sensor file")
    try:
        return _from_table(data, path)
    except UserError as exc:
        raise UserError(f"sensor file {path}: {exc}") from None


def _from_table(data: dict, path: Path) -> SensorConfig:
    from nlosplan.sensor_models.fitted_to import parse_record

    fields = sorted(f.name for f in dataclasses.fields(SensorConfig))
    data = dict(data)
    base = data.pop("base", None)
    if "fitted_to" in data:  # the record of real sources (:mod:`.fitted_to`): checked here, read by sensor_record
        parse_record(data.pop("fitted_to"))
    check_keys(data, ["base", "fitted_to", *fields], "field(s)")
    for name in ("pulse_shape",) + ZONE_FIELDS:
        if isinstance(data.get(name), list):
            data[name] = tuple(data[name])
    if base is not None:
        if not isinstance(base, str) or base not in PRESET_NAMES:
            raise UserError(f"base = {shown(base)} is not a sensor preset; allowed: {', '.join(PRESET_NAMES)}")
        data.setdefault("name", f"{path.stem} ({base})")
        return preset(base).replace(**data)
    missing = [f for f in fields if f not in data and f not in OPTIONAL_FILE_FIELDS]
    if missing:
        what = "is empty" if not data else f"misses {', '.join(missing)}"
        raise UserError(f"the file {what}; name the preset it refines (e.g. base = \"{PRESET_NAMES[0]}\"; "
                        f"presets: {', '.join(PRESET_NAMES)}) or give every field")
    data.setdefault("name", path.stem)
    return SensorConfig(**data)


def sensor_base(spec) -> str | None:
    """The preset a sensor spec refines: the preset's own name, a sensor file's ``base``, else None."""
    if isinstance(spec, SensorConfig):
        return spec.name if spec.name in PRESET_NAMES and spec == preset(spec.name) else None
    spec = str(spec)
    if spec.endswith((".toml", ".json")):
        base = load_table(spec, "sensor file").get("base")
        return base if isinstance(base, str) and base in PRESET_NAMES else None
    return spec if spec in PRESET_NAMES else None


def preset_uncertainty(name: str) -> dict | None:
    """The parameter uncertainty a preset ships (the ``X.uncertainty.json`` format of
    :mod:`nlosplan.sensor_models.uncertainty`, package data ``data/<name>.uncertainty.json``), or None.

    ``denali-tmf8828-3x3`` ships one (``nlosplan calibrate --stats denali-table2 --bootstrap 40 --variants``:
    photon scale and floor). The other presets' measured values carry line-fit errors only
    (:data:`MEASURED`), not a calibration's joint uncertainty; the design planner's worlds then draw only
    from their declared ranges.

    Raises
    ------
    UserError
        For an unknown preset name.
    """
    import json
    from importlib import resources

    if name not in PRESET_NAMES:
        raise UserError(f"unknown sensor preset {name!r}; allowed: {', '.join(PRESET_NAMES)}")
    f = resources.files("nlosplan.sensor_models") / "data" / f"{name}.uncertainty.json"
    return json.loads(f.read_text()) if f.is_file() else None


def resolve_sensor(spec) -> SensorConfig:
    """A preset name or a path to a ``.toml``/``.json`` sensor file (a :class:`SensorConfig` is returned as it is)."""
    if isinstance(spec, SensorConfig):
        return spec
    spec = str(spec)
    if spec.endswith((".toml", ".json")):
        return load_sensor_file(spec)
    if spec not in PRESET_NAMES and Path(spec).exists():
        raise UserError(f"sensor file {spec} must end in .toml or .json (or give a preset: {', '.join(PRESET_NAMES)})")
    return preset(spec)
