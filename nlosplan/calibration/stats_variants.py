"""Model variants of a statistics-file fit: the choices the data cannot decide (``calibrate --stats --variants``).

The bootstrap (:func:`~.stats_fit.bootstrap`) redraws the statistics within
their SEMs with the model held fixed; its spread is statistical only. What the
model could equally have been is the larger error, and each variant refits the
same free parameters under one such choice. The set (a full product of the
axes, :data:`MODEL_VARIANTS`):

- ``repeats``: each Table-2 capture the mean of its 3 repeats (DENALI's loader,
  the file's ``[processing]``) or a single capture (the table's own
  description: "30 shapes x 100 positions x 3 repeats" captures per row).
  Single captures carry three times the noise variance, which the clip at 0
  turns into counts: the retro albedo moves by ~20 %.
- ``levels``: the reading of the checkpoint levels, which alone pin the photon
  scale against the floor (Table 2 cannot: its totals move with photon scale x
  albedo). The three checkpoints agree within about 3 %
  (``shared/data/denali/hist_stats.md``), so the mean count per bin is read
  3 % low or high, and the mean log1p count by the same 3 % (0.03) low or high,
  one at a time: photon scale ~4 %, floor ~3.5 %.
- ``diffuse_albedo``: the object's Lambertian base, 0 to 0.3 (Table 2 cannot
  separate it from the retroreflective part).
- ``mount_in_background``: which of DENALI's NOOBJECT / NOOBJECTMOUNT
  backgrounds holds the mount (docs/calibration.md, "The NOOBJECT/NOOBJECTMOUNT
  question").

Left out, because Table 2 does decide them: the early residual off (objective
172 against 35.6) and fits to one checkpoint level only (photon scale and
floor then trade freely: not identified, not a model error).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from itertools import product

from nlosplan.calibration.stats_file import StatsFile
from nlosplan.calibration.stats_fit import StatsFit, fit_stats
from nlosplan.calibration.stats_model import SENSOR_PARAMS

#: The checkpoint levels' relative reading error (three checkpoints agree within about 3 %).
LEVEL_READING_REL = 0.03
#: Level readings: name -> (factor on the mean-count level, shift of the mean-log1p level).
LEVEL_READINGS = {
    "nominal": (1.0, 0.0),
    "mean count -3 %": (1.0 - LEVEL_READING_REL, 0.0),
    "mean count +3 %": (1.0 + LEVEL_READING_REL, 0.0),
    "log1p -0.03": (1.0, -LEVEL_READING_REL),
    "log1p +0.03": (1.0, LEVEL_READING_REL),
}
DIFFUSE_BASES = (0.0, 0.1, 0.2, 0.3)


@dataclass(frozen=True)
class Variant:
    """One model choice of each undecided axis.

    Attributes
    ----------
    repeats : {"mean", "single"}
        Processing of each capture (the file's ``processing.<zones>.repeats``).
    levels : str
        A key of :data:`LEVEL_READINGS`.
    diffuse_albedo : float
    mount_in_background : bool
    """

    repeats: str
    levels: str
    diffuse_albedo: float
    mount_in_background: bool

    def scene(self) -> dict:
        """The scene parameters this variant fixes."""
        return {"diffuse_albedo": self.diffuse_albedo, "mount_in_background": self.mount_in_background}

    def stats(self, stats: StatsFile, zones: str) -> StatsFile:
        """``stats`` with this variant's processing of ``zones`` and reading of the levels."""
        factor, shift = LEVEL_READINGS[self.levels]
        levels = tuple(replace(lev, value=lev.value * factor if lev.statistic == "mean_count" else lev.value + shift)
                       for lev in stats.levels)
        proc = stats.processing | {zones: replace(stats.processing[zones], repeats=self.repeats)}
        return replace(stats, processing=proc, levels=levels)

    def as_dict(self) -> dict:
        """The variant's choices (JSON-ready)."""
        return {"repeats": self.repeats, "levels": self.levels, "diffuse_albedo": self.diffuse_albedo,
                "mount_in_background": self.mount_in_background}


#: Every variant ``calibrate --stats --variants`` refits under (80: 2 processings x 5 level readings x 4 diffuse
#: bases x mount in/out of the background).
MODEL_VARIANTS = tuple(Variant(r, lev, d, m) for r, lev, d, m in
                       product(("mean", "single"), LEVEL_READINGS, DIFFUSE_BASES, (False, True)))


def variant_fits(stats: StatsFile, comp, sensor, fit: StatsFit, variants=MODEL_VARIANTS, *, seed: int = 0,
                 maxeval: int = 150, progress=None) -> list[StatsFit]:
    """Refits of ``fit``'s free parameters under each variant (same data, same noise seed).

    Parameters
    ----------
    stats : StatsFile
    comp : Components
        Of ``sensor``'s time base.
    sensor : SensorConfig
    fit : StatsFit
        The nominal fit: its values start every refit.
    variants : sequence of Variant
    seed : int
        Common-random-number seed (the nominal fit's).
    maxeval : int
        Evaluations per optimizer pass.
    progress : callable, optional
        ``progress(done, total)`` after each refit.

    Returns
    -------
    list of StatsFit
        One per variant, in order; each one's ``values`` hold the variant's scene parameters. Their spread is
        the model's own uncertainty, which the SEMs' bootstrap does not see; their objectives say how much the
        data prefer one variant.
    """
    out = []
    start = {k: v for k, v in fit.values.items() if k not in SENSOR_PARAMS}
    base = sensor.replace(**{k: float(fit.values[k]) for k in SENSOR_PARAMS})
    for i, var in enumerate(variants):
        v0 = start | var.scene()
        if "albedo" in fit.free:
            v0["albedo"] = min(v0["albedo"], 1.0 - var.diffuse_albedo)
        out.append(fit_stats(var.stats(stats, comp.zones), comp, base, v0, fit.free, seed=seed, maxeval=maxeval))
        if progress is not None:
            progress(i + 1, len(variants))
    return out


def variant_samples(fit: StatsFit, refits: list[StatsFit]) -> list[dict]:
    """Samples of the variant refits: the fitted names and the diffuse base each variant fixed."""
    return [{k: float(r.values[k]) for k in fit.free} | {"diffuse_albedo": float(r.values["diffuse_albedo"])}
            for r in refits]


def variant_summary(refits: list[StatsFit], variants=MODEL_VARIANTS) -> list[str]:
    """One line per choice of each axis: how many refits took it, their objectives' range and photon scales'."""
    lines = []
    for axis in ("repeats", "levels", "diffuse_albedo", "mount_in_background"):
        for choice in dict.fromkeys(getattr(v, axis) for v in variants):
            sel = [r for r, v in zip(refits, variants) if getattr(v, axis) == choice]
            obj = [r.objective for r in sel]
            ps = [r.values["photon_scale"] for r in sel if "photon_scale" in r.values]
            text = f"  {axis} {choice}: {len(sel)} refits, objective {min(obj):.4g} to {max(obj):.4g}"
            if ps:
                text += f", photon scale {min(ps):.4g} to {max(ps):.4g}"
            lines.append(text)
    return lines
