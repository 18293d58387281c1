"""Active capture planning against DENALI's raster, on a simulated rig.

Design
------
One hidden object (default letter A, 8 in, lights off, TMF8828 3x3) on the
DENALI gantry. Candidates: a ``grid x grid`` lattice over the 0-320 mm
travel (19 x 19 by default: DENALI's 10 x 10 points and the points between
them), screened by the keep-out rules. The simulated rig's truth differs
from the planner's nominal model by a calibration ``theta_true``
(registration offset, photon scale, albedo; see
:mod:`nlosplan.planner.capture.simrig`). Each strategy runs the ask/tell
loop (batches of ``batch_size``, route-ordered, gantry time from the
feed/acceleration model) up to ``budget`` captures, once per seed (the
seed draws the Poisson noise and the planner's random state). After every
batch:

- localization RMSE (DENALI's ``loc_rmse``, x and y errors pooled; the
  curve's ``rmse_m`` and the targets ``target_rmse_m`` are in it) of the
  planner's ensemble localizer on a fixed set of noisy test captures at
  ``test_points`` quasi-random positions (not on the candidate grid);
- calibration error of the maximum-likelihood calibration, the largest
  parameter error in units of its tolerance (0.5 mm, 0.5 mm, 1 %, 1 %).

A run stops when the tightest localization target and the calibration
target are both reached. A strategy's *captures to target* is the first capture count at which the
metric reaches the target (and the gantry seconds spent by then). The
interval is the minimum and maximum over seeds; a seed that never reaches
the target within the budget counts as not reached (``None``).
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, fields
from typing import Callable

import numpy as np

from nlosplan.errors import UserError, check_keys

__all__ = ["ActiveStudy", "prepare_world", "run_active_study", "summarise", "to_target"]


@dataclass(frozen=True)
class ActiveStudy:
    """Settings of the active-vs-raster study (see the module notes)."""

    strategies: tuple = ("raster", "random", "active", "active-motion", "doptimal", "doptimal-motion")
    seeds: tuple = (0, 1, 2)
    obj: str = "A"
    size: str = "8in"
    sensor: str = "tmf8828-3x3-short"
    fidelity: str = "draft"
    grid: int = 19
    test_points: int = 40
    budget: int = 100
    batch_size: int = 5
    repeats: int = 3
    target_rmse_m: float = 0.05  # nlosplan design's default localization requirement and rig run's example
    more_targets_m: tuple = (0.03, 0.04)
    target_calibration: float = 1.0
    theta_true: tuple = (0.003, -0.002, 0.1, -0.15)
    feed_mm_s: float = 20.0
    accel_mm_s2: float = 50.0
    settle_s: float = 0.5
    capture_s: float = 1.0

    def __post_init__(self) -> None:
        from nlosplan.planner.capture import STRATEGIES

        bad = [s for s in self.strategies if s not in STRATEGIES]
        if bad or not self.strategies:
            raise UserError(f"unknown strategy {', '.join(bad) or '(none)'}; allowed: {', '.join(STRATEGIES)}")
        if not self.seeds:
            raise UserError("give at least one seed")
        if self.grid < 2 or self.test_points < 2 or self.budget < 1 or self.batch_size < 1 or self.repeats < 1:
            raise UserError("grid and test_points must be >= 2; budget, batch_size and repeats >= 1")
        if not (self.target_rmse_m > 0 and self.target_calibration > 0):
            raise UserError("targets must be > 0")
        object.__setattr__(self, "strategies", tuple(self.strategies))
        object.__setattr__(self, "seeds", tuple(int(s) for s in self.seeds))
        object.__setattr__(self, "theta_true", tuple(float(v) for v in self.theta_true))
        object.__setattr__(self, "more_targets_m", tuple(float(v) for v in self.more_targets_m))
        if any(not v > 0 for v in self.more_targets_m):
            raise UserError("more_targets_m must all be > 0")

    @classmethod
    def from_dict(cls, d: dict) -> "ActiveStudy":
        """From a mapping (e.g. a TOML table); unknown keys are an error."""
        check_keys(d, sorted(f.name for f in fields(cls)), "study setting(s)")
        return cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in d.items()})


def prepare_world(study: ActiveStudy):
    """Candidates (screened), the planner's counts model and the simulated rig.

    Returns
    -------
    space : CandidateSpace
    rig : SimulatedRig
    seconds : float
    """
    from nlosplan.planner.capture import (MotionModel, build_space, denali_scene_fn, grid_points, region_points,
                                          screen_candidates)
    from nlosplan.planner.capture.simrig import build_simulated_rig
    from nlosplan.sensor_models import preset

    t0 = time.perf_counter()
    sensor = preset(study.sensor).linear_uniform()  # the capture planner's counts model is linear, zone-uniform
    scene_fn = denali_scene_fn(study.obj, study.size, "off")
    cand = screen_candidates(grid_points(study.grid, study.grid), scene_fn=scene_fn, sensor=sensor)
    space = build_space(cand.points_mm, sensor, scene_fn=scene_fn, fidelity=study.fidelity, repeats=study.repeats,
                        excluded=cand.excluded)
    motion = MotionModel(study.feed_mm_s, study.accel_mm_s2, study.settle_s, study.capture_s)
    rig = build_simulated_rig(space, sensor, study.theta_true, region_points(study.test_points, seed=7),
                              scene_fn=scene_fn, fidelity=study.fidelity, motion=motion)
    return space, rig, time.perf_counter() - t0


def _run_one(space, rig, test_obs, study: ActiveStudy, strategy: str, seed: int) -> dict:
    """One strategy, one seed: the ask/tell loop with the metrics after every batch."""
    from nlosplan.planner.capture import CapturePlanner, PlannerConfig, calibration_error

    t0 = time.perf_counter()
    planner = CapturePlanner(space, PlannerConfig(strategy=strategy, batch_size=study.batch_size,
                                                  budget=study.budget, seed=seed, motion=rig.motion))
    rng = np.random.default_rng(10_000 + seed)
    curve, pos = [], np.zeros(2)
    while True:
        batch = planner.suggest()
        if not batch:
            break
        results = []
        for p in batch:
            here = np.array([p["x_mm"], p["y_mm"]])
            results.append({"id": p["id"], "histogram": rig.observe([p["index"]], rng)[0],
                            "seconds": rig.motion.route_seconds(pos, here[None]), "position_mm": here})
            pos = here
        planner.ingest(results)
        rmse = planner.localizer().loc_rmse(test_obs, rig.test_labels)
        cal = calibration_error(planner.calibration()["theta"], rig.theta_true)
        curve.append({"captures": len(planner.observations), "gantry_seconds": planner.gantry_seconds,
                      "rmse_m": rmse, "calibration_error": cal})
        if rmse <= min((study.target_rmse_m,) + study.more_targets_m) and cal <= study.target_calibration:
            planner.stop("both targets reached")
    return {"strategy": strategy, "seed": seed, "curve": curve, "seconds": time.perf_counter() - t0,
            "finished": planner.finished,
            "positions_mm": [space.points_mm[o["index"]].tolist() for o in planner.observations]}


def to_target(curve: list, key: str, target: float) -> tuple[int | None, float | None]:
    """First (captures, gantry seconds) of a curve at which ``curve[key] <= target``; (None, None) if never."""
    for row in curve:
        if row[key] <= target:
            return row["captures"], row["gantry_seconds"]
    return None, None


def _stat(values: list) -> dict:
    got = [v for v in values if v is not None]
    if not got:
        return {"median": None, "interval": [None, None], "reached": 0}
    return {"median": float(np.median(got)) if len(got) == len(values) else None,
            "interval": [float(min(got)), float(max(got)) if len(got) == len(values) else None],
            "reached": len(got)}


def summarise(runs: list, study: ActiveStudy) -> list[dict]:
    """Per strategy: captures and gantry seconds to each target, median and [min, max] over seeds.

    A median or an upper end is ``None`` when some seed did not reach the target within the budget.
    """
    out = []
    for name in study.strategies:
        mine = [r for r in runs if r["strategy"] == name]
        loc = [to_target(r["curve"], "rmse_m", study.target_rmse_m) for r in mine]
        cal = [to_target(r["curve"], "calibration_error", study.target_calibration) for r in mine]
        lc, ls, cc, cs = (_stat([t[i] for t in ts]) for ts, i in ((loc, 0), (loc, 1), (cal, 0), (cal, 1)))
        out.append({"name": name, "captures_to_target": lc["median"], "gantry_seconds_to_target": ls["median"],
                    "interval": lc["interval"], "gantry_interval": ls["interval"], "seeds_reached": lc["reached"],
                    "calibration": {"captures_to_target": cc["median"], "interval": cc["interval"],
                                    "gantry_seconds_to_target": cs["median"], "gantry_interval": cs["interval"],
                                    "seeds_reached": cc["reached"]},
                    "targets": [_at(mine, t) for t in sorted({study.target_rmse_m, *study.more_targets_m})],
                    "seconds": float(sum(r["seconds"] for r in mine))})
    return out


def _at(runs: list, target: float) -> dict:
    """Captures and gantry seconds to one localization target (median, [min, max] over seeds)."""
    hits = [to_target(r["curve"], "rmse_m", target) for r in runs]
    c, s = _stat([h[0] for h in hits]), _stat([h[1] for h in hits])
    return {"target_rmse_m": target, "captures_to_target": c["median"], "interval": c["interval"],
            "gantry_seconds_to_target": s["median"], "gantry_interval": s["interval"], "seeds_reached": c["reached"]}


def best_to_raster(summary: list) -> dict:
    """Per localization target: the best strategy's median captures divided by the raster's (None if either
    did not reach it in every seed)."""
    out = {}
    raster = next((s for s in summary if s["name"] == "raster"), None)
    if raster is None:
        return out
    for k, t in enumerate(raster["targets"]):
        base = t["captures_to_target"]
        others = [(s["targets"][k]["captures_to_target"], s["name"]) for s in summary
                  if s["name"] != "raster" and s["targets"][k]["captures_to_target"] is not None]
        best = min(others) if others else None
        out[f"{t['target_rmse_m']:g}"] = (None if base is None or best is None
                                         else {"ratio": best[0] / base, "best": best[1], "captures": best[0],
                                               "raster_captures": base})
    return out


def run_active_study(study: ActiveStudy, *, progress: Callable[[dict], None] | None = None) -> dict:
    """Run every strategy and seed on one simulated world.

    Returns
    -------
    dict
        ``strategies`` (see :func:`summarise`), ``runs`` (every curve), ``config``,
        ``ratio_best_to_raster`` (captures to the localization target, medians), ``world_seconds``,
        ``seconds``, ``candidates``, ``excluded``, ``versions``.
    """
    import platform

    t0 = time.perf_counter()
    space, rig, world_s = prepare_world(study)
    test_obs = rig.test_set()
    if progress:
        progress({"event": "world", "seconds": world_s, "candidates": space.size})
    runs = []
    total = len(study.strategies) * len(study.seeds)
    for name in study.strategies:
        for seed in study.seeds:
            run = _run_one(space, rig, test_obs, study, name, seed)
            runs.append(run)
            if progress:
                progress({"event": "run", "index": len(runs), "total": total, **{k: run[k] for k in
                                                                                   ("strategy", "seed", "seconds")}})
    summary = summarise(runs, study)
    ratio = best_to_raster(summary)
    import subprocess

    import casadi
    import jax

    try:
        rev = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, timeout=5,
                             cwd=__file__.rsplit("/", 3)[0]).stdout.strip() or None
    except (OSError, subprocess.SubprocessError):
        rev = None

    return {"strategies": summary, "runs": runs, "config": asdict(study), "ratio_best_to_raster": ratio,
            "world_seconds": world_s, "seconds": time.perf_counter() - t0, "candidates": space.size,
            "excluded": space.excluded,
            "versions": {"python": platform.python_version(), "numpy": np.__version__, "jax": jax.__version__,
                         "casadi": casadi.__version__, "git": rev}}
