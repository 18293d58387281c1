"""The Table-2 calibration workflow (``nlosplan calibrate --stats FILE``): fit a sensor to a statistics file.

:func:`calibrate_stats` simulates the components of the statistics' zone mode once, fits the free parameters
(sensor, scene and protocol nuisances) to the rows, optionally refits on bootstrap resamples and on the model
variants, and scores the fit row by row; :meth:`StatsCalibration.write` writes the sensor file, its scene table and
its uncertainty JSON (the files that made the ``denali-tmf8828-3x3`` preset). Runs from Python as from the command,
which only parses and prints.

Examples
--------
>>> cal = calibrate_stats("denali-table2", positions=2)  # doctest: +SKIP
>>> cal.fit.objective, cal.score["meets"]  # doctest: +SKIP
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from nlosplan.calibration.bootstrap import MIN_RESAMPLES
from nlosplan.calibration.stats_file import SHIPPED, SHIPPED_NAME, StatsFile, load_stats, resolve_stats_path
from nlosplan.calibration.stats_fit import (DEFAULT_FREE, FITTABLE, StatsFit, bootstrap, fit_stats, intervals, split,
                                            uncertainty_dict)
from nlosplan.calibration.stats_model import NUISANCE_PARAMS, SCENE_PARAMS, SENSOR_PARAMS, components
from nlosplan.calibration.stats_score import scene_for, scene_table_path, scene_table_toml, score_stats
from nlosplan.calibration.stats_variants import MODEL_VARIANTS, variant_fits, variant_samples
from nlosplan.errors import UserError
from nlosplan.sensor_models import SensorConfig, resolve_sensor, sensor_base
from nlosplan.sensor_models.fitted_to import RealSource, record_dicts, without
from nlosplan.sensor_models.preset_sources import sensor_record

__all__ = ["DEFAULT_SENSOR", "StatsCalibration", "calibrate_stats", "check_free", "stats_record"]

#: The sensor a statistics file is fitted to unless another is given (DENALI's Table 2 made it).
DEFAULT_SENSOR = "denali-tmf8828-3x3"


def check_free(names) -> tuple[str, ...]:
    """The fitted parameters, each one of :data:`~nlosplan.calibration.stats_fit.FITTABLE` (default: ``DEFAULT_FREE``)."""
    names = DEFAULT_FREE if names is None else tuple(names)
    bad = [n for n in names if n not in FITTABLE]
    if bad or not names:
        raise UserError(f"unknown parameter(s) {', '.join(bad) or '(none)'} in --fit; allowed: {', '.join(FITTABLE)}")
    return names


@dataclass(frozen=True, eq=False)
class StatsCalibration:
    """A sensor fitted to a statistics file, with its uncertainty and its row-by-row score.

    Attributes
    ----------
    spec : str
        The sensor asked for (preset name or file); ``sensor`` is it resolved.
    source : str
        The statistics file as given (a path or a shipped name); ``stats`` is it loaded.
    stats : StatsFile
    positions : int
        Gantry positions per object of the simulated sample (30 objects).
    seed : int
        Noise seed of the fit.
    fit : StatsFit
    samples : list of dict
        Bootstrap and model-variant refits' values (the uncertainty's spread).
    variants : list of StatsFit
        One refit per :data:`~nlosplan.calibration.stats_variants.MODEL_VARIANTS` (empty without ``variants``).
    bootstraps : int
        Bootstrap refits asked for.
    fitted : SensorConfig
        The calibrated sensor.
    scene, nuisances : dict
        The fitted scene parameters (``mount`` kept from the start) and protocol nuisances.
    score : dict
        :func:`~nlosplan.calibration.stats_score.score_stats` of the fit.
    intervals : dict
        Per parameter ``{"std", "lo", "hi"}`` from the samples.
    uncertainty : dict or None
        The ``X.uncertainty.json`` document.
    method : str
        How the uncertainty was measured, in words.
    fitted_to : tuple of RealSource
        The real data the fitted sensor's values come from (:func:`stats_record`), written into its file.
    """

    spec: str
    sensor: SensorConfig
    source: str
    stats: StatsFile
    positions: int
    seed: int
    fit: StatsFit
    samples: list
    variants: list
    bootstraps: int
    fitted: SensorConfig
    scene: dict
    nuisances: dict
    score: dict
    intervals: dict
    uncertainty: dict | None
    method: str
    fitted_to: tuple = ()
    files: dict = field(default_factory=dict)

    def write(self, out) -> dict[str, str]:
        """Write the sensor file (``.toml`` or ``.json``), its scene table and its uncertainty JSON; their paths."""
        from nlosplan.files import write_text

        out = Path(out)
        res, fit = self.score, self.fit
        fitted = self.fitted.replace(notes=(self.sensor.notes + f" Refitted by 'nlosplan calibrate --stats "
                                            f"{self.source}' (objective {fit.objective:.4g}; "
                                            f"{res['meets']['statistics']} of {res['meets']['statistics_of']} row "
                                            f"statistics, {res['meets']['ratios']} of {res['meets']['ratios_of']} "
                                            "ratios within target).").strip())
        base = sensor_base(self.spec)  # the refined preset, so that later model fields come from it
        record = record_dicts(self.fitted_to)
        write_text(out, fitted.to_toml(base=base, fitted_to=record) if out.suffix == ".toml"
                   else fitted.to_json(base=base, fitted_to=record))
        files = {"sensor": str(out)}
        st = scene_table_path(out)
        write_text(st, scene_table_toml(self.scene, self.nuisances,
                                        {"statistics": self.source, "objective": fit.objective,
                                         "converged": fit.converged, "uncertainty": self.method},
                                        {k: v for k, v in self.intervals.items() if k not in SENSOR_PARAMS}))
        files["scene"] = str(st)
        if self.uncertainty is not None:
            uj = out.with_name(out.stem + ".uncertainty.json")
            write_text(uj, json.dumps(self.uncertainty, indent=1))
            files["uncertainty"] = str(uj)
        self.files.update(files)
        return files

    def to_dict(self) -> dict:
        """JSON-friendly: the fit, the variants, the uncertainty, the score, the record and the files written."""
        fit = self.fit
        return {"sensor": self.sensor.name, "statistics": self.source, "fit": {
            "values": fit.values, "free": list(fit.free), "objective": fit.objective, "converged": fit.converged,
            "evaluations": fit.evaluations, "seconds": fit.seconds, "message": fit.message},
            "variants": [{**v.as_dict(), "objective": r.objective, "converged": r.converged,
                          "values": {k: r.values[k] for k in fit.free}} for v, r in zip(MODEL_VARIANTS, self.variants)],
            "uncertainty": self.uncertainty, "intervals": self.intervals, "uncertainty_method": self.method,
            "score": self.score, "fitted_to": record_dicts(self.fitted_to), "files": dict(self.files)}


def stats_record(stats, table: StatsFile, sensor: str, fitted: SensorConfig, values: dict, free, zones: str,
                 by: str, mount: bool) -> tuple[RealSource, ...]:
    """The ``fitted_to`` record of a sensor fitted to a statistics file.

    The file (its path as given, or the shipped file's for ``denali-table2``, and the sha256 of its content) with
    the fitted sensor fields, scene parameters and nuisances and what the fit held fixed; its ``[[levels]]`` for
    this zone mode, when it has any (fitted jointly: one objective); then the starting sensor's own record less
    what was refitted (its time base and pulse, for example).

    Parameters
    ----------
    stats : str or Path
        The statistics file as given.
    table : StatsFile
        It, loaded.
    sensor : str
        The sensor spec fitted (preset name or file), whose record the rest comes from.
    fitted : SensorConfig
        The fitted sensor.
    values : dict
        The fit's values (sensor fields, scene parameters, nuisances).
    free : sequence of str
        The fitted parameters.
    zones : str
        The zone mode fitted (``"3x3"``).
    by : str
        The command that made it.
    mount : bool
        Whether the scene had the mount.
    """
    import hashlib

    path = resolve_stats_path(stats)
    sha = hashlib.sha256(Path(path).read_bytes()).hexdigest()
    ref = (f"{SHIPPED_NAME} (package data nlosplan/calibration/data/{SHIPPED})" if str(stats) == SHIPPED_NAME
           else str(stats))
    sensor_free = [k for k in free if k in SENSOR_PARAMS]
    params = {k: getattr(fitted, k) for k in sensor_free}
    scene = {k: values[k] for k in free if k not in SENSOR_PARAMS}
    held = {k: getattr(fitted, k) for k in SENSOR_PARAMS if k not in free}
    held |= {k: values[k] for k in SCENE_PARAMS + NUISANCE_PARAMS if k not in free and k in values} | {"mount": mount}
    rows = table.rows_for(zones)
    title = table.source.get("title", Path(path).name)
    out = [RealSource(source=title, ref=ref, sha256=sha, use="fitted", by=by, parameters=params, scene=scene,
                      held=held, what=(f"{len(rows)} rows of the {zones} statistics (total, centroid, spread, skew: "
                                       f"mean +- SEM) and {len(table.ratios)} ratios, processed as the file's "
                                       f"[processing.{zones}] says"))]
    levels = [lev for lev in table.levels if lev.zones == zones]
    if levels and params:
        src = table.source.get("levels", "")
        out.append(RealSource(
            source=f"levels of {Path(path).name}", ref=ref + ", its [[levels]]", sha256=sha, use="fitted", by=by,
            parameters=params, what="; ".join(f"{lev.name} = {lev.value:g} ({lev.statistic})" for lev in levels)
            + "; fitted jointly with the rows (one objective)" + (f"; source: {src}" if src else "")))
    _, start, _, _ = sensor_record(sensor)
    return tuple(out) + without(start, list(free))


def _by(stats, sensor: str, scene, free, positions: int, seed: int, bootstraps: int, variants: bool) -> str:
    """The command line that makes this fit."""
    parts = [f"nlosplan calibrate --stats {stats} --sensor {sensor} --fit {','.join(free)} --positions {positions} "
             f"--seed {seed}"]
    if scene:
        parts.append(f"--scene {scene}")
    if bootstraps:
        parts.append(f"--bootstrap {bootstraps}")
    if variants:
        parts.append("--variants")
    return " ".join(parts)


def _method(bootstraps: int, variants: list) -> str:
    parts = []
    if bootstraps:
        parts.append(f"{bootstraps} bootstrap refits (the statistics redrawn within their SEMs, a new noise seed "
                     "each; scene sample and model held fixed)")
    if variants:
        parts.append(f"{len(variants)} model-variant refits (repeat-mean or single captures x 5 readings of the "
                     "checkpoint levels x diffuse base 0-0.3 x mount in/out of the background)")
    return "spread of " + " and ".join(parts) if parts else "none (no --bootstrap, no --variants)"


def calibrate_stats(stats, *, sensor: str = DEFAULT_SENSOR, scene: str | None = None, free=None, positions: int = 10,
                    seed: int = 0, bootstraps: int = 0, variants: bool = False,
                    say: Callable[[str], None] | None = None,
                    progress: Callable[[str, int, int], None] | None = None) -> StatsCalibration:
    """Fit ``sensor`` to a statistics file (DENALI's Table 2: ``"denali-table2"``).

    Parameters
    ----------
    stats : str or Path
        A statistics file or the name of a shipped one.
    sensor : str
        Preset name or sensor file fitted (its scene table gives the start).
    scene : str, optional
        A scene table to start from instead of the sensor's.
    free : sequence of str, optional
        Fitted parameters (:func:`check_free`; default ``DEFAULT_FREE``).
    positions : int
        Gantry positions per object (30 objects) of the simulated sample.
    seed : int
        Noise seed.
    bootstraps : int
        Bootstrap refits (0, or at least :data:`~nlosplan.calibration.bootstrap.MIN_RESAMPLES`).
    variants : bool
        Also refit on every model variant (their spread joins the uncertainty).
    say : callable, optional
        ``say(text)`` before each long step.
    progress : callable, optional
        ``progress(stage, done, total)`` per refit, stage ``"bootstrap"`` or ``"variants"``.

    Returns
    -------
    StatsCalibration
    """
    if 0 < bootstraps < MIN_RESAMPLES:
        raise UserError(f"bootstrap refits {bootstraps} < {MIN_RESAMPLES}: give at least {MIN_RESAMPLES} "
                        "(30 or more for a 95 % interval)")
    free = check_free(free)
    say = say or (lambda text: None)
    table = load_stats(stats)
    cfg = resolve_sensor(sensor)
    zones = f"{cfg.zones_rows}x{cfg.zones_cols}"
    if zones not in table.processing or not table.rows_for(zones):
        raise UserError(f"{stats} has no rows for a {zones} sensor ({cfg.name})")
    start_scene, nuis, source = scene_for(sensor, cfg, scene)
    say(f"simulating {30 * positions} scenes per size for {cfg.name} ...")
    comp = components(cfg, table.processing[zones].zone, n_positions=positions)
    start = {k: v for k, v in start_scene.items() if k != "mount"} | nuis
    say(f"fitting {', '.join(free)} (start: {source}) ...")
    fit = fit_stats(table, comp, cfg, start, free, seed=seed)
    step = (lambda stage: None) if progress is None else (lambda stage: lambda done, total: progress(stage, done, total))
    samples = bootstrap(table, comp, cfg, fit, bootstraps, seed=seed, progress=step("bootstrap")) if bootstraps else []
    refits = []
    if variants:
        refits = variant_fits(table, comp, cfg, fit, seed=seed, progress=step("variants"))
        samples = samples + variant_samples(fit, refits)
    fitted, fscene, fnuis = split(fit.values, cfg)
    fscene["mount"] = bool(start_scene.get("mount", True))
    record = stats_record(stats, table, sensor, fitted, fit.values, free, zones,
                          _by(stats, sensor, scene, free, positions, seed, bootstraps, variants), fscene["mount"])
    return StatsCalibration(
        spec=sensor, sensor=cfg, source=str(stats), stats=table, positions=positions, seed=seed, fit=fit, samples=samples,
        variants=refits, bootstraps=bootstraps, fitted=fitted, scene=fscene, nuisances=fnuis,
        score=score_stats(table, fitted, fscene, fnuis, comp=comp), intervals=intervals(fit, samples),
        uncertainty=uncertainty_dict(cfg.name, fit, samples), method=_method(bootstraps, refits), fitted_to=record)
