"""Calibration of the counts model from captures: Poisson maximum likelihood by Fisher scoring.

Parameters ``theta = (dx, dy, log g, log a)`` of
:class:`~nlosplan.planner.capture.space.CandidateSpace`. Each observation
is the mean of ``repeats`` captures at a candidate, so its counts are
``repeats``-scaled Poisson; the log-likelihood is
``sum repeats * (h log lam(theta) - lam(theta))``. A weak Gaussian prior
(``prior_std``) keeps the first iterations well posed with few captures.
"""

from __future__ import annotations

import numpy as np

from nlosplan.tasks.fisher import analyse_fisher

__all__ = ["DEFAULT_PRIOR_STD", "DEFAULT_TOLERANCE", "calibration_error", "fit_counts_model", "prior_information"]

#: Prior standard deviation of each parameter: 1 cm offsets, factors within about e^0.5.
DEFAULT_PRIOR_STD = np.array([0.01, 0.01, 0.5, 0.5])
#: Calibration tolerance per parameter: 0.5 mm offsets, 1 % photon scale and albedo.
DEFAULT_TOLERANCE = np.array([0.0005, 0.0005, 0.01, 0.01])


def prior_information(prior_std=DEFAULT_PRIOR_STD) -> np.ndarray:
    """Information of the Gaussian prior, shape (4, 4): ``diag(1 / std^2)``."""
    return np.diag(1.0 / np.asarray(prior_std, dtype=np.float64) ** 2)


def fit_counts_model(space, index, observations, *, theta0=None, prior_std=DEFAULT_PRIOR_STD,
                     iterations: int = 30) -> dict:
    """Maximum-likelihood fit of the counts model's parameters (dx, dy, log photon scale, log albedo) to observations.

    Parameters
    ----------
    space : CandidateSpace
    index : array_like of int, shape (N,)
        Candidate of each observation.
    observations : array_like, shape (N, K)
        Mean counts of ``space.repeats`` captures.
    theta0 : array_like, shape (4,), optional
        Start (default: the nominal model, 0).
    prior_std : array_like, shape (4,)
    iterations : int

    Returns
    -------
    dict
        ``theta`` (4,), ``covariance`` (4, 4) (inverse of data + prior
        information), ``std`` (4,), ``identifiable`` and ``reason`` of the
        data-only Fisher matrix (:func:`~nlosplan.tasks.fisher.analyse_fisher`),
        ``iterations``.
    """
    idx = np.asarray(index, dtype=int)
    obs = np.asarray(observations, dtype=np.float64).reshape(len(idx), space.direct.shape[1])
    r = space.repeats
    p_info = prior_information(prior_std)
    theta = np.zeros(4) if theta0 is None else np.asarray(theta0, dtype=np.float64).copy()
    if not len(idx):  # nothing observed: the prior
        cov = np.linalg.inv(p_info)
        return {"theta": theta, "covariance": cov, "std": np.sqrt(np.diag(cov)), "identifiable": False,
                "reason": "no captures yet", "iterations": 0, "fisher": np.zeros((4, 4))}

    def loglik(th):
        lam = np.maximum(space.counts(th, idx), 1e-12)
        return float(r * (obs * np.log(lam) - lam).sum() - 0.5 * th @ p_info @ th)

    it = 0
    for it in range(1, iterations + 1):
        lam = np.maximum(space.counts(theta, idx), 1e-12)
        jac = space.jacobian(theta, idx)
        grad = r * np.einsum("nk,nkp->p", obs / lam - 1.0, jac) - p_info @ theta
        info = r * np.einsum("nkp,nk,nkq->pq", jac, 1.0 / lam, jac) + p_info
        step = np.linalg.solve(info, grad)
        base, scale = loglik(theta), 1.0
        while scale > 1e-4 and loglik(theta + scale * step) < base - 1e-9:
            scale *= 0.5
        theta = theta + scale * step
        if np.all(np.abs(scale * step) <= 1e-6 * np.sqrt(np.diag(np.linalg.inv(info)))):
            break
    fisher = space.fisher(theta, idx).sum(axis=0) if len(idx) else np.zeros((4, 4))
    info = fisher + p_info
    cov = np.linalg.inv(info)
    data = analyse_fisher(fisher, ["dx", "dy", "log_photon_scale", "log_albedo"], n_position=2)
    return {"theta": theta, "covariance": cov, "std": np.sqrt(np.diag(cov)), "identifiable": data["identifiable"],
            "reason": data["reason"], "iterations": it, "fisher": fisher}


def calibration_error(theta, truth, tolerance=DEFAULT_TOLERANCE) -> float:
    """Largest parameter error in units of its tolerance (<= 1: every parameter within tolerance)."""
    return float(np.max(np.abs(np.asarray(theta) - np.asarray(truth)) / np.asarray(tolerance)))
