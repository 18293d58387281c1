"""The forward model of a statistics file: a sensor and scene parameters -> the four statistics per row.

DENALI's Table 2 is a mean over noisy captures processed nonlinearly (background
subtracted, cropped, clipped at 0), so the model simulates the noisy processed
histograms themselves, with common random numbers (:class:`Noise`) so that the
statistics are smooth in the parameters.

The light is linear in the photon budget and the albedos (DENALI's flux is
~0.05 photons per iteration in the centre zone: pile-up does not matter), so the
fast simulator runs once per sensor time base (:func:`components`): per scene
the processing zone's direct return, the object's retroreflective and
Lambertian returns at albedo 1, and the mount + plate (Lambertian, albedo 1),
per iteration at photon scale 1. Everything else is arithmetic
(:func:`simulate_rows`):

- counts per capture: ``K = photon_scale x iterations`` times the components;
  floor per bin ``F = (dark + ambient if lights on) x bin width x iterations``;
- capture ``= F + K (direct + albedo retro + diffuse_albedo lambertian)
  [+ mount_albedo mount] + early residual``; background ``= F (1 + offset[light])
  + K direct [+ mount]`` (the mount is in both when ``mount_in_background``);
- processed ``= max(capture - background + noise, clip_min)`` on bins
  ``>= crop_below_bin``; noise Gaussian with the Poisson variance of both
  (divided by the repeats for repeat means).

Parameter names: :data:`SENSOR_PARAMS` are :class:`SensorConfig` fields,
:data:`SCENE_PARAMS` are :func:`~nlosplan.simulators.denali_scene` keywords and
:data:`NUISANCE_PARAMS` the statistics file's protocol nuisances.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nlosplan.calibration.stats_file import STATISTICS, StatsFile
from nlosplan.errors import UserError
from nlosplan.sensor_models.config import SensorConfig
from nlosplan.sensor_models.noise import floor_counts

SENSOR_PARAMS = ("photon_scale", "dark_rate_hz", "ambient_rate_hz")
SCENE_PARAMS = ("albedo", "diffuse_albedo", "mount_albedo", "mount_in_background")
NUISANCE_PARAMS = ("background_offset_on", "background_offset_off", "early_residual_counts",
                   "early_residual_decay_bins")
#: Nuisances that are off (a model without protocol nuisances).
NO_NUISANCES = {"background_offset_on": 0.0, "background_offset_off": 0.0, "early_residual_counts": 0.0,
                "early_residual_decay_bins": 3.0}


@dataclass(frozen=True)
class Components:
    """Per-scene light of the processing zone, photons per iteration at photon scale 1 (no floor).

    Attributes
    ----------
    zones : str
        Zone mode (``"3x3"``).
    zone : (int, int)
    pairs : tuple of (str, int)
        (object, gantry position) of each scene, the same for both sizes.
    direct : ndarray, shape (B,)
        First-bounce light of the rig (wall, tables), the same in every scene.
    retro, lamb : dict size -> ndarray, shape (N, B)
        The object's retroreflective / Lambertian return at albedo 1.
    mount : ndarray, shape (N, B)
        Mount post + plate, Lambertian, albedo 1.
    bin_width_ps : float
    """

    zones: str
    zone: tuple
    pairs: tuple
    direct: np.ndarray
    retro: dict
    lamb: dict
    mount: np.ndarray
    bin_width_ps: float


def scene_pairs(n_positions: int) -> tuple:
    """Every DENALI object at ``n_positions`` gantry positions spread over the grid (object i: k i, k i + s, ...).

    ``s = 100 // n_positions`` and ``k = max(1, s // 30)``: with one position per object the 30 objects take
    positions 0, 3, ..., 87 (rows 0-8 of the 10 x 10 grid), not 0-29 (the first three rows only).
    """
    from nlosplan.denali import DENALI_OBJECTS

    if not 1 <= n_positions <= 100:
        raise UserError(f"positions per object must be 1-100, got {n_positions}")
    step = 100 // n_positions
    k = max(1, step // 30)
    return tuple((o, (k * i + j * step) % 100) for i, o in enumerate(DENALI_OBJECTS) for j in range(n_positions))


def linear_sensor(sensor: SensorConfig) -> SensorConfig:
    """``sensor`` per iteration at photon scale 1, no floor, no pile-up, time walk or clip (the components' sensor)."""
    return sensor.replace(photon_scale=1.0, iterations=1, ambient_rate_hz=0.0, dark_rate_hz=0.0, saturation=False,
                          pileup=False, time_walk_ps=0.0, dead_time_ps=None)


def components(sensor: SensorConfig, zone=(1, 1), n_positions: int = 10, fidelity="default") -> Components:
    """Run the fast simulator for the components of :func:`simulate_rows`.

    Parameters
    ----------
    sensor : SensorConfig
        Its zone grid, FoV, time base and pulse matter here; its photon budget
        and rates enter :func:`simulate_rows`.
    zone : (int, int)
        The processing zone.
    n_positions : int
        Gantry positions per object (all 30 objects): ``30 x n_positions`` scenes per size.
    fidelity : str
        Fast-simulator fidelity.
    """
    from nlosplan.simulators import denali_scene, expected_batch

    lin = linear_sensor(sensor)
    zone = (int(zone[0]), int(zone[1]))
    if not (zone[0] < sensor.zones_rows and zone[1] < sensor.zones_cols):
        raise UserError(f"processing zone {list(zone)} is outside the {sensor.zones_rows}x{sensor.zones_cols} sensor "
                        f"{sensor.name}")
    pairs = scene_pairs(n_positions)
    n = len(pairs)
    out = {}
    for refl in ("retroreflective", "lambertian"):
        scenes = [denali_scene(o, s, p, reflectance=refl, albedo=1.0) for s in ("4in", "8in") for o, p in pairs]
        e = expected_batch(scenes, lin, fidelity=fidelity, zones=[zone], chunk=50, parts=True).parts
        obj = np.asarray(e["object"], float)[:, 0, :]
        out[refl] = {"4in": obj[:n], "8in": obj[n:]}
        direct = np.asarray(e["direct"], float)[0, 0, :]
    positions = sorted({p for _, p in pairs})
    mscenes = []
    for p in positions:
        sc = denali_scene("A", "8in", p, mount=True, mount_albedo=1.0, mount_in_background=False)
        mscenes.append(sc.replace(objects=sc.objects[1:]))
    m = np.asarray(expected_batch(mscenes, lin, fidelity=fidelity, zones=[zone], chunk=50, parts=True)
                   .parts["object"], float)[:, 0, :]
    index = {p: k for k, p in enumerate(positions)}
    mount = m[[index[p] for _, p in pairs]]
    return Components(zones=f"{sensor.zones_rows}x{sensor.zones_cols}", zone=zone, pairs=pairs, direct=direct,
                      retro=out["retroreflective"], lamb=out["lambertian"], mount=mount,
                      bin_width_ps=float(sensor.bin_width_ps))


class Noise:
    """Common random numbers: standard normals per row, fixed by ``seed``.

    ``draws(row_index, shape)`` returns the same array for the same arguments.
    """

    def __init__(self, seed: int = 0):
        self.seed = int(seed)
        self._cache = {}

    def draws(self, index: int, shape: tuple) -> np.ndarray:
        key = (index, tuple(shape))
        if key not in self._cache:
            self._cache[key] = np.random.default_rng([self.seed, index]).standard_normal(shape)
        return self._cache[key]


def statistics(h: np.ndarray, bins: np.ndarray) -> tuple:
    """Total, centroid, spread, skew of each histogram ``h (..., B)`` over bin indices ``bins (B,)``.

    NaN for the centroid, spread and skew of an empty histogram.
    """
    b = np.asarray(bins, float)
    tot = h.sum(-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        c = (h * b).sum(-1) / tot
        d = b - c[..., None]
        var = (h * d**2).sum(-1) / tot
        sk = (h * d**3).sum(-1) / tot / var**1.5
    return tot, c, np.sqrt(var), sk


def _check_params(scene: dict, nuisances: dict) -> None:
    missing = [k for k in SCENE_PARAMS if k not in scene] + [k for k in NUISANCE_PARAMS if k not in nuisances]
    if missing:
        raise UserError(f"the Table-2 model needs {', '.join(missing)}")


def simulate_rows(comp: Components, sensor: SensorConfig, scene: dict, nuisances: dict, stats: StatsFile,
                  noise: Noise, *, keep: bool = False) -> dict:
    """Mean statistics of every row of ``comp``'s zone mode, as DENALI's processing gives them.

    Parameters
    ----------
    comp : Components
    sensor : SensorConfig
        Photon scale, iterations, bin width, dark and ambient rates are used.
    scene : dict
        :data:`SCENE_PARAMS` (albedos without unit; ``mount_in_background`` bool).
    nuisances : dict
        :data:`NUISANCE_PARAMS` (offsets: fractions of the floor; residual: counts per capture; decay: bins).
    stats : StatsFile
    noise : Noise
    keep : bool
        Also return the processed histograms (``"histograms"``: row key -> (R, N, B')).

    Returns
    -------
    dict
        ``rows``: row key -> ndarray (4,) (total counts, centroid bin, spread bins, skew), and
        ``levels``: level name -> model value.
    """
    _check_params(scene, nuisances)
    proc = stats.processing[comp.zones]
    crop = proc.crop_below_bin
    nb = comp.direct.shape[-1]
    bins = np.arange(crop, nb)
    k = sensor.photon_scale * sensor.iterations
    direct = k * comp.direct[crop:]
    early = nuisances["early_residual_counts"] * np.exp(-(bins - crop) / nuisances["early_residual_decay_bins"])
    mount = k * scene["mount_albedo"] * comp.mount[:, crop:]
    out, hists = {}, {}
    for i, row in enumerate(stats.rows):
        if row.zones != comp.zones:
            continue
        f = floor_counts(sensor, row.light == "on")
        sig = k * (scene["albedo"] * comp.retro[row.size][:, crop:] + scene["diffuse_albedo"]
                   * comp.lamb[row.size][:, crop:])
        m_cap = f + direct + sig + early
        m_bg = f * (1.0 + nuisances[f"background_offset_{row.light}"]) + direct
        if scene["mount_in_background"]:
            m_bg = m_bg + mount
        m_cap = m_cap + mount
        if proc.repeats == "mean":
            var, draws = (m_cap + m_bg) / proc.n_repeats, 1
        else:
            var, draws = m_cap + m_bg, proc.n_repeats
        z = noise.draws(i, (draws,) + m_cap.shape)
        h = np.maximum((m_cap - m_bg)[None] + np.sqrt(np.maximum(var, 0.0))[None] * z, proc.clip_min)
        t, c, s, sk = statistics(h, bins)
        out[row.key] = np.array([t.mean(), np.nanmean(c), np.nanmean(s), np.nanmean(sk)])
        if keep:
            hists[row.key] = h
    levels = {}
    for lev in stats.levels:
        if lev.zones != comp.zones:
            continue
        raw = [k * comp.direct + floor_counts(sensor, light == "on") for light in ("on", "off")]
        levels[lev.name] = float(np.mean([r.mean() if lev.statistic == "mean_count" else np.log1p(r).mean()
                                          for r in raw]))
    res = {"rows": out, "levels": levels}
    if keep:
        res["histograms"] = hists
    return res


def ratios(stats: StatsFile, rows: dict) -> dict:
    """Model ratios of totals (name -> value) for the ratios whose rows were simulated."""
    return {q.name: float(rows[q.numerator][0] / rows[q.denominator][0]) for q in stats.ratios
            if q.numerator in rows and q.denominator in rows}


def row_dict(values) -> dict:
    """The four statistics of one row as a dict."""
    return {s: float(v) for s, v in zip(STATISTICS, values)}
