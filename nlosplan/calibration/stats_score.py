"""Score a sensor and scene parameters against a statistics file (``calibrate --score STATS``, ``bench real``).

Per row: the four statistics, real (mean, SEM) and model, their difference and
whether each meets the file's target; per ratio the same. The model's
Monte-Carlo error is the spread over common-random-number seeds.

Scene parameters and protocol nuisances travel in a *scene table* (TOML:
``[scene]`` with :data:`~.stats_model.SCENE_PARAMS` and ``mount``,
``[nuisances]`` with :data:`~.stats_model.NUISANCE_PARAMS`), written by
``calibrate --stats`` beside the sensor file as ``<stem>.scene.toml``; the
DENALI presets carry theirs (:mod:`nlosplan.sensor_models.presets_denali`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from nlosplan.calibration.stats_file import STATISTICS, StatsFile
from nlosplan.calibration.stats_model import (NUISANCE_PARAMS, SCENE_PARAMS, Noise, components, ratios,
                                              row_dict, simulate_rows)
from nlosplan.errors import UserError, check_keys
from nlosplan.sensor_models.config import SensorConfig

SCENE_KEYS = SCENE_PARAMS + ("mount",)


def scene_table_path(sensor_file) -> Path:
    """``<stem>.scene.toml`` beside a sensor file."""
    p = Path(sensor_file)
    return p.with_name(p.stem + ".scene.toml")


def parse_scene_table(data: dict, where: str) -> tuple[dict, dict]:
    """Validate a scene table's ``[scene]`` and ``[nuisances]`` (one-line errors naming the field)."""
    check_keys(data, ("scene", "nuisances", "fit", "uncertainty"), "table(s)", prefix=f"{where}: ")
    for k, v in data.get("uncertainty", {}).items():
        if k not in SCENE_PARAMS + NUISANCE_PARAMS:
            raise UserError(f"{where}: uncertainty.{k} is not a scene parameter or nuisance")
        if not (isinstance(v, list) and len(v) == 4 and all(isinstance(x, (int, float)) for x in v)):
            raise UserError(f"{where}: uncertainty.{k} must be [value, std, lo, hi]")
    out = []
    for table, keys in (("scene", SCENE_KEYS), ("nuisances", NUISANCE_PARAMS)):
        d = data.get(table)
        if not isinstance(d, dict):
            raise UserError(f"{where}: missing table [{table}]")
        check_keys(d, keys, "field(s)", prefix=f"{where}: ", suffix=f" in [{table}]")
        for k in keys:
            if k not in d:
                raise UserError(f"{where}: missing field {table}.{k}")
            boolean = k in ("mount", "mount_in_background")
            if boolean != isinstance(d[k], bool) or not (boolean or isinstance(d[k], (int, float))):
                raise UserError(f"{where}: {table}.{k} must be {'true or false' if boolean else 'a number'}, "
                                f"got {d[k]!r}")
        out.append({k: (d[k] if isinstance(d[k], bool) else float(d[k])) for k in keys})
    scene, nuis = out
    if not scene["mount"]:
        scene["mount_albedo"] = 0.0
    return scene, nuis


def load_scene_table(path) -> tuple[dict, dict]:
    """Read a scene table TOML: ``(scene, nuisances)``."""
    from nlosplan.schema import loads, read_text

    p = Path(path)
    data = loads(read_text(p, "scene table"), "toml", f"scene table {p}")
    return parse_scene_table(data, str(p))


def scene_table_toml(scene: dict, nuisances: dict, fit: dict | None = None, uncertainty: dict | None = None) -> str:
    """The TOML text of a scene table (``fit``: optional provenance strings and numbers; ``uncertainty``: name ->
    {value, std, lo, hi} of fitted scene parameters and nuisances, written as ``name = [value, std, lo, hi]``)."""
    def val(v):
        return ("true" if v else "false") if isinstance(v, bool) else (f'"{v}"' if isinstance(v, str) else f"{v:.6g}")

    lines = ["[scene]"] + [f"{k} = {val(scene[k])}" for k in SCENE_KEYS]
    lines += ["", "[nuisances]"] + [f"{k} = {val(nuisances[k])}" for k in NUISANCE_PARAMS]
    if fit:
        lines += ["", "[fit]"] + [f"{k} = {val(v)}" for k, v in fit.items()]
    if uncertainty:
        lines += ["", "[uncertainty]"] + [f"{k} = [{', '.join(val(p[f]) for f in ('value', 'std', 'lo', 'hi'))}]"
                                          for k, p in uncertainty.items()]
    return "\n".join(lines) + "\n"


