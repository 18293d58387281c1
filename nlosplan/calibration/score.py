"""Score-only mode: a sensor against real data, nothing fitted (``nlosplan calibrate --score``).

One entry point, :func:`score_input`, dispatches by the kind of input
(:func:`input_kind`). Kinds and what scores them:

- ``plane``: a JSON list of plane captures at known distances
  (``tmf882x_distance`` layout) -> per-zone table of :mod:`.plane_scores`.
- ``statistics``: a statistics file (``.toml``, or a ``.json`` object) such as
  DENALI Table 2 -> per-row table of :mod:`.stats_score` (with a scene table).
- ``denali folder``, ``capture store``: recognised, not scored yet (a clear
  error says so); a scorer is one more entry of :data:`SCORERS`.

Scene-side inputs (the plane's arrivals) come from the caller, so this module
stays on the sensor side of the rooms.
"""

from __future__ import annotations

from dataclasses import asdict
from pathlib import Path

from nlosplan.errors import UserError
from nlosplan.sensor_models.config import SensorConfig

KINDS = ("plane", "denali folder", "capture store", "statistics")


def input_kind(path) -> str:
    """The kind of a real-data input (one of :data:`KINDS`).

    Raises
    ------
    UserError
        A path that does not exist or is none of the kinds.
    """
    p = Path(path)
    if p.is_dir():
        return "denali folder"
    if not p.exists():
        raise UserError(f"cannot read {p}: no such file or folder")
    if p.suffix in (".sqlite", ".db"):
        return "capture store"
    if p.suffix == ".toml":
        return "statistics"
    if p.suffix == ".json":
        from nlosplan.schema import loads, read_text

        data = loads(read_text(p, "captures file", max_bytes=2**30), "json", f"captures file {p}")
        if isinstance(data, list):
            return "plane"
        if isinstance(data, dict):
            return "statistics"
    raise UserError(f"{p} is neither plane captures (.json list), a DENALI folder, a capture store (.sqlite) "
                    "nor a statistics file (.toml or .json object)")


def _score_plane(path, sensor: SensorConfig, *, plane_arrivals, min_distance_m, max_distance_m, **_) -> dict:
    from nlosplan.calibration.plane_scores import TARGETS, score_plane, tables_dict
    from nlosplan.calibration.tmf882x_fit import load_distance_captures

    caps = load_distance_captures(path)
    rows, per = score_plane(sensor, caps, plane_arrivals(sensor), min_distance_m=min_distance_m,
                            max_distance_m=max_distance_m)
    return {"kind": "plane", "input": str(path), "sensor": sensor.name, "zones": tables_dict(rows),
            "per_capture": per, "targets": TARGETS, "rows": [asdict(r) for r in rows]}


def _score_statistics(path, sensor: SensorConfig, *, sensor_spec=None, scene_file=None, n_positions=10, **_) -> dict:
    from nlosplan.calibration.stats_file import load_stats
    from nlosplan.calibration.stats_score import scene_for, score_stats

    stats = load_stats(path)
    scene, nuis, source = scene_for(sensor.name if sensor_spec is None else sensor_spec, sensor, scene_file)
    res = score_stats(stats, sensor, scene, nuis, n_positions=n_positions)
    return {"kind": "statistics", "input": str(path), "scene_source": source, **res}


#: Scorer of each kind that can be scored.
SCORERS = {"plane": _score_plane, "statistics": _score_statistics}


def score_input(path, sensor: SensorConfig, *, plane_arrivals=None, min_distance_m: float = 0.06,
                max_distance_m: float = float("inf"), sensor_spec=None, scene_file=None, n_positions: int = 10) -> dict:
    """Score ``sensor`` on the real data at ``path`` without fitting anything.

    Parameters
    ----------
    path : str or Path
        The data; the word ``denali-table2`` names the shipped DENALI Table 2 statistics file.
    sensor : SensorConfig
    plane_arrivals : callable
        ``plane_arrivals(sensor) -> arrivals(distance_m) -> (times_ps (Z, K), weights (Z, K))``.
    min_distance_m, max_distance_m : float
        Plane captures outside this range are not scored.
    sensor_spec : str, optional
        Statistics: the preset name or sensor file ``sensor`` came from (its ``.scene.toml`` sidecar).
    scene_file : str, optional
        Statistics: the scene table (scene parameters and protocol nuisances) to score with.
    n_positions : int
        Statistics: gantry positions per object simulated.

    Returns
    -------
    dict
        Plane: ``kind``, ``zones`` (per-zone rows with the targets each meets), ``per_capture``, ``targets``.
        Statistics: ``kind``, ``rows``, ``ratios``, ``levels``, ``meets``, ``targets`` (:func:`.stats_score.score_stats`).

    Raises
    ------
    UserError
        Unreadable input, or a kind that cannot be scored yet.
    """
    from nlosplan.calibration.stats_file import resolve_stats_path

    path = resolve_stats_path(path)
    kind = input_kind(path)
    if scene_file and kind != "statistics":
        raise UserError(f"--scene applies to statistics files; {path} is a {kind}")
    if kind not in SCORERS:
        raise UserError(f"--score takes plane captures (a JSON list) or a statistics file so far; {path} is a "
                        f"{kind}, which cannot be scored without fitting yet")
    return SCORERS[kind](path, sensor, plane_arrivals=plane_arrivals, min_distance_m=min_distance_m,
                         max_distance_m=max_distance_m, sensor_spec=sensor_spec, scene_file=scene_file,
                         n_positions=n_positions)
