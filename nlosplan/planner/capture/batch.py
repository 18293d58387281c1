"""Joint batch selection by information, optionally per second of gantry time.

Information of a batch ``B`` given what is known (``A``):
``I(B) = log det(A + sum_{c in B} F_c) - log det(A)``. It has diminishing
returns: a candidate that repeats what another batch member measures adds
little, so choosing members one after another by their gain *given the
members already chosen* spreads the batch (unlike the top-n of one score).

With a motion model the objective is information per second,
``I(B) / T(B)``, where ``T(B)`` is the time to visit the batch from the
current gantry position (moves by cheapest insertion into the current
route, settle and capture at every stop). After the greedy pass, single
swaps that raise the objective are made (a local search over batches).
"""

from __future__ import annotations

import numpy as np

from nlosplan.planner.capture.motion import MotionModel

__all__ = ["batch_information", "select_batch"]


def _logdets(mats: np.ndarray) -> np.ndarray:
    sign, val = np.linalg.slogdet(mats)
    return np.where(sign > 0, val, -np.inf)


def batch_information(batch, fishers, prior) -> float:
    """``log det(A + sum_B F) - log det(A)`` (nats) for candidate indices ``batch``."""
    a = np.asarray(prior, dtype=np.float64)
    f = np.asarray(fishers, dtype=np.float64)
    b = list(batch)
    return float(_logdets((a + f[b].sum(axis=0))[None])[0] - _logdets(a[None])[0])


def _route_time(start, pts, motion: MotionModel) -> float:
    """Cheapest-insertion route time from ``start`` through ``pts`` (K, 2), s (moves + stops)."""
    if not len(pts):
        return 0.0
    route = [np.asarray(start, float)]
    total = 0.0
    for p in pts:
        best, where = np.inf, len(route)
        for i in range(1, len(route) + 1):
            prev = route[i - 1]
            nxt = route[i] if i < len(route) else None
            add = float(motion.move_time(np.linalg.norm(p - prev)))
            if nxt is not None:
                add += float(motion.move_time(np.linalg.norm(nxt - p)) - motion.move_time(np.linalg.norm(nxt - prev)))
            if add < best:
                best, where = add, i
        route.insert(where, np.asarray(p, float))
        total += best
    return total + len(pts) * (motion.settle_s + motion.capture_s)


def select_batch(fishers, prior, n: int, *, allowed=None, points_mm=None, start_mm=None,
                 motion: MotionModel | None = None, swap_pool: int = 30) -> list[int]:
    """Choose ``n`` candidates jointly for information (per second with ``motion``).

    Parameters
    ----------
    fishers : array_like, shape (C, P, P)
        Information of one capture at each candidate.
    prior : array_like, shape (P, P)
        Information held already (positive definite).
    n : int
        Batch size (fewer when fewer candidates are allowed).
    allowed : array_like of bool, shape (C,), optional
    points_mm : array_like, shape (C, 2), optional
        Candidate gantry positions, mm (needed with ``motion``).
    start_mm : array_like, shape (2,), optional
        Current gantry position, mm.
    motion : MotionModel, optional
        Score information per second of gantry time instead of information.
    swap_pool : int
        Unchosen candidates (best single ratio first) tried in the swap pass.

    Returns
    -------
    list of int
        Chosen candidate indices, in the order they were chosen.
    """
    f = np.asarray(fishers, dtype=np.float64)
    a = np.asarray(prior, dtype=np.float64)
    ok = np.ones(len(f), bool) if allowed is None else np.asarray(allowed, bool).copy()
    pts = None if points_mm is None else np.asarray(points_mm, dtype=np.float64)
    start = np.zeros(2) if start_mm is None else np.asarray(start_mm, dtype=np.float64)
    base = float(_logdets(a[None])[0])

    def score(batch) -> float:
        info = batch_information(batch, f, a)
        if motion is None:
            return info
        return info / max(_route_time(start, pts[list(batch)], motion), 1e-9)

    batch: list[int] = []
    total = a.copy()
    for _ in range(min(n, int(ok.sum()))):
        pool = np.flatnonzero(ok)
        gains = _logdets(total[None] + f[pool]) - base
        if motion is None:
            pick = int(pool[int(np.argmax(gains))])
        else:
            seconds = np.array([_route_time(start, pts[batch + [int(c)]], motion) for c in pool])
            ratio = gains / np.maximum(seconds, 1e-9)
            pick = int(pool[int(np.argmax(ratio))])
        batch.append(pick)
        ok[pick] = False
        total = total + f[pick]
    if motion is not None and batch:
        pool = np.flatnonzero(ok)
        if len(pool):
            single = (_logdets(a[None] + f[pool]) - base) / np.array(
                [_route_time(start, pts[[int(c)]], motion) for c in pool])
            pool = pool[np.argsort(-single)[:swap_pool]]
        best = score(batch)
        improved = True
        while improved:
            improved = False
            for i in range(len(batch)):
                for c in pool:
                    if c in batch:
                        continue
                    trial = batch[:i] + [int(c)] + batch[i + 1:]
                    s = score(trial)
                    if s > best + 1e-12:
                        batch, best, improved = trial, s, True
    return batch
