"""Fidelity knobs of the Mitsuba twin and their named levels."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

from nlosplan.errors import UserError
from nlosplan.simulators.levels import resolve_level


@dataclass(frozen=True)
class TwinFidelity:
    """Monte-Carlo and film sizes of the twin (every result converges as they grow).

    Parameters
    ----------
    spp : int
        Path samples per film pixel (hidden-geometry sampling of the object,
        BSDF sampling back to the wall, next-event estimation of the flash).
    zone_sub : int
        Film pixels per zone axis: the film is ``(rows * zone_sub, cols * zone_sub)``
        wall points, the centres of each zone's sub-pixels.
    time_oversample : int
        Film time boxes per sensor bin.
    flash_resolution : int
        Columns of the projector's flash texture.
    """

    spp: int = 256
    zone_sub: int = 8
    time_oversample: int = 4
    flash_resolution: int = 256

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise UserError(f"twin fidelity {f.name}={v!r} must be an integer >= 1")
        if self.spp > 1 << 20 or self.zone_sub > 128 or self.flash_resolution > 4096 or self.time_oversample > 64:
            raise UserError("twin fidelity too large: spp <= 1048576, zone_sub <= 128, flash_resolution <= 4096, "
                            "time_oversample <= 64")

    def to_dict(self) -> dict[str, int]:
        """Plain dictionary of the knobs."""
        return dataclasses.asdict(self)


#: Named levels, cheapest first; "reference" is the converged twin of ``nlosplan bench fidelity``.
TWIN_LEVELS: dict[str, TwinFidelity] = {
    "draft": TwinFidelity(spp=16, zone_sub=4),
    "low": TwinFidelity(spp=64, zone_sub=6),
    "default": TwinFidelity(),
    "high": TwinFidelity(spp=1024, zone_sub=12),
    "reference": TwinFidelity(spp=4096, zone_sub=16, time_oversample=4, flash_resolution=512),
}


def resolve_twin_fidelity(value: Any) -> TwinFidelity:
    """A :class:`TwinFidelity` from a level name, a mapping of knobs, or a TwinFidelity."""
    return resolve_level(value, TWIN_LEVELS, TwinFidelity, "twin fidelity")
