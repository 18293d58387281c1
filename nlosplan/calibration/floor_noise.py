"""The floor's noise measured on real captures: does a bin scatter like Poisson counts about its mean?

The capture noise model (:class:`nlosplan.sensor_models.noise.CaptureNoise`) draws every bin Poisson about its
expectation. World parity (issue 35) names one way the real captures could be easier than the simulated ones: a
floor (the counts that do not come from the flash) that scatters less than Poisson counts, a pedestal. This module
measures it on real captures.

The late bins of a capture, long after the return has decayed, hold the floor and at most a slow tail. A
low-order polynomial in time takes out that trend; the residual variance over the mean is the floor's Fano factor
(1 for Poisson counts, above 1 for excess noise such as a gain that varies during the capture, below 1 for a
pedestal or dead time). The same estimator applied to draws of the noise model about the same fitted means gives
the model's figure, with the estimator's own bias (the fit takes ``degree + 1`` degrees of freedom, which the
variance corrects), so real and model are compared like for like.

Examples
--------
>>> import numpy as np
>>> rng = np.random.default_rng(0)
>>> hists = rng.poisson(150.0, size=(40, 9, 128)).astype(float)
>>> d = floor_dispersion(hists)
>>> bool(0.9 < d.real_median < 1.1)
True
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from nlosplan.errors import UserError
from nlosplan.sensor_models.noise import CaptureNoise

__all__ = ["FloorDispersion", "fano_factors", "floor_dispersion", "floor_windows"]

#: First bin of the floor window on a TMF882x short-range capture (128 bins): the plane captures' returns peak at
#: bin 43 at the latest (0.4 m), so bins 96-127 lie more than 50 bins (about 5 ns) after every return.
FIRST_FLOOR_BIN = 96
#: A window is used when its mean floor is at least this many counts (an empty zone says nothing about noise).
MIN_FLOOR_COUNTS = 20.0


def floor_windows(hists, first_bin: int = FIRST_FLOOR_BIN, min_mean: float = MIN_FLOOR_COUNTS):
    """The late-bin windows that hold a floor, one per capture and zone.

    Parameters
    ----------
    hists : array, shape (N, Z, B)
        Raw counts of N captures, Z zones, B bins.
    first_bin : int
        First bin of the window (the window is ``first_bin`` to ``B - 1``).
    min_mean : float
        Windows whose mean count is below this are left out.

    Returns
    -------
    windows : ndarray, shape (M, B - first_bin), float64
        Counts of the kept windows.
    zones : ndarray, shape (M,), int
        The zone of each window.

    Raises
    ------
    UserError
        Histograms that are not (N, Z, B), a window shorter than 8 bins, or no window with a floor.
    """
    h = np.asarray(hists, dtype=np.float64)
    if h.ndim != 3:
        raise UserError(f"floor noise: histograms must be captures x zones x bins, got shape {h.shape}")
    width = h.shape[-1] - int(first_bin)
    if first_bin < 0 or width < 8:
        raise UserError(f"floor noise: the window from bin {first_bin} of {h.shape[-1]} must hold at least 8 bins")
    win = h[:, :, first_bin:].reshape(-1, width)
    zones = np.tile(np.arange(h.shape[1]), h.shape[0])
    keep = win.mean(axis=1) >= min_mean
    if not keep.any():
        raise UserError(f"floor noise: no capture has a floor of {min_mean:g} counts or more in bins {first_bin}+")
    return win[keep], zones[keep]


def _trend(windows: np.ndarray, degree: int) -> np.ndarray:
    """Least-squares polynomial of ``degree`` in time through each window, shape as ``windows``."""
    t = np.linspace(-1.0, 1.0, windows.shape[1])
    basis = np.vander(t, degree + 1)                       # (W, degree + 1)
    coef, *_ = np.linalg.lstsq(basis, windows.T, rcond=None)
    return (basis @ coef).T


def fano_factors(windows, degree: int = 2) -> np.ndarray:
    """Residual variance over mean of each window about its polynomial trend.

    Parameters
    ----------
    windows : array, shape (M, W)
        Counts.
    degree : int
        Degree of the trend (0: a constant floor).

    Returns
    -------
    ndarray, shape (M,)
        The Fano factor of each window (1 for Poisson counts about a trend of that degree).
    """
    w = np.asarray(windows, dtype=np.float64)
    resid = w - _trend(w, degree)
    dof = w.shape[1] - (degree + 1)
    return (resid ** 2).sum(axis=1) / dof / w.mean(axis=1)


@dataclass(frozen=True)
class FloorDispersion:
    """The floor's Fano factor, real beside the noise model's, with bootstrap intervals of the medians.

    Attributes
    ----------
    windows : int
        Capture-zone windows used.
    first_bin, last_bin, degree : int
        The window's first and last bin and the trend's degree.
    level_counts : float
        Median floor level of the windows, counts per bin.
    real_median : float
        Median Fano factor of the real windows.
    real_interval : (float, float)
        95 % bootstrap interval of that median (windows resampled).
    model_median : float
        Median Fano factor of the noise model's draws about the windows' fitted trends.
    model_interval : (float, float)
    per_zone : list of dict
        ``{"zone", "windows", "median"}`` of the real windows.
    """

    windows: int
    first_bin: int
    last_bin: int
    degree: int
    level_counts: float
    real_median: float
    real_interval: tuple
    model_median: float
    model_interval: tuple
    per_zone: list

    def to_dict(self) -> dict:
        return asdict(self)


def _median_interval(values: np.ndarray, rng: np.random.Generator, draws: int = 400) -> tuple:
    idx = rng.integers(0, len(values), size=(draws, len(values)))
    meds = np.median(values[idx], axis=1)
    return float(np.percentile(meds, 2.5)), float(np.percentile(meds, 97.5))


def floor_dispersion(hists, *, first_bin: int = FIRST_FLOOR_BIN, degree: int = 2,
                     min_mean: float = MIN_FLOOR_COUNTS, seed: int = 0) -> FloorDispersion:
    """The floor's Fano factor of real captures and of the noise model about the same means.

    Parameters
    ----------
    hists : array, shape (N, Z, B)
        Raw counts.
    first_bin, degree, min_mean
        See :func:`floor_windows` and :func:`fano_factors`.
    seed : int
        Seed of the model's draws and of the bootstrap.

    Returns
    -------
    FloorDispersion
    """
    windows, zones = floor_windows(hists, first_bin, min_mean)
    rng = np.random.default_rng(seed)
    real = fano_factors(windows, degree)
    means = np.maximum(_trend(windows, degree), 0.0)
    model = fano_factors(CaptureNoise().draw(rng, means).astype(np.float64), degree)
    per_zone = [{"zone": int(z), "windows": int((zones == z).sum()), "median": float(np.median(real[zones == z]))}
                for z in np.unique(zones)]
    return FloorDispersion(windows=len(real), first_bin=int(first_bin), last_bin=int(first_bin) + windows.shape[1] - 1,
                           degree=int(degree),
                           level_counts=float(np.median(windows.mean(axis=1))),
                           real_median=float(np.median(real)), real_interval=_median_interval(real, rng),
                           model_median=float(np.median(model)), model_interval=_median_interval(model, rng),
                           per_zone=per_zone)
