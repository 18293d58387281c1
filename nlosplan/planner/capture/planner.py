"""The capture planner: ask/tell, JSON checkpoint and resume, failed captures recorded.

Use::

    planner = CapturePlanner(space, PlannerConfig(strategy="active-motion", batch_size=5, budget=40))
    while (batch := planner.suggest()):
        results = [{"id": p["id"], "histogram": rig.capture(p)} for p in batch]   # or {"id", "error"}
        planner.ingest(results)
        planner.save("plan.json")
    print(planner.finished, planner.best())

``suggest`` returns an empty list and sets :attr:`CapturePlanner.finished`
(a reason) when it has nothing worth proposing: the budget is spent, the
candidates are used up, or a target was reached (:meth:`stop`).
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from nlosplan.errors import UserError
from nlosplan.files import write_json
from nlosplan.planner.capture.calibration import (DEFAULT_PRIOR_STD, fit_counts_model, prior_information)
from nlosplan.planner.capture.ensemble import EnsembleLocalizer
from nlosplan.planner.capture.motion import MotionModel
from nlosplan.planner.capture.route import order_batch
from nlosplan.planner.capture.strategies import STRATEGIES, choose, raster_order

__all__ = ["CHECKPOINT_FORMAT", "CapturePlanner", "PlannerConfig"]

CHECKPOINT_FORMAT = "nlosplan-capture-planner/1"
#: A candidate whose capture failed this many times is not proposed again.
MAX_FAILURES = 2


@dataclass(frozen=True)
class PlannerConfig:
    """Settings of a capture planner.

    Parameters
    ----------
    strategy : str
        One of :data:`~nlosplan.planner.capture.strategies.STRATEGIES`.
    batch_size : int
        Positions per :meth:`CapturePlanner.suggest` (default).
    budget : int or None
        Most positions to capture in all (None: until the candidates run out).
    seed : int
        Random state of the planner (random strategy, ensemble priors).
    members : int
        Ensemble size of the localization model.
    noise_m : float
        Localization noise scale of the active strategies' information, m.
    motion : MotionModel
    start_mm : tuple of float
        Gantry position before the first move, mm.
    """

    strategy: str = "active-motion"
    batch_size: int = 5
    budget: int | None = None
    seed: int = 0
    members: int = 8
    noise_m: float = 0.005
    motion: MotionModel = field(default_factory=MotionModel)
    start_mm: tuple = (0.0, 0.0)

    def __post_init__(self) -> None:
        if self.strategy not in STRATEGIES:
            raise UserError(f"unknown planner strategy {self.strategy!r}; allowed: {', '.join(STRATEGIES)}")
        if int(self.batch_size) < 1:
            raise UserError(f"batch_size={self.batch_size} must be >= 1")
        if self.budget is not None and int(self.budget) < 1:
            raise UserError(f"budget={self.budget} must be >= 1 (or None)")
        if not self.noise_m > 0:
            raise UserError(f"noise_m={self.noise_m} must be > 0")
        if isinstance(self.motion, dict):
            object.__setattr__(self, "motion", MotionModel(**self.motion))
        object.__setattr__(self, "start_mm", tuple(float(v) for v in self.start_mm))

    def to_dict(self) -> dict:
        """JSON form."""
        d = asdict(self)
        d["start_mm"] = list(self.start_mm)
        return d


class CapturePlanner:
    """Ask/tell capture planner over a :class:`~nlosplan.planner.capture.space.CandidateSpace`.

    Parameters
    ----------
    space : CandidateSpace
    config : PlannerConfig
    """

    def __init__(self, space, config: PlannerConfig | None = None):
        self.space = space
        self.config = config or PlannerConfig()
        self.rng = np.random.default_rng(self.config.seed)
        self.position_mm = np.array(self.config.start_mm, dtype=np.float64)
        self.proposals: dict[str, dict] = {}
        self.observations: list[dict] = []
        self.failures: list[dict] = []
        self.finished: str | None = None
        self.gantry_seconds = 0.0
        self._next = 0
        self._raster = raster_order(space.points_mm)
        self._calib: dict | None = None
        self._localizer: EnsembleLocalizer | None = None

    # ------------------------------------------------------------------ state
    @property
    def captured(self) -> np.ndarray:
        """Candidate index of every observation, shape (N,)."""
        return np.array([o["index"] for o in self.observations], dtype=int)

    def _allowed(self) -> np.ndarray:
        ok = np.ones(self.space.size, bool)
        ok[self.captured] = False
        for p in self.proposals.values():
            if p["status"] == "pending":
                ok[p["index"]] = False
        fails = np.bincount([f["index"] for f in self.failures], minlength=self.space.size)
        ok[fails >= MAX_FAILURES] = False
        if self.config.strategy == "raster":
            on = np.zeros(self.space.size, bool)
            on[self._raster] = True
            ok &= on
        return ok

    def _observed(self) -> np.ndarray:
        """Observations, shape (N, K)."""
        k = int(np.prod(self.space.shape))
        return np.array([o["histogram"] for o in self.observations], dtype=np.float64).reshape(-1, k)

    def calibration(self) -> dict:
        """Maximum-likelihood calibration from the observations (cached until the next ingest)."""
        if self._calib is None:
            self._calib = fit_counts_model(self.space, self.captured, self._observed())
        return self._calib

    def localizer(self) -> EnsembleLocalizer:
        """The ensemble localization model fitted on the observations (cached until the next ingest)."""
        if self._localizer is None:
            ref = self.space.counts().mean(axis=0)
            loc = EnsembleLocalizer(ref, members=self.config.members, seed=self.config.seed)
            idx = self.captured
            self._localizer = loc.fit(self._observed(), self.space.labels_xy[idx])
        return self._localizer

    # ------------------------------------------------------------------ ask
    def suggest(self, n: int | None = None) -> list[dict]:
        """Propose the next batch, ordered into a route from the current gantry position.

        Parameters
        ----------
        n : int, optional
            Batch size (default ``config.batch_size``; cut to the budget left).

        Returns
        -------
        list of dict
            ``id`` (str), ``index`` (candidate), ``x_mm``, ``y_mm``, ``label_xy`` (m), in visiting
            order; empty when :attr:`finished` says why nothing is proposed.
        """
        n = int(self.config.batch_size if n is None else n)
        if n < 1:
            raise UserError(f"batch size n={n} must be >= 1")
        if self.finished:
            return []
        pending = sum(p["status"] == "pending" for p in self.proposals.values())
        if self.config.budget is not None:
            left = int(self.config.budget) - len(self.observations) - pending
            if left <= 0:
                if not pending:
                    self.finished = f"budget of {self.config.budget} captures spent"
                return []
            n = min(n, left)
        allowed = self._allowed()
        if not allowed.any():
            if not pending:
                self.finished = "no candidate positions left"
            return []
        calib = self.calibration()
        theta = calib["theta"]
        batch, note = choose(self.config.strategy, n, space=self.space, allowed=allowed, rng=self.rng,
                             raster=self._raster,
                             localizer=self.localizer() if self.config.strategy.startswith("active") else None,
                             theta=theta, held_info=calib["fisher"], prior_info=prior_information(DEFAULT_PRIOR_STD),
                             noise_m=self.config.noise_m, motion=self.config.motion, position_mm=self.position_mm)
        pts = self.space.points_mm[batch]
        if self.config.strategy != "raster":
            order, _, _ = order_batch(self.position_mm, pts, self.config.motion)
            batch = [batch[i] for i in order]
        out = []
        for k, i in enumerate(batch):
            pid = f"c{self._next:05d}"
            self._next += 1
            prop = {"id": pid, "index": int(i), "x_mm": float(self.space.points_mm[i, 0]),
                    "y_mm": float(self.space.points_mm[i, 1]), "label_xy": self.space.labels_xy[i].tolist(),
                    "status": "pending", "batch_order": k, **note}
            self.proposals[pid] = prop
            out.append({k2: v for k2, v in prop.items() if k2 != "status"})
        return out

    # ------------------------------------------------------------------ ingest
    def ingest(self, results) -> None:
        """Record capture results.

        Parameters
        ----------
        results : iterable of dict
            ``{"id", "histogram"}`` (mean counts of the repeats, ``(rows, cols, bins)`` or flat) for a
            capture taken, ``{"id", "error": reason}`` for one that failed; optional ``seconds`` (gantry
            and capture time spent) and ``position_mm`` (where the gantry is now).

        Raises
        ------
        UserError
            An unknown or already-ingested id, or a histogram of the wrong size.
        """
        k = int(np.prod(self.space.shape))
        for r in results:
            pid = r.get("id")
            prop = self.proposals.get(pid)
            if prop is None:
                raise UserError(f"capture id {pid!r} was not proposed by this planner")
            if prop["status"] != "pending":
                raise UserError(f"capture id {pid!r} was already ingested ({prop['status']})")
            if "error" in r:
                prop["status"] = "failed"
                self.failures.append({"id": pid, "index": prop["index"], "reason": str(r["error"])})
            else:
                h = np.asarray(r["histogram"], dtype=np.float64).reshape(-1)
                if h.size != k or not np.all(np.isfinite(h)):
                    raise UserError(f"capture {pid}: histogram must hold {k} finite counts, got {h.size}")
                prop["status"] = "done"
                self.observations.append({"id": pid, "index": prop["index"], "histogram": h})
            self.gantry_seconds += float(r.get("seconds", 0.0))
            if r.get("position_mm") is not None:
                self.position_mm = np.asarray(r["position_mm"], dtype=np.float64).reshape(2)
            else:
                self.position_mm = np.array([prop["x_mm"], prop["y_mm"]])
        self._calib = self._localizer = None

    def amend(self, ids, *, drop=(), add=(), check_only: bool = False) -> list[dict]:
        """Edit a pending batch before it runs (the approval gate): drop proposals, add candidates.

        Parameters
        ----------
        ids : sequence of str
            The ids of the pending batch, as :meth:`suggest` returned it.
        drop : sequence of str
            Ids of the batch not to capture: their status becomes ``"dropped"``
            (not a failure; the candidate may be proposed again).
        add : sequence of int
            Candidate indices to capture as well: free candidates only (not
            captured, not pending, not given up), within the budget left.
        check_only : bool
            Only check the edit (raise if it is not allowed); change nothing, return [].

        Returns
        -------
        list of dict
            The edited batch, route-ordered from the current gantry position,
            in :meth:`suggest`'s form (new ids for the added candidates).

        Raises
        ------
        UserError
            An id not in the batch, an index that is not a free candidate, more
            positions than the budget allows, or nothing left to capture.
        """
        ids, drop = [str(i) for i in ids], [str(i) for i in drop]
        add = [int(i) for i in add]
        for pid in ids:
            if self.proposals.get(pid, {}).get("status") != "pending":
                raise UserError(f"capture id {pid!r} is not a pending proposal of this planner")
        bad = [pid for pid in drop if pid not in ids]
        if bad:
            raise UserError(f"cannot drop {', '.join(bad)}: not in the batch ({', '.join(ids)})")
        if len(set(add)) != len(add):
            raise UserError("a candidate is added twice")
        allowed = self._allowed()
        for i in add:
            if not 0 <= i < self.space.size:
                raise UserError(f"candidate {i} does not exist (0..{self.space.size - 1})")
            if not allowed[i]:
                raise UserError(f"candidate {i} at ({self.space.points_mm[i, 0]:g}, {self.space.points_mm[i, 1]:g}) mm "
                                "is not free (captured, proposed, given up, or off the raster)")
        kept = [pid for pid in ids if pid not in drop]
        if self.config.budget is not None:
            pending = sum(p["status"] == "pending" for p in self.proposals.values()) - len(drop)
            left = int(self.config.budget) - len(self.observations) - pending
            if len(add) > left:
                raise UserError(f"{len(add)} positions added but the budget leaves room for {max(left, 0)} more")
        if not kept and not add:
            raise UserError("the edited batch is empty; refuse the batch instead")
        if check_only:
            return []
        for pid in drop:
            self.proposals[pid]["status"] = "dropped"
        for i in add:
            pid = f"c{self._next:05d}"
            self._next += 1
            self.proposals[pid] = {"id": pid, "index": i, "x_mm": float(self.space.points_mm[i, 0]),
                                   "y_mm": float(self.space.points_mm[i, 1]),
                                   "label_xy": self.space.labels_xy[i].tolist(), "status": "pending",
                                   "batch_order": 0, "added": True}
            kept.append(pid)
        pts = np.array([[self.proposals[p]["x_mm"], self.proposals[p]["y_mm"]] for p in kept])
        if self.config.strategy != "raster" or add:
            order, _, _ = order_batch(self.position_mm, pts, self.config.motion)
            kept = [kept[i] for i in order]
        out = []
        for k, pid in enumerate(kept):
            self.proposals[pid]["batch_order"] = k
            out.append({k2: v for k2, v in self.proposals[pid].items() if k2 != "status"})
        return out

    def stop(self, reason: str) -> None:
        """Propose nothing more (e.g. the target was reached)."""
        self.finished = str(reason)

    def best(self) -> dict:
        """What the planner knows now: captures, failures, the calibration and the localizer's training size."""
        c = self.calibration()
        return {"strategy": self.config.strategy, "captures": len(self.observations), "failed": len(self.failures),
                "gantry_seconds": self.gantry_seconds, "position_mm": self.position_mm.tolist(),
                "calibration": {"theta": c["theta"].tolist(), "std": c["std"].tolist(),
                                "parameters": ["dx_m", "dy_m", "log_photon_scale", "log_albedo"],
                                "identifiable": c["identifiable"], "reason": c["reason"]},
                "finished": self.finished}

    # ------------------------------------------------------------------ checkpoint
    def state_dict(self) -> dict:
        """Everything needed to resume, as JSON-ready data."""
        return {"format": CHECKPOINT_FORMAT, "config": self.config.to_dict(),
                "space": {"fingerprint": self.space.fingerprint(), "candidates": self.space.size,
                          "meta": self.space.meta, "points_mm": np.round(self.space.points_mm, 4).tolist(),
                          "excluded": list(self.space.excluded)},
                "rng": self.rng.bit_generator.state, "next_id": self._next,
                "position_mm": self.position_mm.tolist(), "gantry_seconds": self.gantry_seconds,
                "finished": self.finished, "proposals": list(self.proposals.values()),
                "observations": [{"id": o["id"], "index": o["index"], "histogram": o["histogram"].tolist()}
                                 for o in self.observations],
                "failures": self.failures}

    def save(self, path, extra: dict | None = None) -> Path:
        """Write :meth:`state_dict` to ``path`` atomically (a temporary file, then rename).

        ``extra`` adds top-level entries (e.g. a closed loop's history); :meth:`load` ignores them.
        """
        return write_json(path, {**(extra or {}), **self.state_dict()})

    @classmethod
    def load(cls, path, space) -> "CapturePlanner":
        """Resume from a checkpoint written by :meth:`save` over the same candidates."""
        try:
            state = json.loads(Path(path).read_text(encoding="utf-8"))
        except (OSError, json.JSONDecodeError) as exc:
            raise UserError(f"cannot read planner checkpoint {path}: {exc}") from None
        return cls.from_state(state, space)

    @classmethod
    def from_state(cls, state: dict, space) -> "CapturePlanner":
        """Rebuild a planner from :meth:`state_dict`."""
        if not isinstance(state, dict) or state.get("format") != CHECKPOINT_FORMAT:
            raise UserError(f"not a capture-planner checkpoint (format must be {CHECKPOINT_FORMAT!r})")
        if state["space"]["fingerprint"] != space.fingerprint():
            raise UserError("the checkpoint was made over other candidate positions; rebuild the same candidates "
                            "(grid, limits, keep-out) to resume")
        planner = cls(space, PlannerConfig(**state["config"]))
        planner.rng.bit_generator.state = state["rng"]
        planner._next = int(state["next_id"])
        planner.position_mm = np.asarray(state["position_mm"], dtype=np.float64)
        planner.gantry_seconds = float(state["gantry_seconds"])
        planner.finished = state["finished"]
        planner.proposals = {p["id"]: dict(p) for p in state["proposals"]}
        planner.observations = [{"id": o["id"], "index": int(o["index"]),
                                 "histogram": np.asarray(o["histogram"], dtype=np.float64)}
                                for o in state["observations"]]
        planner.failures = list(state["failures"])
        return planner
