"""The multi-fidelity design search, as ask/tell (:class:`~nlosplan.planner.protocol.AskTellPlanner`).

:class:`DesignSearch` proposes batches of evaluations (:meth:`~DesignSearch.suggest`)
and takes their results (:meth:`~DesignSearch.ingest`); it never runs anything
itself, so the same search runs serially, on a process pool or on Dask, and
resumes from a log of results (anything already ingested is not suggested
again). Stages:

1. **screen** — the fast bounds (CRLB, ideal observer) on one-at-a-time grids
   along every axis from the reference design, and along jitter and photon
   budget for every zone layout (the trade-off curves).
2. **curves** — trained models at the grid points whose bound meets the
   requirement (a design that fails its bound fails every model: it is
   recorded as screened out, not trained).
3. **refine** — bisection on the continuous axes (jitter, pulse, photons) and bins,
   between the last grid point that meets a requirement and the first that
   does not (the metric is monotone in them), ``refine_steps`` times.
4. **optimize** — for every discrete choice (zones x bin width) and task,
   nlopt COBYLA over normalized continuous variables (jitter, log photons,
   bins) minimizes the cost subject to the bound corrected by the
   bound-to-trained gap measured in stages 1-3 (multi-fidelity).
5. **verify** — the cheapest candidates per task with trained models over
   ``seeds`` seeds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from nlosplan.planner.design.cost import CostModel
from nlosplan.planner.design.evaluators import DEFAULT_FIDELITY
from nlosplan.planner.design.jobs import DesignJob
from nlosplan.planner.design.requirements import Requirement
from nlosplan.planner.design.space import Design, DesignSpace

__all__ = ["SearchConfig", "DesignSearch", "axis_grid", "CONTINUOUS", "MORE_IS_BETTER", "metric_to_score",
           "score_to_metric"]

CONTINUOUS = ("jitter_fwhm_ps", "pulse_fwhm_ps", "photon_fraction")
#: Axes along which a larger value is more (better, costlier) hardware.
MORE_IS_BETTER = {"zones": True, "bin_factor": False, "n_bins": True, "jitter_fwhm_ps": False,
                  "pulse_fwhm_ps": False, "photon_fraction": True}
_CURVE_AXES = ("jitter_fwhm_ps", "photon_fraction")  # also per zone layout


@dataclass(frozen=True)
class SearchConfig:
    """Knobs of the search.

    Parameters
    ----------
    grid_points : int
        Points of each continuous axis grid (and of the bins grid).
    refine_steps : int
        Bisection steps after the grid.
    seeds : int
        Seeds of the verification.
    candidates : int
        Cheapest candidates verified per task.
    optimize_evals : int
        COBYLA evaluations per discrete choice.
    fidelity : dict
        Knobs per evaluator (see :data:`~nlosplan.planner.design.evaluators.DEFAULT_FIDELITY`).
    """

    grid_points: int = 6
    refine_steps: int = 2
    seeds: int = 3
    candidates: int = 2
    optimize_evals: int = 15
    fidelity: dict = field(default_factory=lambda: {k: dict(v) for k, v in DEFAULT_FIDELITY.items()})

    def to_dict(self) -> dict:
        return dict(self.__dict__)


def axis_grid(space: DesignSpace, axis: str, points: int, base: Design) -> list[Design]:
    """Designs along one axis from ``base`` (others fixed), cheapest to costliest order not implied."""
    if axis == "zones":
        return [base.replace(zones=z) for z in space.zones]
    if axis == "bin_factor":  # same window: bins shrink as they widen
        return [base.replace(bin_factor=f, n_bins=max(1, min(space.max_bins(f), base.n_bins * 1 // f)))
                for f in space.bin_factors]
    if axis == "n_bins":
        lo, hi = space.n_bins[0], space.max_bins(base.bin_factor)
        vals = sorted({int(round(v)) for v in np.linspace(lo, hi, points)})
        return [base.replace(n_bins=v) for v in vals]
    lo, hi = getattr(space, axis)
    if axis == "photon_fraction":
        vals = np.geomspace(lo, hi, points)
    else:
        vals = np.linspace(lo, hi, points)
    return [base.replace(**{axis: float(round(v, 6))}) for v in vals]


def _met(req: Requirement, value: float) -> bool:
    return math.isfinite(value) and req.met(value)


class DesignSearch:
    """Ask/tell design search over a space, for a set of requirements.

    Parameters
    ----------
    space : DesignSpace
    requirements : sequence of Requirement
    config : SearchConfig
    references : dict
        Zone layout ``"RxC"`` -> path of its saved reference data (simulated).
    cost : CostModel
    trained_references : dict, optional
        Zone layout -> reference of real captures for the trained evaluator
        (default: the simulated ``references``).
    """

    def __init__(self, space: DesignSpace, requirements, config: SearchConfig, references: dict,
                 cost: CostModel | None = None, trained_references: dict | None = None):
        self.space, self.requirements, self.config = space, list(requirements), config
        self.references = dict(references)
        self.trained_references = dict(trained_references or references)
        self.cost = cost or CostModel()
        self.base = space.reference_design()
        self.results: dict[str, dict] = {}
        self.stage = "screen"
        self._optimized = False
        self.candidates: dict[str, list[dict]] = {}
        self.optimize_log: list[dict] = []

    # ---------------------------------------------------------------- jobs
    def _layout(self, d: Design) -> str:
        return f"{d.zones[0]}x{d.zones[1]}"

    def job(self, evaluator: str, req: Requirement, d: Design, seed: int = 0) -> DesignJob:
        refs = self.trained_references if evaluator == "trained" else self.references
        return DesignJob(evaluator, req.task, d, int(seed),
                         self.config.fidelity["trained" if evaluator == "trained_sim" else evaluator], req.condition,
                         str(refs[self._layout(d)]), self.space.sensor.to_dict())

    def result(self, evaluator: str, req: Requirement, d: Design, seed: int = 0) -> dict | None:
        return self.results.get(self.job(evaluator, req, d, seed).key)

    def lines(self) -> list[tuple[str, str, Design, list[Design]]]:
        """The one-at-a-time lines: (axis, layout label, base, designs)."""
        out = []
        for axis in self.space.axes:
            out.append((axis, self._layout(self.base), self.base,
                        axis_grid(self.space, axis, self.config.grid_points, self.base)))
        for z in self.space.zones:
            if z == self.base.zones:
                continue
            b = self.base.replace(zones=z)
            for axis in _CURVE_AXES:
                if axis in self.space.axes:
                    out.append((axis, self._layout(b), b, axis_grid(self.space, axis, self.config.grid_points, b)))
        return out

    def _line_designs(self) -> list[Design]:
        return list(dict.fromkeys(d for *_, ds in self.lines() for d in ds))

    # ----------------------------------------------------------- ask / tell
    def ingest(self, results) -> None:
        """Record evaluation results (ok, unreachable or failed), in order."""
        for result in results:
            self.results[result["key"]] = result

    def _new(self, jobs: list[DesignJob]) -> list[DesignJob]:
        seen, out = set(), []
        for j in jobs:
            key = j.key
            if key not in self.results and key not in seen:
                seen.add(key)
                out.append(j)
        return out

    def suggest(self, n: int | None = None) -> list[DesignJob]:
        """The next batch of evaluations, at most ``n`` (all of the stage's by default; empty: finished).

        Stages advance when everything they suggested has been ingested; jobs
        already ingested (a resumed run) are never suggested again.
        """
        while True:
            jobs = self._new(self._stage_jobs())
            if jobs:
                return jobs if n is None else jobs[:n]
            if not self._advance():
                return []

    def _stage_jobs(self) -> list[DesignJob]:
        if self.stage == "screen":
            return [self.job("bound", r, d) for r in self.requirements for d in self._line_designs()]
        if self.stage == "curves":
            return [self.job("trained", r, d) for r in self.requirements for d in self._line_designs()
                    if self.bound_meets(r, d)]
        if self.stage == "refine":
            return self._refine_jobs()
        if self.stage == "verify":
            jobs = [self.job("trained", r, c["design"], s) for r in self.requirements
                    for c in self.candidates.get(r.name, []) for s in range(self.config.seeds)]
            if self.has_real:  # the same designs trained on simulated captures: where do sim and real disagree?
                jobs += [self.job("trained_sim", r, d) for r in self.requirements for d in self.trained_designs(r)]
            return jobs
        return []

    def _advance(self) -> bool:
        order = ["screen", "curves", "refine", "optimize", "verify", "done"]
        if self.stage == "done" or (self.stage == "optimize" and not self._optimized):
            return False  # optimize runs in the driver (see run.py), which then calls set_candidates
        self.stage = order[order.index(self.stage) + 1]
        return True

    # --------------------------------------------------------------- stages
    @property
    def has_real(self) -> bool:
        """The trained evaluator reads real captures (and ``trained_sim`` the simulated ones)."""
        return self.trained_references != self.references

    def trained_designs(self, req: Requirement) -> list[Design]:
        """Designs with a successful trained evaluation for ``req``'s task."""
        return sorted({Design.from_dict(r["design"]) for r in self.results.values()
                       if r["task"] == req.task and r["evaluator"] == "trained" and r["status"] == "ok"})

    def disagreements(self, req: Requirement) -> list[dict]:
        """Real against simulated trained metrics of the same designs (real backend only).

        ``disagree`` is True where their 95 % intervals do not overlap.
        """
        rows = []
        for d in self.trained_designs(req):
            real, sim = self.trained_value(req, d), self.result("trained_sim", req, d)
            if real is None or sim is None or sim["status"] != "ok":
                continue
            rows.append({"requirement": req.name, "design": d.key(), "real": real["value"], "real_lo": real["lo"],
                         "real_hi": real["hi"], "sim": sim["value"], "sim_lo": sim["lo"], "sim_hi": sim["hi"],
                         "disagree": bool(real["hi"] < sim["lo"] or sim["hi"] < real["lo"])})
        return rows

    def bound_meets(self, req: Requirement, d: Design) -> bool:
        """Does the design's bound meet the requirement (optimistic side of its interval)?"""
        r = self.result("bound", req, d)
        if r is None or r["status"] != "ok":
            return r is not None and r["status"] == "failed"  # a failed bound does not screen out
        best = r["lo"] if req.smaller_is_better else r["hi"]
        return _met(req, best)

    def trained_value(self, req: Requirement, d: Design) -> dict | None:
        """Mean trained metric over the seeds evaluated, with its interval (None if never trained)."""
        recs = [self.results[k] for k in self._seed_keys(req, d) if k in self.results]
        recs = [r for r in recs if r["status"] == "ok" and math.isfinite(r["value"])]
        if not recs:
            return None
        vals = np.array([r["value"] for r in recs])
        k = len(vals)
        # interval of the seed average: within-seed (bootstrap) and between-seed variance, normal approximation
        se_within = np.array([(r["hi"] - r["lo"]) / (2 * 1.96) for r in recs])
        var_between = vals.var(ddof=1) if k >= 2 else 0.0
        half = 1.96 * math.sqrt(float(np.mean(se_within ** 2)) / k + var_between / k)
        lo, hi = vals.mean() - half, vals.mean() + half
        if not req.smaller_is_better:
            lo, hi = max(lo, 0.0), min(hi, 1.0)
        else:
            lo = max(lo, 0.0)
        return {"value": float(vals.mean()), "lo": float(lo), "hi": float(hi), "seeds": len(vals),
                "seconds": float(sum(r["seconds"] for r in recs))}

    def _seed_keys(self, req, d):
        return [self.job("trained", req, d, s).key for s in range(max(self.config.seeds, 1))]

    def _refine_jobs(self) -> list[DesignJob]:
        jobs = []
        for req in self.requirements:
            for axis, layout, base, designs in self.lines():
                if (axis not in CONTINUOUS and axis != "n_bins") or layout != self._layout(self.base):
                    continue
                pts = self.line_points(req, axis, base)
                grid = set(designs)
                if sum(p["design"] not in grid and (p["trained"] is not None or p["screened"])
                       for p in pts) >= self.config.refine_steps:
                    continue
                bracket = _bracket(pts, req, MORE_IS_BETTER[axis])
                if bracket is None:
                    continue
                a, b = bracket
                if axis == "n_bins":  # whole bins: stop when the bracket is one bin wide
                    mid = int(round(0.5 * (a + b)))
                    if mid in (int(a), int(b)):
                        continue
                    d = base.replace(n_bins=mid)
                else:
                    mid = math.sqrt(a * b) if axis == "photon_fraction" else 0.5 * (a + b)
                    d = base.replace(**{axis: float(round(mid, 6))})
                if self.bound_meets(req, d) or self.result("bound", req, d) is None:
                    if self.result("bound", req, d) is None:
                        jobs.append(self.job("bound", req, d))
                    else:
                        jobs.append(self.job("trained", req, d))
        return jobs

    def line_points(self, req: Requirement, axis: str, base: Design) -> list[dict]:
        """Every evaluated design on the line through ``base`` along ``axis``, sorted by the axis value.

        Each point: ``x`` (axis value in its unit), ``design``, ``bound`` (value or None),
        ``trained`` (:meth:`trained_value` or None), ``screened`` (the bound failed).
        """
        pts = {}
        for r in self.results.values():
            if r["task"] != req.task or r.get("condition") != (None if req.condition is None else str(req.condition)):
                continue
            d = Design.from_dict(r["design"])
            if any(getattr(d, f) != getattr(base, f) for f in ("zones", "bin_factor", "n_bins", "jitter_fwhm_ps",
                                                                "pulse_fwhm_ps", "photon_fraction")
                   if f != axis and not (axis == "bin_factor" and f == "n_bins")):
                continue
            if axis == "bin_factor" and d.n_bins != max(1, min(self.space.max_bins(d.bin_factor), base.n_bins // d.bin_factor)):
                continue
            if d in pts:
                continue
            bound = self.result("bound", req, d)
            pts[d] = {"x": d.value(axis, self.space.sensor), "design": d,
                      "bound": None if bound is None or bound["status"] != "ok" else bound["value"],
                      "bound_status": None if bound is None else bound["status"],
                      "bound_reason": "" if bound is None else bound["reason"],
                      "trained": self.trained_value(req, d),
                      "screened": bound is not None and bound["status"] == "ok" and not self.bound_meets(req, d)}
        return sorted(pts.values(), key=lambda p: p["x"])

    # ------------------------------------------------------- multi-fidelity
    def gap(self, req: Requirement) -> dict:
        """The bound-to-trained gap of a task over every design evaluated by both.

        Localization: the median log ratio trained / bound; accuracies: the
        median logit difference. ``n`` pairs, and ``spread`` (their IQR).
        """
        diffs = []
        for d in {Design.from_dict(r["design"]) for r in self.results.values() if r["task"] == req.task}:
            b, t = self.result("bound", req, d), self.trained_value(req, d)
            if b is None or t is None or b["status"] != "ok" or not math.isfinite(b["value"]):
                continue
            diffs.append(metric_to_score(req, t["value"]) - metric_to_score(req, b["value"]))
        if not diffs:
            return {"value": 0.0, "n": 0, "spread": math.nan}
        q1, med, q3 = np.percentile(diffs, [25, 50, 75])
        return {"value": float(med), "n": len(diffs), "spread": float(q3 - q1)}

    def predict(self, req: Requirement, bound_value: float) -> float:
        """The trained metric predicted from a bound value and the measured gap."""
        return score_to_metric(req, metric_to_score(req, bound_value) + self.gap(req)["value"])

    def set_candidates(self, candidates: dict[str, list[dict]], log: list[dict]) -> None:
        """Candidates per requirement name from the optimize stage (see :func:`optimize.run_optimize`)."""
        self.candidates = candidates
        self.optimize_log = log
        self._optimized = True


def metric_to_score(req: Requirement, v: float) -> float:
    """The scale the gap and interpolation work on: log RMSE, or logit accuracy (clipped to [0.001, 0.999])."""
    if req.smaller_is_better:
        return math.log(max(v, 1e-9))
    p = min(max(v, 1e-3), 1 - 1e-3)
    return math.log(p / (1 - p))


def score_to_metric(req: Requirement, z: float) -> float:
    """Inverse of :func:`metric_to_score`."""
    if req.smaller_is_better:
        return math.exp(z)
    return 1.0 / (1.0 + math.exp(-z))


def _bracket(points: list[dict], req: Requirement, more_is_better: bool):
    """Adjacent axis values (meets, misses) by the trained metric, or None."""
    seq = [p for p in points if p["trained"] is not None or p["screened"]]
    if not more_is_better:
        seq = seq[::-1]  # walk from the cheapest end (more jitter) to the costliest
    # now: along seq hardware increases; find the first index that meets
    for i in range(1, len(seq)):
        prev_ok = seq[i - 1]["trained"] is not None and _met(req, seq[i - 1]["trained"]["value"])
        cur_ok = seq[i]["trained"] is not None and _met(req, seq[i]["trained"]["value"])
        if cur_ok and not prev_ok:
            a, b = seq[i]["x"], seq[i - 1]["x"]
            if abs(a - b) <= 1e-6 * max(abs(a), abs(b), 1.0):
                return None
            return a, b
    return None
