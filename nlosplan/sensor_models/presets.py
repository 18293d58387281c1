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
- DRV: the DENALI / cc-hardware driver constant for long range (260 ps bins).
- ST: ST UM3183 and the cc-hardware VL53L8CH driver (compact normalised
  histograms: bins of ~37.5 mm = 250 ps, up to 32 bins, pulse ~10 bins wide).

Where a value has no source it is marked "assumed" in the preset's notes.
"""

from __future__ import annotations

from nlosplan.errors import UserError
from nlosplan.sensor_models.config import SensorConfig

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


def _builders() -> dict:
    return {
        "tmf8828-3x3-short": lambda: _tmf8828_short(3, 3, (33.0, 32.0), 550_000, "tmf8828-3x3-short"),
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


def uncertainty(name: str) -> dict | None:
    """The parameter uncertainty a preset ships (the ``X.uncertainty.json`` format of
    :mod:`nlosplan.sensor_models.uncertainty`), or None.

    No preset ships one today: their measured values carry line-fit errors
    only (:data:`MEASURED`), not a calibration's joint uncertainty. The design
    planner's worlds then draw only from their declared ranges.

    Raises
    ------
    UserError
        For an unknown preset name.
    """
    if name not in _builders():
        raise UserError(f"unknown sensor preset {name!r}; allowed: {', '.join(_builders())}")
    return None


def resolve_sensor(spec) -> SensorConfig:
    """A preset name or a path to a ``.toml``/``.json`` sensor file (a :class:`SensorConfig` is returned as it is)."""
    if isinstance(spec, SensorConfig):
        return spec
    spec = str(spec)
    if spec.endswith((".toml", ".json")):
        return SensorConfig.load(spec)
    return preset(spec)
