"""A localization model with uncertainty: an ensemble of kernel regressors with random priors.

Input: one observation (mean of ``repeats`` captures, ``K = zones * bins``
counts), whitened as ``(h - ref) / sqrt(ref + 1)`` with ``ref`` the mean
nominal histogram over the candidates (Poisson scaling). Output: the
object's (x, y) in metres.

Each of the ``M`` members is an RBF kernel ridge regressor fitted on a
bootstrap resample, with its own length scale, plus a fixed random linear
*prior function* that the regressor fits the residual of (randomized-prior
ensembles, Osband et al. 2018). Where captures were taken the members
agree; away from them each falls back to its own prior, so their spread
is a model-uncertainty signal even before any capture. The prediction is
the members' mean.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nlosplan.errors import UserError

__all__ = ["EnsembleLocalizer"]


@dataclass(eq=False)
class EnsembleLocalizer:
    """Randomized-prior kernel ridge ensemble for (x, y) localization.

    Parameters
    ----------
    ref : ndarray, shape (K,)
        Reference histogram (counts) for the whitening.
    members : int
        Ensemble size ``M``.
    length_scale : float
        Median RBF length scale, in units of the features' RMS per dimension.
    alpha : float
        Ridge regularization of each member.
    prior_scale_m : float
        Standard deviation of the members' prior functions, metres.
    seed : int
    """

    ref: np.ndarray
    members: int = 8
    length_scale: float = 1.0
    alpha: float = 1e-3
    prior_scale_m: float = 0.1
    seed: int = 0

    def __post_init__(self) -> None:
        if self.members < 2:
            raise UserError(f"members={self.members} must be >= 2 (the spread needs two)")
        rng = np.random.default_rng(self.seed)
        k = len(self.ref)
        self.ref = np.asarray(self.ref, dtype=np.float64)
        self._w_prior = rng.normal(0.0, 1.0, (self.members, k, 2)) / np.sqrt(k)
        self._ls = self.length_scale * np.exp(rng.uniform(np.log(0.5), np.log(2.0), self.members))
        self._boot_seed = int(rng.integers(2**31))
        self._x = np.zeros((0, k))
        self._y = np.zeros((0, 2))
        self._fits: list = []
        self._scale = 1.0
        self._center = np.zeros(2)

    def features(self, histograms) -> np.ndarray:
        """Whitened features, shape (N, K), of histograms (N, K) or (N, rows, cols, bins)."""
        h = np.asarray(histograms, dtype=np.float64).reshape(len(histograms), -1)
        if h.shape[1] != len(self.ref):
            raise UserError(f"histograms have {h.shape[1]} values, the localizer expects {len(self.ref)}")
        return (h - self.ref) / np.sqrt(self.ref + 1.0)

    def _prior(self, z: np.ndarray) -> np.ndarray:
        """Members' prior functions at standardized features (N, K): (M, N, 2), metres."""
        return self.prior_scale_m * np.einsum("nk,mko->mno", z, self._w_prior) + self._center

    def _kernel(self, a: np.ndarray, b: np.ndarray, ls: float) -> np.ndarray:
        d2 = (a * a).sum(1)[:, None] + (b * b).sum(1)[None, :] - 2.0 * a @ b.T
        return np.exp(-np.maximum(d2, 0.0) / (2.0 * ls * ls * a.shape[1]))

    def fit(self, histograms, labels_xy) -> "EnsembleLocalizer":
        """Fit every member on the observations so far.

        Parameters
        ----------
        histograms : array_like, shape (N, K) or (N, rows, cols, bins)
            Observations (mean counts of the repeats); N may be 0.
        labels_xy : array_like, shape (N, 2)
            Object positions, metres.
        """
        x = self.features(histograms) if len(histograms) else np.zeros((0, len(self.ref)))
        y = np.asarray(labels_xy, dtype=np.float64).reshape(-1, 2)
        if len(x) != len(y):
            raise UserError(f"{len(x)} histograms but {len(y)} labels")
        self._x, self._y = x, y
        self._scale = float(x.std()) if len(x) > 1 and x.std() > 0 else 1.0
        self._center = y.mean(axis=0) if len(y) else self._center
        z = x / self._scale
        prior = self._prior(z)
        rng = np.random.default_rng(self._boot_seed)
        self._fits = []
        for m in range(self.members):
            if not len(z):
                self._fits.append(None)
                continue
            idx = np.unique(rng.integers(0, len(z), len(z))) if len(z) > 2 else np.arange(len(z))
            kmat = self._kernel(z[idx], z[idx], self._ls[m])
            coef = np.linalg.solve(kmat + self.alpha * np.eye(len(idx)), y[idx] - prior[m, idx])
            self._fits.append((idx, coef))
        return self

    def member_predictions(self, histograms) -> np.ndarray:
        """Every member's (x, y), shape (M, N, 2), metres."""
        z = self.features(histograms) / self._scale
        out = self._prior(z)
        for m, fit in enumerate(self._fits):
            if fit is not None:
                idx, coef = fit
                out[m] += self._kernel(z, self._x[idx] / self._scale, self._ls[m]) @ coef
        return out

    def predict(self, histograms) -> np.ndarray:
        """Ensemble mean (x, y), shape (N, 2), metres."""
        return self.member_predictions(histograms).mean(axis=0)

    def information(self, histograms, noise_m: float = 0.005) -> np.ndarray:
        """Per-candidate information matrices of the ensemble's spread, shape (N, 2M, 2M).

        ``phi_c`` stacks the members' deviations from their mean at candidate
        ``c`` (divided by ``sqrt(M) * noise_m``); ``F_c = phi_c phi_c^T``. With
        ``A = I`` the batch criterion ``log det(I + sum_B F_c)`` equals
        ``log det(I + K_BB / noise^2)`` for the ensemble's covariance ``K``
        between candidates: the batch's mutual information with the model
        under a Gaussian approximation (twice it, in nats).
        """
        e = self.member_predictions(histograms)                      # (M, N, 2)
        dev = (e - e.mean(axis=0)) / (np.sqrt(self.members) * noise_m)
        phi = np.transpose(dev, (1, 0, 2)).reshape(e.shape[1], -1)   # (N, 2M)
        return phi[:, :, None] * phi[:, None, :]

    def loc_rmse(self, histograms, labels_xy) -> float:
        """DENALI's localization RMSE of :meth:`predict` (x and y errors pooled), metres."""
        from nlosplan.tasks.metrics import loc_rmse

        return loc_rmse(self.predict(histograms), np.asarray(labels_xy, dtype=np.float64).reshape(-1, 2))
