"""Cross-validation of the all-zone plane fit by distance, and uncertainties from its refits.

The usable captures are ranked by distance and dealt into ``K`` folds
(capture of rank ``r`` in fold ``r mod K``), so every fold spans the whole
range and every capture is predicted by a fit that never saw it or its
distance. Each fold's fit becomes a sensor file (:func:`.plane_fit.zone_sensor`)
and the held-out captures are scored through the simulator's path
(:func:`.plane_scores.score_plane`): what a user of that sensor file gets.

The ``K`` refits on ``(K - 1) / K`` of the captures also give a delete-a-group
jackknife standard error of every fitted value,
``sqrt((K - 1) / K * sum_k (theta_k - mean)^2)``: it includes the model's own
error, unlike photon-counting (Fisher) errors.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from nlosplan.errors import UserError
from nlosplan.calibration.plane_fit import ZoneFit, fit_plane_zones, zone_sensor
from nlosplan.calibration.plane_model import TERMS
from nlosplan.calibration.plane_scores import ZoneTable, score_plane, zone_tables
from nlosplan.sensor_models.config import SensorConfig

#: Values whose jackknife error is reported (the pulse samples are left out).
REPORTED = ("bin_width_ps", "start_offset_ps", "photon_scale", "iterations", "time_walk_ps", "pulse_tail_fraction",
            "pulse_tail_decay_ps", "zone_time_offsets_ps", "zone_time_scales", "zone_gains", "zone_overlap_m")


def distance_folds(distance_m: np.ndarray, indices, folds: int) -> list[np.ndarray]:
    """Deal ``indices`` ranked by distance into ``folds`` interleaved folds (sorted index arrays)."""
    idx = np.asarray(indices, dtype=int)
    order = idx[np.argsort(distance_m[idx], kind="stable")]
    return [np.sort(order[k::folds]) for k in range(folds)]


def jackknife(values: list[dict]) -> dict:
    """Delete-a-group jackknife standard error of each reported value (lists stay per zone)."""
    k = len(values)
    out = {}
    for name in REPORTED:
        if name not in values[0]:
            continue
        a = np.array([np.atleast_1d(v[name]) for v in values], dtype=np.float64)
        se = np.sqrt((k - 1) / k * np.sum((a - a.mean(0)) ** 2, axis=0))
        out[name] = [float(x) for x in se] if isinstance(values[0][name], list) else float(se[0])
    return out


@dataclass
class PlaneCV:
    """Result of :func:`cross_validate`; ``to_dict()`` is JSON-ready.

    Attributes
    ----------
    folds : int
    rows : list of ZoneTable
        Held-out scores per zone, pooled over the folds.
    per_capture : dict
        ``distance_m`` and the per capture zone score lists, in distance order.
    fold_fits : list of dict
        Each fold's fitted values, deviance, convergence and held-out distances.
    errors : dict
        Jackknife standard errors (see module notes).
    messages : list of str
    seconds : float
    """

    folds: int
    rows: list
    per_capture: dict
    fold_fits: list
    errors: dict
    messages: list = field(default_factory=list)
    seconds: float = 0.0

    def to_dict(self) -> dict:
        """JSON-ready dictionary."""
        from dataclasses import asdict

        return {"folds": self.folds, "zones": [asdict(r) for r in self.rows], "per_capture": self.per_capture,
                "fold_fits": self.fold_fits, "errors": self.errors, "messages": self.messages,
                "seconds": self.seconds}


def cross_validate(captures, arrivals, base: SensorConfig, *, folds: int = 5, terms=TERMS, zones=None,
                   indices=None, min_distance_m: float = 0.06, progress=None) -> PlaneCV:
    """Fit on ``K - 1`` folds, score the held-out fold, for every fold.

    Parameters
    ----------
    captures : DistanceCaptures
    arrivals : callable
        As :func:`.plane_fit.fit_plane_zones`.
    base : SensorConfig
    folds : int
        ``K`` (2 to the number of captures).
    terms, zones, indices, min_distance_m
        As :func:`.plane_fit.fit_plane_zones`.
    progress : callable, optional
        ``progress(done, total)`` after each fold.

    Raises
    ------
    UserError
        Fewer than 2 folds, or folds too small to fit (3 captures) or to score.
    """
    t0 = time.perf_counter()
    idx = np.arange(captures.distance_m.size) if indices is None else np.asarray(indices, dtype=int)
    idx = idx[captures.distance_m[idx] >= min_distance_m]
    if not 2 <= int(folds) <= idx.size // 2:
        raise UserError(f"--folds {folds} must be between 2 and {max(idx.size // 2, 2)} "
                        f"(half the {idx.size} captures at d >= {min_distance_m} m)")
    parts = distance_folds(captures.distance_m, idx, int(folds))
    n_zones = captures.hists.shape[1]
    pooled = None
    dist = []
    fold_fits, values, messages = [], [], []
    for k, test in enumerate(parts):
        train = np.setdiff1d(idx, test)
        fit: ZoneFit = fit_plane_zones(captures, arrivals, base, zones=zones, terms=terms, indices=train,
                                       min_distance_m=min_distance_m)
        sensor = zone_sensor(base, fit, floor_counts=None)
        _, per = score_plane(sensor, captures, arrivals, indices=test, min_distance_m=min_distance_m)
        arrays = {key: np.asarray(per[key], dtype=np.float64) for key in ("subbin_err", "peak_bin_err", "l1", "amp_ratio")}
        pooled = arrays if pooled is None else {key: np.concatenate([pooled[key], arrays[key]]) for key in arrays}
        dist += per["distance_m"]
        values.append(fit.values)
        fold_fits.append({"fold": k, "held_out_m": [float(d) for d in captures.distance_m[test]],
                          "deviance": fit.deviance, "converged": fit.converged, "evaluations": fit.evaluations,
                          "seconds": fit.seconds, "values": {n: fit.values[n] for n in REPORTED if n in fit.values}})
        messages += [f"fold {k}: {m}" for m in fit.messages if "did not converge" in m or "bound" in m]
        if progress is not None:
            progress(k + 1, len(parts))
    order = np.argsort(dist, kind="stable")
    per_capture = {"distance_m": [float(dist[i]) for i in order],
                   **{key: np.where(np.isfinite(v[order]), v[order], np.nan).tolist() for key, v in pooled.items()}}
    rows: list[ZoneTable] = zone_tables(pooled, range(n_zones))
    fitted = set(range(n_zones) if zones is None else zones)
    rows = [r for r in rows if r.zone in fitted]
    return PlaneCV(int(folds), rows, per_capture, fold_fits, jackknife(values), messages, time.perf_counter() - t0)
