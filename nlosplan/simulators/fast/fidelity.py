"""Fidelity knobs of the fast simulator and their named levels."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

from nlosplan.errors import UserError
from nlosplan.simulators.levels import resolve_level


@dataclass(frozen=True)
class Fidelity:
    """Quadrature and sampling sizes (every result converges as they grow).

    Parameters
    ----------
    zone_sub : int
        Sub-rays per zone axis: first-bounce returns and the detection cells
        (``x2``) of Lambertian three-bounce paths.
    flash_sub : int
        Flash cells per zone axis inside the field of view (``x1``).
    flash_outer : int
        Flash cells per side per axis outside the field of view, out to 3.5
        sigma of a Gaussian flash (Lambertian objects, or lobes reaching in).
    object_samples : int
        Stratified, area-weighted surface samples per hidden object.
    diffuse_samples : int
        Surface samples of the diffuse (Lambertian) base of a retroreflective
        object: its return is ~7 % of an equal-albedo retroreflector's, so it
        needs fewer samples for the same error of the whole signal (at the
        calibrated mix, 2.3-10 % of the signal: 32 samples against 128 add
        0.02 percentage points to the mean error of 24 positions, at most
        0.08, and the mixed model runs 1.3-1.5x as fast).
    support_samples : int
        Surface samples of a support part (``HiddenObject.support``: DENALI's
        mount and plate, Lambertian 0.8, 8-23 % of the mixed object's signal
        on the bench's reference positions). Its return is smooth and
        secondary: 128 samples against 2,048 add at most 0.30 % of the whole
        signal (L1) over those positions, against 0.19 % with 384 (64: up to
        1.03 %, 32: up to 2.0 %), and the mount costs a third of what it did.
    support_flash_sub : int
        Lit wall cells per zone axis inside the field of view for a support
        part's illumination leg (``flash_sub`` is the object's). The mount
        and plate are large and smooth: at 2 against 4 their leg has 201
        lit cells instead of 467 on DENALI, and the bench's errors do not
        move (0.815 % at most on eight positions, 0.816 % with 4); their
        detection cells (``zone_sub``) and outer lit cells (``flash_outer``)
        stay the object's (halving those raised the error to 1.0-1.2 %).
    time_oversample : int
        Time-grid nodes per sensor bin.
    seed : int
        Seed of the surface sampling.
    """

    zone_sub: int = 4
    flash_sub: int = 4
    flash_outer: int = 8
    object_samples: int = 384
    time_oversample: int = 4
    seed: int = 0
    diffuse_samples: int = 32
    support_samples: int = 128
    support_flash_sub: int = 2

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            lo = 0 if f.name in ("flash_outer", "seed") else 1
            if isinstance(v, bool) or not isinstance(v, int) or v < lo:
                raise UserError(f"fidelity {f.name}={v!r} must be an integer >= {lo}")
        if max(self.object_samples, self.diffuse_samples, self.support_samples) > 1_000_000 or self.zone_sub > 64 \
                or self.flash_sub > 64 or self.support_flash_sub > 64:
            raise UserError("fidelity too large: object_samples, diffuse_samples and support_samples <= 1e6, "
                            "zone_sub, flash_sub and support_flash_sub <= 64")

    def to_dict(self) -> dict[str, int]:
        """Plain dictionary of the knobs."""
        return dataclasses.asdict(self)


#: Named levels, cheapest first. "reference" is the converged reference of ``nlosplan bench simulate``.
#: On DENALI 3x3, relative L1 of the three-bounce part: retroreflective mix against the fast reference
#: draft ~6 %, low <= 2 %, default 0.3-1.2 % (flash_sub limits small objects), high <= 0.25 %; Lambertian
#: objects against the converged Mitsuba twin (``nlosplan bench fidelity``) draft ~3 %, low ~0.9 %,
#: default ~0.6 %, high ~0.6 % (a ~0.5 % floor: the two simulators' systematic difference). The reference's
#: diffuse base has 2,048 samples: a Lambertian term over its 120 x 120 flash cells costs ~1 GB per 1,000 samples
#: (16,384 ran out of memory), and the base is a few per cent of a mixed object's signal. Lambertian
#: objects see the wall lit outside the field of view, so the outer flash cells (``flash_outer``,
#: geometric in width from the zone pitch) set their error: 4 outer cells at default gave 2.7 %. Support parts
#: (the mount and plate) have ``support_samples``: about a third of ``object_samples``, and at default half the lit
#: cells per zone axis (``support_flash_sub``; the other levels keep ``flash_sub``) (see :class:`Fidelity`).
FIDELITY_LEVELS: dict[str, Fidelity] = {
    "draft": Fidelity(zone_sub=2, flash_sub=2, flash_outer=4, object_samples=64, time_oversample=2,
                      diffuse_samples=16, support_samples=32, support_flash_sub=2),
    "low": Fidelity(zone_sub=3, flash_sub=3, flash_outer=6, object_samples=256, time_oversample=4,
                    diffuse_samples=32, support_samples=96, support_flash_sub=3),
    "default": Fidelity(),
    "high": Fidelity(zone_sub=6, flash_sub=8, flash_outer=12, object_samples=1536, time_oversample=4,
                     diffuse_samples=512, support_samples=512, support_flash_sub=8),
    "reference": Fidelity(zone_sub=8, flash_sub=24, flash_outer=24, object_samples=16384, time_oversample=8,
                          diffuse_samples=2048, support_samples=2048, support_flash_sub=24),
}


def resolve_fidelity(value: Any) -> Fidelity:
    """A :class:`Fidelity` from a level name, a mapping of knobs, or a Fidelity."""
    return resolve_level(value, FIDELITY_LEVELS, Fidelity, "fidelity")
