"""Fisher information of Poisson counts and its honest inversion.

:func:`poisson_fisher` builds ``J^T diag(1/lam) J``; :func:`analyse_fisher`
inverts it after equilibration with an eigen-decomposition, and names the
parameter combinations that carry no information instead of returning a
huge number for them (the stability catalog's "unidentifiable parameters").
"""

from __future__ import annotations

import math

import numpy as np

from nlosplan.errors import UserError

__all__ = ["COND_MAX", "analyse_fisher", "poisson_fisher"]

#: Equilibrated Fisher matrices with a larger condition number are (numerically) singular.
COND_MAX = 1e10
#: A null direction whose component along a parameter is below this counts as orthogonal to it (it does not
#: name the parameter, and leaves a position estimable). The Jacobian's central differences are exact to ~1e-8.
_ORTHO_TOL = 1e-6


def poisson_fisher(lam, jac, repeats: int = 1) -> np.ndarray:
    """Fisher information of independent Poisson counts.

    Parameters
    ----------
    lam : array_like, shape (..., K)
        Means (>= 0). Bins with ``lam == 0`` carry no information and are left out.
    jac : array_like, shape (..., K, P)
        ``d lam / d theta``.
    repeats : int
        Independent captures (the information adds up).

    Returns
    -------
    ndarray, shape (..., P, P)
        ``repeats * J^T diag(1 / lam) J``.
    """
    lam = np.asarray(lam, dtype=np.float64)
    jac = np.asarray(jac, dtype=np.float64)
    if int(repeats) < 1:
        raise UserError(f"repeats={repeats} must be >= 1")
    pos = lam > 0
    w = np.where(pos, 1.0 / np.where(pos, lam, 1.0), 0.0)
    jac = np.where(pos[..., None], jac, 0.0)
    fisher = np.einsum("...kp,...k,...kq->...pq", jac, w, jac)
    return int(repeats) * 0.5 * (fisher + np.swapaxes(fisher, -1, -2))


def _describe(vec, names) -> str:
    v = vec / np.abs(vec).max()
    idx = [i for i in np.argsort(-np.abs(v)) if abs(v[i]) > 0.05]
    plain = [names[i].removeprefix("log_") for i in idx]
    if len(idx) == 1:
        return f"{plain[0]} is not identifiable"
    combo = " ".join(f"{v[i]:+.2f}*{names[i]}" for i in idx)
    return f"{', '.join(plain[:-1])} and {plain[-1]} are not separately identifiable (null direction {combo})"


def analyse_fisher(fisher, names, n_position: int = 2, cond_max: float = COND_MAX) -> dict:
    """Invert a Fisher matrix honestly: equilibrate, eigen-decompose, flag null directions.

    Parameters
    ----------
    fisher : array_like, shape (P, P)
    names : sequence of str, length P
        The first ``n_position`` are the position parameters.
    n_position : int
    cond_max : float
        Eigenvalues of the equilibrated matrix ``D^-1/2 F D^-1/2`` below
        ``max / cond_max`` span its numerical null space.

    Returns
    -------
    dict
        ``covariance`` (n_position, n_position): the position block of the
        pseudo-inverse, ``inf`` on the diagonal (``nan`` off it) for a
        position axis with a null-space component; ``identifiable`` (no
        null direction at all), ``position_identifiable`` (every position
        axis is orthogonal to the null space: its bound is finite),
        ``condition_number``, ``null_directions`` (list of dicts name ->
        component) and ``reason`` (one line, empty when identifiable).
    """
    f = np.asarray(fisher, dtype=np.float64)
    f = 0.5 * (f + f.T)
    p = f.shape[0]
    d = np.diag(f).copy()
    info = d > 0
    reasons, nulls = [], []
    if not np.all(np.isfinite(f)):
        pos = np.full((n_position, n_position), np.nan)
        np.fill_diagonal(pos, math.inf)
        return {"covariance": pos, "identifiable": False, "position_identifiable": False, "condition_number": math.inf,
                "null_directions": [], "reason": "the Fisher matrix is not finite (non-finite counts or derivatives)"}
    for i in np.flatnonzero(~info):
        reasons.append(f"{names[i].removeprefix('log_')} is not identifiable: zero information")
        nulls.append({names[i]: 1.0})
    cov = np.full((p, p), np.nan)
    estimable = info.copy()
    cond = math.inf
    sub = np.flatnonzero(info)
    if sub.size:
        s = 1.0 / np.sqrt(d[sub])
        c = f[np.ix_(sub, sub)] * s[:, None] * s[None, :]
        w, v = np.linalg.eigh(c)
        null = w <= w.max() / cond_max
        cond = float(w.max() / w.min()) if w.min() > 0 else math.inf
        for k in np.flatnonzero(null):
            nulls.append({names[sub[i]]: float(v[i, k]) for i in range(sub.size) if abs(v[i, k]) > _ORTHO_TOL})
            reasons.append(_describe(v[:, k], [names[i] for i in sub]) + f" (condition number {cond:.1e})")
        keep = ~null
        inv = (v[:, keep] / w[keep]) @ v[:, keep].T
        cov[np.ix_(sub, sub)] = inv * s[:, None] * s[None, :]
        leak = np.linalg.norm(v[:, null], axis=1) if null.any() else np.zeros(sub.size)
        estimable[sub[leak > _ORTHO_TOL]] = False
    pos = cov[:n_position, :n_position].copy()
    for i in range(n_position):
        if not estimable[i]:
            pos[i, :] = pos[:, i] = np.nan
            pos[i, i] = math.inf
    return {"covariance": pos, "identifiable": not reasons, "position_identifiable": bool(estimable[:n_position].all()),
            "condition_number": cond, "null_directions": nulls, "reason": "; ".join(reasons)}
