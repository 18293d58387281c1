"""`SensorConfig`: the frozen, validated description of a flash dToF sensor.

Every parameter a design study may vary lives here, in explicit units:
picoseconds for time, degrees for angles, hertz for rates. The time axis is

    bin ``j`` covers ``[start_offset_ps + j * bin_width_ps,
                        start_offset_ps + (j + 1) * bin_width_ps)``

where time 0 is the laser emission seen at zero optical path (round trip).
A negative ``start_offset_ps`` means a zero-distance return lands after bin 0,
as on the TMF882x (about bin 13).
"""

from __future__ import annotations

import dataclasses
import json
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from nlosplan.constants import MAX_COUNT_24BIT
from nlosplan.errors import UserError, check_keys
from nlosplan.sensor_models.impulse import impulse_sigma_ps

FLASH_PROFILES = ("gaussian", "uniform")
MAX_ZONES_PER_AXIS = 16
MAX_BINS = 4096


@dataclass(frozen=True)
class SensorConfig:
    """A flash direct-time-of-flight sensor (TMF8828 class).

    Parameters
    ----------
    name : str
        Label used in reports.
    zones_rows, zones_cols : int
        Zone grid, 1 to 16 per axis.
    n_bins : int
        Number of histogram bins, 1 to 4096.
    bin_width_ps : float
        Width of one bin, picoseconds (> 0).
    start_offset_ps : float
        Time of the left edge of bin 0, picoseconds, relative to emission at
        zero optical path.
    fov_x_deg, fov_y_deg : float
        Full field of view of the zone grid per axis, degrees (0, 170).
    flash_profile : {"gaussian", "uniform"}
        Angular emission profile of the flash illuminator.
    flash_fwhm_x_deg, flash_fwhm_y_deg : float
        FWHM of the Gaussian flash profile per axis, degrees (ignored for
        "uniform", which lights exactly the field of view).
    sensitivity_cos_power : float
        Zone sensitivity falls as ``cos(theta)**p`` off axis (0: flat).
    pulse_fwhm_ps : float
        FWHM of the Gaussian laser pulse, ps (>= 0; 0 is an ideal impulse).
    pulse_shape : tuple of float, optional
        Measured pulse as non-negative samples of a piecewise-constant shape
        (normalised to unit area on construction). When given, the impulse
        response is ``pulse_shape (*) Gaussian(pulse_fwhm_ps (+) jitter)``.
    pulse_shape_step_ps : float
        Width of one ``pulse_shape`` sample, ps.
    pulse_shape_t0_ps : float
        Time of the left edge of the first ``pulse_shape`` sample relative to
        the nominal arrival time, ps.
    jitter_fwhm_ps : float
        FWHM of the Gaussian timing jitter, ps (>= 0).
    photon_scale : float
        Detected photons per iteration per unit of transport response (>= 0).
    iterations : int
        Laser pulses accumulated into one histogram (exposure, >= 0).
    ambient_rate_hz : float
        Detected ambient photons per second per zone with lights on (>= 0).
    dark_rate_hz : float
        Dark-count rate per zone, per second (>= 0).
    crosstalk : float
        Expected crosstalk (cover-glass) photons per iteration per zone at
        zero optical path (>= 0).
    pileup : bool
        Apply first-photon pile-up (Coates model).
    saturation : bool
        Clip counts at the 24-bit register maximum.
    notes : str
        Provenance: where the values come from.
    """

    name: str = "custom"
    zones_rows: int = 3
    zones_cols: int = 3
    n_bins: int = 128
    bin_width_ps: float = 100.0
    start_offset_ps: float = 0.0
    fov_x_deg: float = 33.0
    fov_y_deg: float = 32.0
    flash_profile: str = "gaussian"
    flash_fwhm_x_deg: float = 30.0
    flash_fwhm_y_deg: float = 32.0
    sensitivity_cos_power: float = 0.0
    pulse_fwhm_ps: float = 0.0
    pulse_shape: tuple[float, ...] | None = None
    pulse_shape_step_ps: float = 100.0
    pulse_shape_t0_ps: float = 0.0
    jitter_fwhm_ps: float = 0.0
    photon_scale: float = 1.0
    iterations: int = 550_000
    ambient_rate_hz: float = 0.0
    dark_rate_hz: float = 0.0
    crosstalk: float = 0.0
    pileup: bool = False
    saturation: bool = True
    notes: str = field(default="", compare=False)

    def __post_init__(self) -> None:
        # numpy scalars validate like Python numbers; store them as Python numbers so that
        # JSON/TOML writers accept them
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if isinstance(value, np.generic):
                object.__setattr__(self, f.name, value.item())
        if self.pulse_shape is not None:
            bad = "pulse_shape must be a non-empty list of finite, non-negative samples"
            if not isinstance(self.pulse_shape, (list, tuple, np.ndarray)):
                raise UserError(bad)
            try:
                shape = np.asarray(self.pulse_shape, dtype=float).ravel()
            except (TypeError, ValueError):
                raise UserError(bad) from None
            if shape.size == 0 or not np.all(np.isfinite(shape)) or np.any(shape < 0):
                raise UserError(bad)
            total = float(shape.sum())
            if total <= 0:
                raise UserError("pulse_shape must have a positive sum")
            if abs(total - 1.0) > 1e-12:  # normalise once; re-normalising would drift in the last digit
                shape = shape / total
            object.__setattr__(self, "pulse_shape", tuple(float(v) for v in shape))
        validate(self)

    # ------------------------------------------------------------------ derived
    @property
    def n_zones(self) -> int:
        """Number of zones, ``zones_rows * zones_cols``."""
        return self.zones_rows * self.zones_cols

    @property
    def window_ps(self) -> float:
        """Length of the time window, ``n_bins * bin_width_ps`` (ps)."""
        return self.n_bins * self.bin_width_ps

    @property
    def sigma_ps(self) -> float:
        """Standard deviation of the Gaussian part of the impulse response, ps.

        ``sqrt(sigma_pulse**2 + sigma_jitter**2)`` with sigma = FWHM / 2.3548.
        """
        return impulse_sigma_ps(self.pulse_fwhm_ps, self.jitter_fwhm_ps)

    @property
    def max_count(self) -> int:
        """Largest count one bin can hold (24-bit register)."""
        return MAX_COUNT_24BIT

    def bin_edges_ps(self) -> np.ndarray:
        """Bin edges, shape ``(n_bins + 1,)``, picoseconds (float64)."""
        return self.start_offset_ps + self.bin_width_ps * np.arange(self.n_bins + 1, dtype=np.float64)

    # ------------------------------------------------------------- round trips
    def replace(self, **changes: Any) -> "SensorConfig":
        """Return a copy with some fields changed (validated again).

        Raises
        ------
        UserError
            For unknown field names or invalid values.
        """
        check_keys(changes, sorted(f.name for f in dataclasses.fields(self)), "sensor parameter(s)")
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        """Plain-data dictionary (JSON/TOML friendly; ``pulse_shape`` as a list)."""
        out = dataclasses.asdict(self)
        if out["pulse_shape"] is not None:
            out["pulse_shape"] = list(out["pulse_shape"])
        return out

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> "SensorConfig":
        """Build from a dictionary as written by :meth:`to_dict`.

        Raises
        ------
        UserError
            For unknown keys or invalid values.
        """
        if not isinstance(data, dict):
            raise UserError("a sensor configuration must be a table/object of parameters")
        check_keys(data, sorted(f.name for f in dataclasses.fields(cls)), "sensor parameter(s)")
        data = dict(data)
        if isinstance(data.get("pulse_shape"), list):
            data["pulse_shape"] = tuple(data["pulse_shape"])
        try:
            return cls(**data)
        except TypeError as exc:  # pragma: no cover - defensive
            raise UserError(f"invalid sensor configuration: {exc}") from None

    def to_json(self, base: str | None = None) -> str:
        """JSON text of :meth:`to_dict` (with ``base`` first when given: see :meth:`load`)."""
        data = self.to_dict() if base is None else {"base": base, **self.to_dict()}
        return json.dumps(data, indent=2)

    @classmethod
    def from_json(cls, text: str) -> "SensorConfig":
        """Parse JSON text written by :meth:`to_json` (every field; missing ones take the class defaults)."""
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise UserError(f"sensor JSON is not valid JSON: {exc.msg} at line {exc.lineno}") from None
        return cls.from_dict(data)

    def to_toml(self, base: str | None = None) -> str:
        """TOML text of :meth:`to_dict` (``pulse_shape`` omitted when unset; ``base`` first when given)."""
        import tomli_w

        data = {k: v for k, v in self.to_dict().items() if v is not None}
        if base is not None:
            data = {"base": base, **data}
        return tomli_w.dumps(data)

    @classmethod
    def from_toml(cls, text: str) -> "SensorConfig":
        """Parse TOML text written by :meth:`to_toml` (every field; missing ones take the class defaults)."""
        try:
            data = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise UserError(f"sensor TOML is not valid TOML: {exc}") from None
        return cls.from_dict(data)

    def save(self, path: str | Path, base: str | None = None) -> None:
        """Write every field to ``.toml`` or ``.json`` (chosen by the suffix), atomically.

        Parameters
        ----------
        path : str or Path
        base : str, optional
            The preset this sensor refines, written as ``base`` so that fields
            added to the model later take the preset's values (see :meth:`load`).
        """
        from nlosplan.files import write_text

        path = Path(path)
        if path.suffix == ".toml":
            write_text(path, self.to_toml(base))
        elif path.suffix == ".json":
            write_text(path, self.to_json(base))
        else:
            raise UserError(f"sensor file {path} must end in .toml or .json")


