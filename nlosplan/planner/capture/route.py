"""Route ordering of a capture batch: nearest neighbour, then 2-opt.

The batch is an open path that starts at the gantry's current position and
may end anywhere; the cost of a leg is the gantry's move time
(:class:`~nlosplan.planner.capture.motion.MotionModel`), which is a
monotone function of the distance, so short legs are preferred as in a
Euclidean tour. 2-opt reverses a segment whenever that shortens the path
and stops at a local optimum; it starts from the better of the nearest-
neighbour order and the given order, so the result is never longer than
the batch as given.
"""

from __future__ import annotations

import numpy as np

from nlosplan.planner.capture.motion import MotionModel

__all__ = ["nearest_neighbour", "order_batch", "path_cost", "two_opt"]


def _costs(start_mm, points_mm, motion: MotionModel) -> np.ndarray:
    """Leg costs between the start (node 0) and the points (nodes 1..K), shape (K+1, K+1), s."""
    nodes = np.vstack([np.asarray(start_mm, dtype=np.float64).reshape(1, 2),
                       np.asarray(points_mm, dtype=np.float64).reshape(-1, 2)])
    return motion.travel_matrix(nodes)


def path_cost(order, cost: np.ndarray) -> float:
    """Cost of the open path 0 -> order[0] -> order[1] ... (nodes of ``cost``, 1-based points), s."""
    seq = np.concatenate([[0], np.asarray(order, dtype=int)])
    return float(cost[seq[:-1], seq[1:]].sum())


def nearest_neighbour(cost: np.ndarray) -> list[int]:
    """Greedy open path from node 0 through every other node of ``cost`` (K+1, K+1); returns nodes 1..K."""
    k = cost.shape[0] - 1
    left = set(range(1, k + 1))
    here, out = 0, []
    while left:
        nxt = min(left, key=lambda j: (cost[here, j], j))
        out.append(nxt)
        left.remove(nxt)
        here = nxt
    return out


def two_opt(order, cost: np.ndarray, max_rounds: int = 100) -> list[int]:
    """Improve an open path (start node 0 fixed, free end) by segment reversals.

    Parameters
    ----------
    order : sequence of int
        Nodes 1..K in visiting order.
    cost : ndarray, shape (K+1, K+1)
        Symmetric leg costs.
    max_rounds : int
        Passes over all segment pairs (each pass that improves nothing ends it).

    Returns
    -------
    list of int
        An order whose :func:`path_cost` is <= that of ``order``.
    """
    seq = [0] + list(order)
    n = len(seq)
    for _ in range(max_rounds):
        improved = False
        for i in range(1, n - 1):
            for j in range(i + 1, n):
                a, b = seq[i - 1], seq[i]
                c = seq[j]
                d = seq[j + 1] if j + 1 < n else None
                old = cost[a, b] + (cost[c, d] if d is not None else 0.0)
                new = cost[a, c] + (cost[b, d] if d is not None else 0.0)
                if new < old - 1e-12:
                    seq[i:j + 1] = seq[i:j + 1][::-1]
                    improved = True
        if not improved:
            break
    return seq[1:]


def order_batch(start_mm, points_mm, motion: MotionModel) -> tuple[np.ndarray, float, float]:
    """Order a batch of gantry positions to minimise travel time from ``start_mm``.

    Parameters
    ----------
    start_mm : array_like, shape (2,)
        Current gantry position, mm.
    points_mm : array_like, shape (K, 2)
        Batch positions, mm, in any order.
    motion : MotionModel

    Returns
    -------
    order : ndarray of int, shape (K,)
        Permutation of ``range(K)``: visit ``points_mm[order]``.
    seconds : float
        Move time of the ordered path (no settle/capture), s.
    seconds_given : float
        Move time of the batch in the given order, s (``seconds <= seconds_given``).
    """
    pts = np.asarray(points_mm, dtype=np.float64).reshape(-1, 2)
    k = len(pts)
    if k == 0:
        return np.zeros(0, dtype=int), 0.0, 0.0
    cost = _costs(start_mm, pts, motion)
    given = list(range(1, k + 1))
    nn = nearest_neighbour(cost)
    seed = nn if path_cost(nn, cost) <= path_cost(given, cost) else given
    best = two_opt(seed, cost)
    return np.asarray(best, dtype=int) - 1, path_cost(best, cost), path_cost(given, cost)
