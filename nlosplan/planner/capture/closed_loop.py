"""The planner in closed loop with a rig: suggest/ingest callables for an ask/tell capture plan.

:class:`ClosedLoop` adapts a :class:`~nlosplan.planner.capture.planner.CapturePlanner`
to :func:`nlosplan.hardware.plans.ask_tell_plan` (which yields the moves and
captures; the executor runs them): ``suggest(n)`` asks the planner for a
batch (and, with an approval callback, asks a person first), ``ingest``
averages each position's repeats, ingests them into the planner, refits the model and the
calibration, records the progress, checkpoints the planner, and stops the
loop when the localization target is reached. The target is checked on a
cross-validated localization RMSE (DENALI's ``loc_rmse``: x and y errors
pooled) of the ensemble localizer over the captures so far (a real rig has
no separate test set).
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from nlosplan.errors import UserError
from nlosplan.planner.capture.ensemble import EnsembleLocalizer

__all__ = ["ClosedLoop", "cv_loc_rmse"]


def cv_loc_rmse(planner, folds: int = 5, seed: int = 0) -> float:
    """K-fold cross-validated ``loc_rmse`` (DENALI's, x and y pooled) of the planner's ensemble, m (inf if < 2 K)."""
    idx = planner.captured
    if len(idx) < 2 * folds:
        return float("inf")
    obs = planner._observed()
    labels = planner.space.labels_xy[idx]
    ref = planner.space.counts().mean(axis=0)
    order = np.random.default_rng(seed).permutation(len(idx))
    err = []
    for k in range(folds):
        test = order[k::folds]
        train = np.setdiff1d(order, test)
        loc = EnsembleLocalizer(ref, members=planner.config.members, seed=planner.config.seed)
        loc.fit(obs[train], labels[train])
        err.append((loc.predict(obs[test]) - labels[test]) ** 2)
    return float(np.sqrt(np.concatenate(err).mean()))  # mean over the N x 2 entries: loc_rmse


class ClosedLoop:
    """Suggest/ingest callables around a capture planner (:class:`~nlosplan.planner.protocol.AskTellPlanner`).

    Parameters
    ----------
    planner : CapturePlanner
    target_rmse_m : float, optional
        Stop when the cross-validated ``loc_rmse`` (m) reaches it.
    approve : callable, optional
        ``approve(batch, planner)`` before anything moves: True runs the batch, False stops the
        loop, a dict ``{"drop": [ids], "add": [candidate indices]}`` runs the batch so edited
        (:meth:`CapturePlanner.amend`).
    checkpoint : path, optional
        The planner's JSON checkpoint with the loop's history (``loop``), written after every
        suggestion (the pending batch) and every ingest.
    on_batch : callable, optional
        Called with each history row.
    """

    def __init__(self, planner, *, target_rmse_m: float | None = None,
                 approve: Callable[[list, object], bool] | None = None, checkpoint=None,
                 on_batch: Callable[[dict], None] | None = None):
        self.planner = planner
        self.target = target_rmse_m
        self.approve = approve
        self.checkpoint = checkpoint
        self.on_batch = on_batch
        self.history: list[dict] = []
        self._pending: list[dict] = []

    def save(self) -> None:
        """Write the checkpoint (when one is set): the planner's state and ``loop`` (target, history)."""
        if self.checkpoint is not None:
            self.planner.save(self.checkpoint, extra={"loop": {"target_rmse_m": self.target,
                                                               "history": self.history}})

    def suggest(self, n: int) -> list[tuple[float, float]]:
        """The next batch as (x_mm, y_mm) in route order; empty ends the plan."""
        batch = self.planner.suggest(n)
        if batch:
            self.save()
        verdict = True if not batch or self.approve is None else self.approve(batch, self.planner)
        if isinstance(verdict, dict):
            batch = self.planner.amend([p["id"] for p in batch], drop=verdict.get("drop", ()),
                                       add=verdict.get("add", ()))
            self.save()
        elif not verdict:
            self.planner.stop("batch not approved")
            for p in batch:
                self.planner.proposals[p["id"]]["status"] = "rejected"
            self.save()
            return []
        self._pending = batch
        return [(p["x_mm"], p["y_mm"]) for p in batch]

    def ingest(self, told) -> None:
        """Ingest ``[((x, y), [CaptureResult, ...]), ...]`` in the order suggested."""
        if len(told) != len(self._pending):
            raise UserError(f"the plan told {len(told)} positions back for a batch of {len(self._pending)}")
        results = []
        for prop, ((x, y), caps) in zip(self._pending, told):
            if abs(x - prop["x_mm"]) > 1e-6 or abs(y - prop["y_mm"]) > 1e-6:
                raise UserError(f"told position ({x}, {y}) mm is not the suggested ({prop['x_mm']}, {prop['y_mm']})")
            hists = [c.histogram for c in caps if getattr(c, "histogram", None) is not None]
            if not hists:
                results.append({"id": prop["id"], "error": "no histogram (dry run or failed capture)"})
                continue
            pos = caps[-1].reported_mm or caps[-1].commanded_mm
            results.append({"id": prop["id"], "histogram": np.mean(np.asarray(hists, dtype=np.float64), axis=0),
                            "position_mm": pos})
        self._pending = []
        self.planner.ingest(results)
        calib = self.planner.calibration()
        row = {"captures": len(self.planner.observations), "failed": len(self.planner.failures),
               "cv_loc_rmse_m": cv_loc_rmse(self.planner), "calibration_theta": calib["theta"].tolist(),
               "calibration_std": calib["std"].tolist()}
        self.history.append(row)
        if self.target is not None and row["cv_loc_rmse_m"] <= self.target:
            self.planner.stop(f"target reached: cross-validated loc_rmse {1e3 * row['cv_loc_rmse_m']:.1f} mm "
                              f"<= {1e3 * self.target:g} mm")
        self.save()
        if self.on_batch:
            self.on_batch(row)