def _check(cond: bool, message: str) -> None:
    if not cond:
        raise UserError(message)


def _finite_number(name: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise UserError(f"{name}={value!r} must be a number")
    value = float(value)
    _check(math.isfinite(value), f"{name}={value} must be finite")
    return value


def _integer(name: str, value: Any, lo: int, hi: int) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise UserError(f"{name}={value!r} must be an integer between {lo} and {hi}")
    _check(lo <= int(value) <= hi, f"{name}={value} is out of range; allowed: {lo} to {hi}")


def validate(cfg: SensorConfig) -> None:
    """Check every field of ``cfg``; raise :class:`UserError` naming the first bad one."""
    _check(isinstance(cfg.name, str) and cfg.name != "", f"name={cfg.name!r} must be a non-empty string")
    _integer("zones_rows", cfg.zones_rows, 1, MAX_ZONES_PER_AXIS)
    _integer("zones_cols", cfg.zones_cols, 1, MAX_ZONES_PER_AXIS)
    _integer("n_bins", cfg.n_bins, 1, MAX_BINS)
    _integer("iterations", cfg.iterations, 0, 10**12)
    bw = _finite_number("bin_width_ps", cfg.bin_width_ps)
    _check(bw > 0, f"bin_width_ps={bw} must be > 0 ps")
    _finite_number("start_offset_ps", cfg.start_offset_ps)
    for name in ("fov_x_deg", "fov_y_deg"):
        v = _finite_number(name, getattr(cfg, name))
        _check(0 < v < 170, f"{name}={v} is out of range; allowed: 0 < fov < 170 degrees")
    _check(
        cfg.flash_profile in FLASH_PROFILES,
        f"flash_profile={cfg.flash_profile!r} is unknown; allowed: {', '.join(FLASH_PROFILES)}",
    )
    for name in ("flash_fwhm_x_deg", "flash_fwhm_y_deg"):
        v = _finite_number(name, getattr(cfg, name))
        _check(0 < v <= 360, f"{name}={v} is out of range; allowed: 0 < fwhm <= 360 degrees")
    for name in (
        "sensitivity_cos_power",
        "pulse_fwhm_ps",
        "jitter_fwhm_ps",
        "photon_scale",
        "ambient_rate_hz",
        "dark_rate_hz",
        "crosstalk",
    ):
        v = _finite_number(name, getattr(cfg, name))
        _check(v >= 0, f"{name}={v} must be >= 0")
    step = _finite_number("pulse_shape_step_ps", cfg.pulse_shape_step_ps)
    _check(step > 0, f"pulse_shape_step_ps={step} must be > 0 ps")
    _finite_number("pulse_shape_t0_ps", cfg.pulse_shape_t0_ps)
    if cfg.pulse_shape is not None:
        _check(len(cfg.pulse_shape) <= 512, "pulse_shape may have at most 512 samples")
    _check(isinstance(cfg.pileup, bool), f"pileup={cfg.pileup!r} must be true or false")
    _check(isinstance(cfg.saturation, bool), f"saturation={cfg.saturation!r} must be true or false")
