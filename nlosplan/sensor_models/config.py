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
from nlosplan.schema import QUANTITIES
from nlosplan.sensor_models.impulse import impulse_sigma_ps

FLASH_PROFILES = ("gaussian", "uniform")
#: Fields holding one value per zone (row-major); None means the neutral value for every zone.
ZONE_FIELDS = ("zone_time_offsets_ps", "zone_time_scales", "zone_gains", "zone_overlap_m")
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
        Apply flux-dependent detection: each of the zone's ``spads_per_zone``
        detectors records at most one photon per ``dead_time_ps`` (first-photon
        pile-up, Coates' model, when the dead time outlasts the window); ambient
        and dark counts in the window count toward it.
    saturation : bool
        Clip counts at the 24-bit register maximum.
    zone_time_offsets_ps : tuple of float, optional
        Per-zone time offset, ps, added to every arrival of the zone (its TDC
        delay), row-major, one per zone; None: all 0.
    zone_time_scales : tuple of float, optional
        Per-zone clock rate (> 0, row-major): the zone records light arriving
        ``t`` ps after emission at ``s_z * t + zone_time_offsets_ps[z]`` (its
        TDC's time scale relative to the sensor's bins); None: all 1.
    zone_gains : tuple of float, optional
        Per-zone relative gain (>= 0, row-major, one per zone) multiplying all
        light of the zone; None: all 1.
    zone_overlap_m : tuple of float, optional
        Per-zone near-field overlap distance ``d0``, metres (>= 0, row-major):
        light arriving at time ``t`` is weighted by ``r^2 / (r^2 + d0^2)`` with
        ``r = c t / 2`` (the range for a first bounce); None: no overlap loss.
    pulse_tail_fraction : float
        Share of the impulse response in an exponential tail that continues the
        measured pulse shape after its last sample, in [0, 1); needs a
        ``pulse_shape``. 0: no tail.
    pulse_tail_decay_ps : float
        E-folding time of that tail, ps (> 0).
    time_walk_ps : float
        Flux-dependent timing: a zone records its light earlier by this many ps
        per decade of its signal (photons per iteration, 1 = no shift), ps; 0: none.
    spads_per_zone : int
        Independent detectors sharing a zone's light equally (with ``pileup``), >= 1.
    dead_time_ps : float, optional
        Non-paralyzable dead time of each detector after a detection, ps (> 0);
        None: blind for the rest of the laser iteration (Coates' first-photon
        model). Used only with ``pileup``.
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
    zone_time_offsets_ps: tuple[float, ...] | None = None
    zone_time_scales: tuple[float, ...] | None = None
    zone_gains: tuple[float, ...] | None = None
    zone_overlap_m: tuple[float, ...] | None = None
    pulse_tail_fraction: float = 0.0
    pulse_tail_decay_ps: float = 1000.0
    time_walk_ps: float = 0.0
    spads_per_zone: int = 1
    dead_time_ps: float | None = None
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
            total = float(shape.sum()) if shape.max() < 1e300 else math.inf
            if total <= 0:
                raise UserError("pulse_shape must have a positive sum")
            if not math.isfinite(total):   # samples whose sum overflows: the shape is relative, scale it first
                shape = shape / shape.max()
                total = float(shape.sum())
            if abs(total - 1.0) > 1e-12:  # normalise once; re-normalising would drift in the last digit
                shape = shape / total
            object.__setattr__(self, "pulse_shape", tuple(float(v) for v in shape))
        for name in ZONE_FIELDS:
            value = getattr(self, name)
            if value is None:
                continue
            if isinstance(value, (str, bytes, dict)) or not isinstance(value, (list, tuple, np.ndarray)):
                raise UserError(f"{name} must be a list of numbers, one per zone (row-major), or left out")
            object.__setattr__(self, name, tuple(_finite_number(f"{name}[{i}]", v) for i, v in enumerate(value)))
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
    def impulse_sigma_ps(self) -> float:
        """Standard deviation of the Gaussian part of the impulse response, ps (:func:`.impulse.impulse_sigma_ps`).

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

        Changing the zone grid drops the per-zone values (they belong to one
        unit's layout) and removing ``pulse_shape`` drops its tail, unless the
        same call gives them.

        Raises
        ------
        UserError
            For unknown field names or invalid values.
        """
        check_keys(changes, sorted(f.name for f in dataclasses.fields(self)), "sensor parameter(s)")
        grid = (changes.get("zones_rows", self.zones_rows), changes.get("zones_cols", self.zones_cols))
        if grid != (self.zones_rows, self.zones_cols):
            # per-zone values belong to one unit's zone layout: another layout starts neutral
            for name in ZONE_FIELDS:
                changes.setdefault(name, None)
        if "pulse_shape" in changes and changes["pulse_shape"] is None:
            changes.setdefault("pulse_tail_fraction", 0.0)  # the tail continues the measured pulse: it goes with it
        return dataclasses.replace(self, **changes)

    def linear_uniform(self) -> "SensorConfig":
        """This sensor made linear and alike in every zone.

        No pile-up or dead time, no per-zone gains, offsets, time scales or
        overlap, no time walk and no pulse tail; everything else kept. The
        reference for physics checks that must not depend on one unit's
        calibration (inverse-square law, symmetry, linear parts).
        """
        return self.replace(pileup=False, spads_per_zone=1, dead_time_ps=None, time_walk_ps=0.0,
                            pulse_tail_fraction=0.0, **{name: None for name in ZONE_FIELDS})

    def to_dict(self) -> dict[str, Any]:
        """Plain-data dictionary (JSON/TOML friendly; ``pulse_shape`` as a list)."""
        out = dataclasses.asdict(self)
        for name in ("pulse_shape",) + ZONE_FIELDS:
            if out[name] is not None:
                out[name] = list(out[name])
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
        for name in ("pulse_shape",) + ZONE_FIELDS:
            if isinstance(data.get(name), list):
                data[name] = tuple(data[name])
        try:
            return cls(**data)
        except TypeError as exc:  # pragma: no cover - defensive
            raise UserError(f"invalid sensor configuration: {exc}") from None

    def to_json(self, base: str | None = None, fitted_to: list | None = None) -> str:
        """JSON text of :meth:`to_dict` (with ``base`` first when given: see
        :func:`~nlosplan.sensor_models.presets.load_sensor_file`; ``fitted_to``, a list of plain-data entries of
        :mod:`~nlosplan.sensor_models.fitted_to`, last when given)."""
        data = self.to_dict() if base is None else {"base": base, **self.to_dict()}
        if fitted_to is not None:
            data["fitted_to"] = fitted_to
        return json.dumps(data, indent=2)

    @classmethod
    def from_json(cls, text: str) -> "SensorConfig":
        """Parse JSON text written by :meth:`to_json` (every field; missing ones take the class defaults)."""
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise UserError(f"sensor JSON is not valid JSON: {exc.msg} at line {exc.lineno}") from None
        return cls.from_dict(data)

    def to_toml(self, base: str | None = None, fitted_to: list | None = None) -> str:
        """TOML text of :meth:`to_dict` (unset optional fields such as ``pulse_shape`` omitted; ``base`` first when
        given; ``fitted_to`` as ``[[fitted_to]]`` tables when given)."""
        import tomli_w

        data = {k: v for k, v in self.to_dict().items() if v is not None}
        if base is not None:
            data = {"base": base, **data}
        if fitted_to is not None:
            data["fitted_to"] = fitted_to
        return tomli_w.dumps(data)

    @classmethod
    def from_toml(cls, text: str) -> "SensorConfig":
        """Parse TOML text written by :meth:`to_toml` (every field; missing ones take the class defaults)."""
        try:
            data = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise UserError(f"sensor TOML is not valid TOML: {exc}") from None
        return cls.from_dict(data)

    def save(self, path: str | Path, base: str | None = None, fitted_to: list | None = None) -> None:
        """Write every field to ``.toml`` or ``.json`` (chosen by the suffix), atomically.

        Parameters
        ----------
        path : str or Path
        base : str, optional
            The preset this sensor refines, written as ``base`` so that fields
            added to the model later take the preset's values (see
            :func:`~nlosplan.sensor_models.presets.load_sensor_file`).
        fitted_to : list of dict, optional
            The real data the values were fitted to (:mod:`~nlosplan.sensor_models.fitted_to`), written with them.
        """
        from nlosplan.files import write_text

        path = Path(path)
        if path.suffix == ".toml":
            write_text(path, self.to_toml(base, fitted_to))
        elif path.suffix == ".json":
            write_text(path, self.to_json(base, fitted_to))
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


def _in_range(name: str, value: float, quantity: str | None = None) -> None:
    """``value`` of field ``name`` within its physical range (:data:`nlosplan.schema.QUANTITIES`)."""
    q = QUANTITIES[quantity or name]
    _check(q.contains(value), f"{name}={value:g} is out of range; allowed: {q.allowed()}")


def validate(cfg: SensorConfig) -> None:
    """Check every field of ``cfg``; raise :class:`UserError` naming the first bad one.

    Physical fields must also lie within the ranges of :data:`nlosplan.schema.QUANTITIES`, the ones the
    command line's flags are held to (e.g. ``bin_width_ps`` 1 ps to 1 us), so that no value makes the
    arithmetic overflow, underflow to zero or silently empty the histogram.
    """
    _check(isinstance(cfg.name, str) and cfg.name != "", f"name={cfg.name!r} must be a non-empty string")
    _integer("zones_rows", cfg.zones_rows, 1, MAX_ZONES_PER_AXIS)
    _integer("zones_cols", cfg.zones_cols, 1, MAX_ZONES_PER_AXIS)
    _integer("n_bins", cfg.n_bins, 1, MAX_BINS)
    _integer("iterations", cfg.iterations, 0, 10**12)
    bw = _finite_number("bin_width_ps", cfg.bin_width_ps)
    _check(bw > 0, f"bin_width_ps={bw} must be > 0 ps")
    _in_range("bin_width_ps", bw)
    _in_range("start_offset_ps", _finite_number("start_offset_ps", cfg.start_offset_ps))
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
        _in_range(name, v)
    step = _finite_number("pulse_shape_step_ps", cfg.pulse_shape_step_ps)
    _check(step > 0, f"pulse_shape_step_ps={step} must be > 0 ps")
    _in_range("pulse_shape_step_ps", step)
    _in_range("pulse_shape_t0_ps", _finite_number("pulse_shape_t0_ps", cfg.pulse_shape_t0_ps))
    if cfg.pulse_shape is not None:
        _check(len(cfg.pulse_shape) <= 512, "pulse_shape may have at most 512 samples")
    _check(isinstance(cfg.pileup, bool), f"pileup={cfg.pileup!r} must be true or false")
    _check(isinstance(cfg.saturation, bool), f"saturation={cfg.saturation!r} must be true or false")
    for name in ZONE_FIELDS:
        value = getattr(cfg, name)
        if value is None:
            continue
        _check(len(value) == cfg.n_zones, f"{name} has {len(value)} values but the sensor has {cfg.n_zones} zones "
                                          f"({cfg.zones_rows}x{cfg.zones_cols}); give one per zone, row-major")
        if name == "zone_time_scales":
            bad = [v for v in value if not 0.5 <= v <= 2.0]
            if bad:
                raise UserError(f"zone_time_scales must be between 0.5 and 2; got {bad[0]}")
        elif name != "zone_time_offsets_ps":
            bad = [v for v in value if v < 0]
            if bad:
                raise UserError(f"{name} must be >= 0; got {bad[0]}")
        if name != "zone_time_scales":
            for i, v in enumerate(value):
                _in_range(f"{name}[{i}]", v, name)
    frac = _finite_number("pulse_tail_fraction", cfg.pulse_tail_fraction)
    _check(0 <= frac < 1, f"pulse_tail_fraction={frac} is out of range; allowed: 0 <= fraction < 1")
    decay = _finite_number("pulse_tail_decay_ps", cfg.pulse_tail_decay_ps)
    _check(decay > 0, f"pulse_tail_decay_ps={decay} must be > 0 ps")
    _in_range("pulse_tail_decay_ps", decay)
    _check(frac == 0 or cfg.pulse_shape is not None,
           "pulse_tail_fraction > 0 needs a pulse_shape (the tail continues the measured pulse after its last sample)")
    walk = _finite_number("time_walk_ps", cfg.time_walk_ps)
    _check(abs(walk) <= 1000, f"time_walk_ps={walk} is out of range; allowed: -1000 to 1000 ps per decade")
    _integer("spads_per_zone", cfg.spads_per_zone, 1, 10**6)
    if cfg.dead_time_ps is not None:
        dead = _finite_number("dead_time_ps", cfg.dead_time_ps)
        _check(dead > 0, f"dead_time_ps={dead} must be > 0 ps, or left out (blind for the rest of the iteration)")
        _in_range("dead_time_ps", dead)
