"""Which candidates a strategy proposes next (the decision part of the planner).

Each function takes the planner's view (``space``, which candidates are
``allowed``, what was observed) and returns candidate indices; the planner
orders them into a route afterwards (except the raster, which keeps
DENALI's snake).
"""

from __future__ import annotations

import numpy as np

from nlosplan.planner.capture.batch import batch_information, select_batch
from nlosplan.planner.capture.doptimal import relaxed_doptimal, round_design

__all__ = ["STRATEGIES", "raster_order"]

#: raster: DENALI's snake; random: uniform; active: ensemble-spread mutual information (localization model);
#: doptimal: D-optimal calibration (registration offset, photon scale, albedo) by IPOPT; ``-motion``: the
#: same information per second of gantry time, batch chosen jointly.
STRATEGIES = ("raster", "random", "active", "active-motion", "doptimal", "doptimal-motion")


def raster_order(points_mm) -> np.ndarray:
    """DENALI's snake over candidates: its 10 x 10 grid points by position index when all 100 are
    candidates, else in DENALI's order over any lattice: column by column of gantry x (increasing), y
    running up the first column and back down the next. Returns candidate indices."""
    from nlosplan.denali import grid_index

    pts = np.asarray(points_mm, dtype=np.float64)
    grid = np.array([grid_index(x, y) for x, y in pts])
    if len(set(grid[grid >= 0].tolist())) == 100:
        on = np.flatnonzero(grid >= 0)
        return on[np.argsort(grid[on], kind="stable")]
    cols = np.unique(np.round(pts[:, 0], 6))
    out = []
    for k, x in enumerate(cols):
        idx = np.flatnonzero(np.isclose(pts[:, 0], x, atol=1e-6))
        idx = idx[np.argsort(pts[idx, 1] * (1 if k % 2 == 0 else -1), kind="stable")]
        out.extend(idx.tolist())
    return np.asarray(out, dtype=int)


def choose(strategy: str, n: int, *, space, allowed, rng, raster, localizer, theta, held_info, prior_info,
           noise_m: float, motion, position_mm) -> tuple[list[int], dict]:
    """Candidate indices for the next batch and a note of the scores.

    Parameters
    ----------
    strategy : str
        One of :data:`STRATEGIES`.
    n : int
    space : CandidateSpace
    allowed : ndarray of bool, shape (C,)
    rng : numpy Generator
    raster : ndarray of int
        The raster order.
    localizer : EnsembleLocalizer
        Fitted on the observations so far.
    theta : ndarray, shape (4,)
        Current calibration estimate.
    held_info : ndarray, shape (4, 4)
        Fisher information of the observations so far (at ``theta``).
    prior_info : ndarray, shape (4, 4)
    noise_m : float
        Localization noise scale of the ensemble information, m.
    motion : MotionModel
    position_mm : ndarray, shape (2,)

    Returns
    -------
    indices : list of int
    note : dict
        ``information_nats`` of the batch under the strategy's criterion (absent for raster/random).
    """
    pool = np.flatnonzero(allowed)
    if strategy == "raster":
        return [int(i) for i in raster if allowed[i]][:n], {}
    if strategy == "random":
        return [int(i) for i in rng.choice(pool, size=min(n, len(pool)), replace=False)], {}
    moving = strategy.endswith("-motion")
    if strategy.startswith("active"):
        fishers = localizer.information(space.counts(theta), noise_m=noise_m)
        prior = np.eye(fishers.shape[1])
    else:
        fishers = space.fisher(theta)
        prior = held_info + prior_info
    if strategy == "doptimal":
        w = np.zeros(space.size)
        w[pool] = relaxed_doptimal(fishers[pool], min(n, len(pool)), prior=prior)
        batch = round_design(w, min(n, len(pool)), fishers, prior, allowed=allowed)
    else:
        batch = select_batch(fishers, prior, n, allowed=allowed, points_mm=space.points_mm, start_mm=position_mm,
                             motion=motion if moving else None)
    return batch, {"information_nats": batch_information(batch, fishers, prior)}
