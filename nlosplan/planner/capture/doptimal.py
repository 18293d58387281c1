"""D-optimal designs: relaxed weights solved with casadi/IPOPT, rounded to a batch.

Every candidate ``c`` carries an information matrix ``F_c`` (P x P): the
Fisher information of one capture there about the parameters being
learned (localization or calibration parameters from the differentiable
simulator, or the feature outer products of a linear model). A batch ``B``
adds its matrices to what is known already (``A``): the D-criterion is
``log det(A + sum_{c in B} F_c)``.

Relaxation: weights ``0 <= w_c <= upper`` with ``sum w = n`` replace the
0/1 choice; the problem is concave in ``w`` and IPOPT solves it. The
rounding keeps the ``n`` heaviest candidates and then exchanges chosen for
unchosen ones while that raises the criterion (Fedorov exchange).

Scaling: matrices are equilibrated with ``D = diag(mean_c F_c + A)^-1/2``
before the optimizer sees them (log det changes by a constant only).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from nlosplan.errors import UserError

__all__ = ["exchange", "logdet", "relaxed_doptimal", "round_design"]


def logdet(matrix) -> float:
    """``log det`` of a symmetric positive definite matrix (``-inf`` when it is not)."""
    sign, val = np.linalg.slogdet(np.asarray(matrix, dtype=np.float64))
    return float(val) if sign > 0 else -np.inf


def _equilibrate(fishers: np.ndarray, prior: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    d = np.diag(fishers.mean(axis=0) + prior).copy()
    d = np.where(d > 0, d, 1.0)
    s = 1.0 / np.sqrt(d)
    return fishers * s[None, :, None] * s[None, None, :], prior * s[:, None] * s[None, :]


def _check(fishers, prior) -> tuple[np.ndarray, np.ndarray]:
    f = np.asarray(fishers, dtype=np.float64)
    if f.ndim != 3 or f.shape[1] != f.shape[2] or not len(f):
        raise UserError(f"information matrices must be (C >= 1, P, P), got {f.shape}")
    a = np.zeros(f.shape[1:]) if prior is None else np.asarray(prior, dtype=np.float64)
    if a.shape != f.shape[1:]:
        raise UserError(f"prior information must be {f.shape[1:]}, got {a.shape}")
    if not (np.all(np.isfinite(f)) and np.all(np.isfinite(a))):
        raise UserError("information matrices must be finite")
    return 0.5 * (f + np.swapaxes(f, 1, 2)), 0.5 * (a + a.T)


def _sym_logdet(m, p: int):
    """Symbolic log det of a casadi P x P expression by an LDL^T factorization (small P)."""
    import casadi as ca

    l = [[None] * p for _ in range(p)]
    d = [None] * p
    out = 0
    for j in range(p):
        dj = m[j, j] - sum(l[j][k] * l[j][k] * d[k] for k in range(j))
        d[j] = dj
        out = out + ca.log(dj)
        for i in range(j + 1, p):
            l[i][j] = (m[i, j] - sum(l[i][k] * l[j][k] * d[k] for k in range(j))) / dj
    return out


@lru_cache(maxsize=16)
def _solver(c: int, p: int, tol: float):
    """IPOPT solver over ``x = (w (C), m (P*P))``: min -log det(m) s.t. sum w = n, m - F^T w = A.

    The information matrix ``m`` is its own variable tied to the weights by
    linear constraints (``F``, the candidates' matrices, is a parameter), so
    the Hessian is only P^2 x P^2 and the solver is built once per (C, P).
    """
    import casadi as ca

    w = ca.SX.sym("w", c)
    m = ca.SX.sym("m", p * p)
    fp = ca.SX.sym("F", c * p * p)
    fmat = ca.reshape(fp, p * p, c)  # column j: candidate j's flattened matrix
    g = ca.vertcat(ca.sum1(w), m - ca.mtimes(fmat, w))
    obj = -_sym_logdet(ca.reshape(m, p, p), p)
    return ca.nlpsol("doptimal", "ipopt", {"x": ca.vertcat(w, m), "p": fp, "f": obj, "g": g},
                     {"ipopt.print_level": 0, "print_time": 0, "ipopt.sb": "yes", "ipopt.tol": tol,
                      "ipopt.max_iter": 500})


def relaxed_doptimal(fishers, n: float, *, prior=None, upper: float = 1.0, tol: float = 1e-8) -> np.ndarray:
    """Relaxed D-optimal design weights by IPOPT.

    Parameters
    ----------
    fishers : array_like, shape (C, P, P)
        Information matrix of one capture at each candidate.
    n : float
        Total weight (the batch size), ``0 < n <= C * upper``.
    prior : array_like, shape (P, P), optional
        Information already held (captures taken, a prior); ``A + sum w F``
        must be non-singular at the optimum.
    upper : float
        Largest weight of one candidate (1: each candidate at most once).
    tol : float
        IPOPT tolerance.

    Returns
    -------
    ndarray of float64, shape (C,)
        Weights in ``[0, upper]`` summing to ``n``.

    Raises
    ------
    UserError
        Bad shapes, ``n`` outside ``(0, C * upper]``, or IPOPT failing.

    Notes
    -----
    maximise ``log det(A + sum_c w_c F_c)`` subject to ``sum_c w_c = n``,
    ``0 <= w_c <= upper``; concave, so IPOPT's stationary point is the optimum.
    """
    f, a = _check(fishers, prior)
    c, p, _ = f.shape
    if not (0 < n <= c * upper + 1e-12):
        raise UserError(f"design size n={n} must be in (0, {c * upper:g}] for {c} candidates with weights <= {upper}")
    f, a = _equilibrate(f, a)
    solver = _solver(c, p, float(tol))
    m0 = a + f.sum(axis=0) * (n / c)
    sol = solver(x0=np.concatenate([np.full(c, n / c), m0.ravel()]),
                 lbx=np.concatenate([np.zeros(c), np.full(p * p, -np.inf)]),
                 ubx=np.concatenate([np.full(c, float(upper)), np.full(p * p, np.inf)]),
                 lbg=np.concatenate([[n], a.ravel()]), ubg=np.concatenate([[n], a.ravel()]),
                 p=f.reshape(c, p * p).ravel())
    status = solver.stats()["return_status"]
    if status not in ("Solve_Succeeded", "Solved_To_Acceptable_Level"):
        raise UserError(f"IPOPT did not solve the D-optimal design ({status}); the information matrices may be "
                        "singular for every design: add prior information")
    return np.clip(np.asarray(sol["x"]).ravel()[:c], 0.0, upper)


def exchange(chosen, fishers, prior=None, *, allowed=None, max_rounds: int = 50) -> list[int]:
    """Fedorov exchange: swap chosen for unchosen candidates while ``log det(A + sum F)`` grows.

    Parameters
    ----------
    chosen : sequence of int
        Starting batch (distinct candidate indices).
    fishers : array_like, shape (C, P, P)
    prior : array_like, shape (P, P), optional
    allowed : array_like of bool, shape (C,), optional
        Candidates that may enter the batch.
    max_rounds : int

    Returns
    -------
    list of int
        A batch of the same size whose criterion is >= the start's.
    """
    f, a = _check(fishers, prior)
    ok = np.ones(len(f), bool) if allowed is None else np.asarray(allowed, bool).copy()
    batch = list(chosen)
    for _ in range(max_rounds):
        total = a + f[batch].sum(axis=0)
        best = logdet(total)
        move = None
        for i, ci in enumerate(batch):
            base = total - f[ci]
            pool = np.flatnonzero(ok & ~np.isin(np.arange(len(f)), batch))
            if not len(pool):
                break
            signs, vals = np.linalg.slogdet(base[None] + f[pool])
            vals = np.where(signs > 0, vals, -np.inf)
            j = int(np.argmax(vals))
            if vals[j] > best + 1e-10:
                best, move = vals[j], (i, int(pool[j]))
        if move is None:
            break
        batch[move[0]] = move[1]
    return batch


def round_design(weights, n: int, fishers, prior=None, *, allowed=None) -> list[int]:
    """Round relaxed weights to a batch of ``n`` distinct candidates (heaviest first, then exchange).

    Parameters
    ----------
    weights : array_like, shape (C,)
    n : int
    fishers, prior, allowed
        As :func:`exchange`.

    Returns
    -------
    list of int
        ``n`` candidate indices.
    """
    w = np.asarray(weights, dtype=np.float64).copy()
    if allowed is not None:
        w[~np.asarray(allowed, bool)] = -np.inf
    order = np.argsort(-w, kind="stable")
    start = [int(i) for i in order[:n] if np.isfinite(w[i])]
    return exchange(start, fishers, prior, allowed=allowed)
