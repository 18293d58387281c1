"""The design space: which sensor parameters the planner varies, and within which bounds.

A :class:`Design` is one point: zones, bin width (a whole multiple of the
reference sensor's), number of bins, timing jitter, Gaussian pulse width and
photon budget (a fraction of the reference's photons per capture, i.e.
exposure x efficiency). :meth:`Design.sensor` turns it into a
:class:`~nlosplan.sensor_models.SensorConfig` built on the reference sensor,
so every other command can use a design.

Defaults are DENALI's TMF8828 as calibrated on the real Table 2
(``denali-tmf8828-3x3``: 3x3 zones, 128 bins of 92.8 ps, the measured pulse,
10.24 M iterations, the real floor of ~10^3 counts per bin): zones 1x1 to
8x8, bins merged up to 8x, 32 to 128 bins, jitter 0 to 1000 ps, pulse 0 to
1000 ps, 1 % to 100 % of the photons.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, replace

from nlosplan.errors import UserError, check_keys
from nlosplan.sensor_models import SensorConfig, resolve_sensor
from nlosplan.simulators.presets.scene_model import DEFAULT_SENSOR

__all__ = ["AXES", "Design", "DesignSpace", "layout_name", "parse_zones"]

#: The design parameters, in report order, with their units and which direction is cheaper.
AXES: dict[str, dict] = {
    "zones": {"label": "zones", "unit": "", "cheaper": "fewer"},
    "bin_factor": {"label": "bin width", "unit": "ps", "cheaper": "wider"},
    "n_bins": {"label": "bins", "unit": "", "cheaper": "fewer"},
    "jitter_fwhm_ps": {"label": "jitter FWHM", "unit": "ps", "cheaper": "more"},
    "pulse_fwhm_ps": {"label": "pulse FWHM", "unit": "ps", "cheaper": "more"},
    "photon_fraction": {"label": "photon budget", "unit": "x reference", "cheaper": "fewer"},
}


def parse_zones(text) -> tuple[int, int]:
    """``"3x3"`` (or ``(3, 3)``) -> ``(3, 3)``; rows and columns 1 to 16."""
    if isinstance(text, (tuple, list)) and len(text) == 2:
        r, c = text
    else:
        parts = str(text).lower().replace(" ", "").split("x")
        if len(parts) != 2:
            raise UserError(f"zones {text!r} must look like 3x3 (rows x cols)")
        try:
            r, c = int(parts[0]), int(parts[1])
        except ValueError:
            raise UserError(f"zones {text!r} must look like 3x3 (rows x cols)") from None
    if not (1 <= int(r) <= 16 and 1 <= int(c) <= 16):
        raise UserError(f"zones {r}x{c}: rows and columns must be 1 to 16")
    return int(r), int(c)


def layout_name(zones) -> str:
    """A zone layout as files, keys and reports name it: ``(3, 3)`` -> ``"3x3"``."""
    return f"{zones[0]}x{zones[1]}"


@dataclass(frozen=True, order=True)
class Design:
    """One sensor design.

    Parameters
    ----------
    zones : (int, int)
        Zone rows and columns (same field of view as the reference sensor).
    bin_factor : int
        Bin width in reference bins (1: the reference's width).
    n_bins : int
        Histogram bins (the window is ``n_bins * bin width``).
    jitter_fwhm_ps, pulse_fwhm_ps : float
        Gaussian timing jitter and laser pulse FWHM, ps (added to the
        reference's measured pulse shape).
    photon_fraction : float
        Photons per capture relative to the reference sensor (> 0).
    """

    zones: tuple[int, int] = (3, 3)
    bin_factor: int = 1
    n_bins: int = 128
    jitter_fwhm_ps: float = 0.0
    pulse_fwhm_ps: float = 0.0
    photon_fraction: float = 1.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "zones", parse_zones(self.zones))
        for name in ("bin_factor", "n_bins"):
            v = getattr(self, name)
            if int(v) != v or int(v) < 1:
                raise UserError(f"{name}={v} must be a whole number >= 1")
            object.__setattr__(self, name, int(v))
        for name in ("jitter_fwhm_ps", "pulse_fwhm_ps", "photon_fraction"):
            v = float(getattr(self, name))
            if not math.isfinite(v) or v < 0 or (name == "photon_fraction" and v == 0):
                raise UserError(f"{name}={v} must be finite and {'> 0' if name == 'photon_fraction' else '>= 0'}")
            object.__setattr__(self, name, v)

    @property
    def n_zones(self) -> int:
        return self.zones[0] * self.zones[1]

    @property
    def layout(self) -> str:
        """Its zone layout's name, e.g. ``"3x3"`` (:func:`layout_name`)."""
        return layout_name(self.zones)

    def key(self) -> str:
        """A short stable name, e.g. ``3x3/b1x128/j0/p0/n1``."""
        return (f"{self.zones[0]}x{self.zones[1]}/b{self.bin_factor}x{self.n_bins}/j{self.jitter_fwhm_ps:g}"
                f"/p{self.pulse_fwhm_ps:g}/n{self.photon_fraction:g}")

    def replace(self, **changes) -> "Design":
        return replace(self, **changes)

    def to_dict(self) -> dict:
        return {**asdict(self), "zones": self.layout}

    @classmethod
    def from_dict(cls, data: dict) -> "Design":
        return cls(**data)

    def value(self, axis: str, reference: SensorConfig) -> float:
        """The design's value on ``axis`` in the axis's unit (bin width in ps, zones as a count)."""
        if axis == "zones":
            return float(self.n_zones)
        if axis == "bin_factor":
            return self.bin_factor * reference.bin_width_ps
        return float(getattr(self, axis))

    def sensor(self, reference: SensorConfig) -> SensorConfig:
        """The :class:`SensorConfig` of this design, built on ``reference``."""
        iterations = max(1, round(reference.iterations * min(self.photon_fraction, 1.0)))
        scale = reference.photon_scale * self.photon_fraction * reference.iterations / iterations
        return reference.replace(
            name=f"design {self.key()}", zones_rows=self.zones[0], zones_cols=self.zones[1],
            bin_width_ps=reference.bin_width_ps * self.bin_factor, n_bins=self.n_bins,
            jitter_fwhm_ps=self.jitter_fwhm_ps, pulse_fwhm_ps=self.pulse_fwhm_ps,
            iterations=iterations, photon_scale=scale,
            notes=f"nlosplan design {self.key()} on {reference.name}")


@dataclass(frozen=True)
class DesignSpace:
    """Bounds and choices of every design parameter, and the reference they start from.

    Parameters
    ----------
    reference : str
        Preset name or sensor file of the reference sensor (the design the
        one-at-a-time scans start from and the unit of the photon budget).
    zones : tuple of (int, int)
        Zone layouts to consider.
    bin_factors : tuple of int
        Bin widths as multiples of the reference's.
    n_bins : (int, int)
        Smallest and largest number of bins (at the reference bin width;
        merged bins cap it at ``reference.n_bins // bin_factor``).
    jitter_fwhm_ps, pulse_fwhm_ps : (float, float)
        Bounds, ps.
    photon_fraction : (float, float)
        Bounds of the photon budget, fractions of the reference's.
    axes : tuple of str
        Parameters scanned one at a time for the per-parameter requirements (from :data:`AXES`).
    """

    reference: str = DEFAULT_SENSOR
    zones: tuple[tuple[int, int], ...] = ((1, 1), (2, 2), (3, 3), (4, 4), (8, 8))
    bin_factors: tuple[int, ...] = (1, 2, 4, 8)
    n_bins: tuple[int, int] = (32, 128)
    jitter_fwhm_ps: tuple[float, float] = (0.0, 1000.0)
    pulse_fwhm_ps: tuple[float, float] = (0.0, 1000.0)
    photon_fraction: tuple[float, float] = (0.01, 1.0)
    axes: tuple[str, ...] = ("zones", "bin_factor", "n_bins", "jitter_fwhm_ps", "pulse_fwhm_ps", "photon_fraction")
    _sensor: SensorConfig | None = field(default=None, compare=False, repr=False)

    def __post_init__(self) -> None:
        zones = tuple(sorted({parse_zones(z) for z in self.zones}, key=lambda z: (z[0] * z[1], z)))
        if not zones:
            raise UserError("the design space needs at least one zone layout")
        object.__setattr__(self, "zones", zones)
        factors = tuple(sorted({int(f) for f in self.bin_factors}))
        if not factors or factors[0] < 1:
            raise UserError("bin_factors must be whole numbers >= 1")
        object.__setattr__(self, "bin_factors", factors)
        for name in ("n_bins", "jitter_fwhm_ps", "pulse_fwhm_ps", "photon_fraction"):
            lo, hi = (float(v) for v in getattr(self, name))
            if not (math.isfinite(lo) and math.isfinite(hi) and 0 <= lo <= hi):
                raise UserError(f"{name} bounds {lo:g}..{hi:g} must be finite with 0 <= low <= high")
            if name == "photon_fraction" and lo <= 0:
                raise UserError("photon_fraction's lower bound must be > 0")
            object.__setattr__(self, name, (int(lo), int(hi)) if name == "n_bins" else (lo, hi))
        if self.n_bins[0] < 1:
            raise UserError("n_bins' lower bound must be >= 1")
        bad = [a for a in self.axes if a not in AXES]
        if bad:
            raise UserError(f"unknown design axis {', '.join(bad)}; allowed: {', '.join(AXES)}")
        sensor = self._sensor or resolve_sensor(self.reference)
        object.__setattr__(self, "_sensor", sensor)
        if self.n_bins[1] > sensor.n_bins:
            raise UserError(f"n_bins up to {self.n_bins[1]} exceeds the reference's {sensor.n_bins} bins")

    @property
    def sensor(self) -> SensorConfig:
        """The reference sensor."""
        return self._sensor

    def reference_design(self) -> Design:
        """The reference sensor as a design: where the one-at-a-time lines start, and the learners are compared.

        Its zones, bin width and bins, no added blur, all its photons (each clipped into the space).
        """
        s = self.sensor
        zones = (s.zones_rows, s.zones_cols)
        return Design(zones, 1, min(s.n_bins, self.n_bins[1]), max(s.jitter_fwhm_ps, self.jitter_fwhm_ps[0]),
                      max(s.pulse_fwhm_ps, self.pulse_fwhm_ps[0]), min(1.0, self.photon_fraction[1]))

    def layout_design(self, zones) -> Design:
        """The design a zone layout's reference data is simulated at: the least blur, every bin of the reference
        sensor and all its photons, so that every design of the layout is reached by degrading it."""
        return Design(zones, 1, self.sensor.n_bins, self.jitter_fwhm_ps[0], self.pulse_fwhm_ps[0], 1.0)

    def layout_sensor(self, zones) -> SensorConfig:
        """The sensor of :meth:`layout_design`, named ``reference RxC`` (its name is part of the reference's key)."""
        return self.layout_design(zones).sensor(self.sensor).replace(name=f"reference {layout_name(zones)}")

    def max_bins(self, bin_factor: int) -> int:
        """Largest number of bins at a bin width (the reference window)."""
        return min(self.n_bins[1], self.sensor.n_bins // bin_factor)

    def contains(self, d: Design) -> str:
        """Empty if ``d`` is in the space, else why not."""
        if d.zones not in self.zones:
            return f"zones {d.zones[0]}x{d.zones[1]} are not in the space"
        if d.bin_factor not in self.bin_factors:
            return f"bin factor {d.bin_factor} is not in the space"
        if not self.n_bins[0] <= d.n_bins <= self.max_bins(d.bin_factor):
            return f"{d.n_bins} bins is outside {self.n_bins[0]}..{self.max_bins(d.bin_factor)}"
        for name in ("jitter_fwhm_ps", "pulse_fwhm_ps", "photon_fraction"):
            lo, hi = getattr(self, name)
            if not lo - 1e-9 <= getattr(d, name) <= hi + 1e-9:
                return f"{name}={getattr(d, name):g} is outside {lo:g}..{hi:g}"
        return ""

    def to_dict(self) -> dict:
        return {"reference": self.reference, "zones": [f"{r}x{c}" for r, c in self.zones],
                "bin_factors": list(self.bin_factors), "n_bins": list(self.n_bins),
                "jitter_fwhm_ps": list(self.jitter_fwhm_ps), "pulse_fwhm_ps": list(self.pulse_fwhm_ps),
                "photon_fraction": list(self.photon_fraction), "axes": list(self.axes)}

    @classmethod
    def from_dict(cls, data: dict, sensor: SensorConfig | None = None) -> "DesignSpace":
        """From :meth:`to_dict` (or a TOML ``[space]`` table); ``sensor`` replaces loading the reference."""
        check_keys(data, sorted(("reference", "zones", "bin_factors", "n_bins", "jitter_fwhm_ps", "pulse_fwhm_ps",
                                 "photon_fraction", "axes")), "design-space key(s)")
        kw = {k: tuple(v) if isinstance(v, list) else v for k, v in data.items()}
        return cls(**kw, _sensor=sensor)