def scene_for(sensor_spec, sensor: SensorConfig, scene_file=None) -> tuple[dict, dict, str]:
    """The scene table to score ``sensor`` with: ``scene_file``, else the sensor file's sidecar, else the preset's.

    Returns
    -------
    (scene, nuisances, source) where source says where they came from.

    Raises
    ------
    UserError
        None of them exists.
    """
    if scene_file:
        s, n = load_scene_table(scene_file)
        return s, n, str(scene_file)
    spec = str(sensor_spec)
    if spec.endswith((".toml", ".json")) and scene_table_path(spec).is_file():
        s, n = load_scene_table(scene_table_path(spec))
        return s, n, str(scene_table_path(spec))
    from nlosplan.sensor_models import presets_denali as d

    if sensor.name in ("denali-tmf8828-3x3", "denali-tmf8828-8x8"):
        return dict(d.DENALI_SCENE_FIT), d.denali_nuisances(sensor.name[-3:]), f"{sensor.name}'s Table-2 fit"
    raise UserError(f"no scene table for {sensor.name}: give --scene FILE (a [scene] and [nuisances] TOML, as "
                    "'calibrate --stats' writes beside its sensor file) or score a denali-tmf8828-* preset")


def _meets(stat: str, model: float, real: float, targets: dict) -> bool:
    if stat == "total":
        return abs(model / real - 1) <= targets["total_rel"]
    if stat == "centroid":
        return abs(model - real) <= targets["centroid_bins"]
    if stat == "spread":
        return abs(model / real - 1) <= targets["spread_rel"]
    return bool(np.sign(model) == np.sign(real))


def score_stats(stats: StatsFile, sensor: SensorConfig, scene: dict, nuisances: dict, *, n_positions: int = 10,
                seeds=(0, 1, 2), comp=None, fidelity="default") -> dict:
    """Model statistics of ``stats``' rows for ``sensor`` (its zone mode), against the real ones.

    Parameters
    ----------
    stats : StatsFile
    sensor : SensorConfig
    scene, nuisances : dict
        As :func:`~.stats_model.simulate_rows` takes them.
    n_positions : int
        Gantry positions per object (30 objects): the Monte-Carlo sample of scenes.
    seeds : sequence of int
        Common-random-number seeds; the table shows their mean and ``mc_std`` their spread.
    comp : Components, optional
        Reuse components already computed for this sensor's time base.

    Returns
    -------
    dict
        ``rows`` (per row: ``light``, ``size``, ``zones``, the four statistics, ``real`` {stat: mean},
        ``sem``, ``diff``, ``meets``, ``mc_std``), ``ratios`` (name -> {model, real, meets}), ``levels``,
        ``meets`` (counts), ``targets``, ``n_scenes``, ``seeds``.
    """
    zones = f"{sensor.zones_rows}x{sensor.zones_cols}"
    if zones not in stats.processing or not stats.rows_for(zones):
        raise UserError(f"the statistics file has no rows for a {zones} sensor ({sensor.name}); its zone modes: "
                        f"{', '.join(sorted({r.zones for r in stats.rows}))}")
    if comp is None:
        comp = components(sensor, stats.processing[zones].zone, n_positions=n_positions, fidelity=fidelity)
    runs = [simulate_rows(comp, sensor, scene, nuisances, stats, Noise(s)) for s in seeds]
    t = stats.targets
    rows = []
    for row in stats.rows_for(zones):
        vals = np.array([r["rows"][row.key] for r in runs])
        m = vals.mean(0)
        real = {s: row.values[s][0] for s in STATISTICS}
        rows.append({"zones": row.zones, "light": row.light, "size": row.size, **row_dict(m), "real": real,
                     "sem": {s: row.values[s][1] for s in STATISTICS},
                     "diff": {s: float(m[i] - real[s]) for i, s in enumerate(STATISTICS)},
                     "meets": {s: _meets(s, float(m[i]), real[s], t) for i, s in enumerate(STATISTICS)},
                     "mc_std": row_dict(vals.std(0))})
    model_ratios = [ratios(stats, r["rows"]) for r in runs]
    rat = {}
    for q in stats.ratios:
        if q.name in model_ratios[0]:
            v = float(np.mean([mr[q.name] for mr in model_ratios]))
            real = stats.real_ratio(q)
            rat[q.name] = {"model": v, "real": real, "meets": abs(v / real - 1) <= t["ratio_rel"]}
    levels = {k: {"model": float(np.mean([r["levels"][k] for r in runs])),
                  "real": next(lev.value for lev in stats.levels if lev.name == k)} for k in runs[0]["levels"]}
    n_stat = sum(sum(r["meets"].values()) for r in rows)
    return {"rows": rows, "ratios": rat, "levels": levels, "targets": t, "sensor": sensor.name,
            "meets": {"statistics": n_stat, "statistics_of": 4 * len(rows),
                      "ratios": sum(v["meets"] for v in rat.values()), "ratios_of": len(rat)},
            "n_scenes": len(comp.pairs), "seeds": list(seeds), "scene": scene, "nuisances": nuisances}
