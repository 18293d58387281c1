"""What a design costs, in relative units: 0 is the cheapest design of the space.

Default model (documented in the report): every parameter adds
``weight * log2(spec / cheapest spec)``, i.e. a fixed price per doubling of
the hardware spec. Doubling the zone count costs 0.30, the number of bins
0.10, the timing resolution (halving the bin width) 0.20, halving the timing
blur (jitter and pulse, in quadrature, floored at 50 ps) 0.20, and doubling
the photon budget (exposure) 0.15. More zones need a larger SPAD array and
readout; finer bins and jitter need faster TDCs and lasers; photons cost
integration time or laser power. Weights are configurable ([cost] in the
TOML file).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

from nlosplan.errors import UserError, check_keys
from nlosplan.sensor_models.impulse import impulse_fwhm_ps

__all__ = ["CostModel"]

_BLUR_FLOOR_PS = 50.0


@dataclass(frozen=True)
class CostModel:
    """Relative cost per doubling of each spec (see the module notes)."""

    zones: float = 0.30
    n_bins: float = 0.10
    bin_width: float = 0.20
    blur: float = 0.20
    photons: float = 0.15

    def __post_init__(self) -> None:
        for k, v in asdict(self).items():
            if not (math.isfinite(v) and v >= 0):
                raise UserError(f"cost weight {k}={v} must be finite and >= 0")

    def terms(self, design, space) -> dict[str, float]:
        """Cost of each spec of ``design`` above the cheapest of ``space``."""
        max_zones = min(r * c for r, c in space.zones)
        blur = max(impulse_fwhm_ps(design.pulse_fwhm_ps, design.jitter_fwhm_ps), _BLUR_FLOOR_PS)
        worst_blur = max(impulse_fwhm_ps(space.pulse_fwhm_ps[1], space.jitter_fwhm_ps[1]), _BLUR_FLOOR_PS)
        return {
            "zones": self.zones * math.log2(design.n_zones / max_zones),
            "n_bins": self.n_bins * math.log2(max(design.n_bins, 1) / max(space.n_bins[0], 1)),
            "bin_width": self.bin_width * math.log2(max(space.bin_factors) / design.bin_factor),
            "blur": self.blur * math.log2(worst_blur / blur),
            "photons": self.photons * math.log2(design.photon_fraction / space.photon_fraction[0]),
        }

    def __call__(self, design, space) -> float:
        return float(sum(self.terms(design, space).values()))

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict) -> "CostModel":
        check_keys(data, tuple(asdict(cls())), "cost weight(s)")
        return cls(**{k: float(v) for k, v in data.items()})
