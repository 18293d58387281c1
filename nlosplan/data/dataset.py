"""`Dataset`: histograms with their labels, in memory (the currency of the task room).

A dataset comes from a :class:`~nlosplan.data.store.CaptureStore` (simulated
or real captures) and goes to the models, the metrics and the studies. Rows
are captures (or the mean of a capture's repeats); labels are a pandas table.

Labels
------
object : str
    DENALI class name (one of the 30, e.g. "A", "7", "circle").
size : {"4in", "8in"}
class_group : {"numbers", "letters", "shapes"}
position : int
    Gantry position index, 0..99 (-1 when unknown).
x, y : float
    Localization label, metres (world frame of the rig).
lights : {"on", "off"}
zones : str
    Zone mode, e.g. "3x3" or "8x8".
repeat : int
    Repeat index of the capture; -1 for a mean over repeats.
source : str
    Where it came from, e.g. "sim:fast", "real:denali".
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from nlosplan.errors import UserError

#: Label columns every dataset has.
LABEL_COLUMNS = ("object", "size", "class_group", "position", "x", "y", "lights", "zones", "repeat", "source")
#: Columns that identify one scene (all repeats of a capture share them).
SCENE_KEYS = ("object", "size", "position", "lights", "zones", "source")


def scene_keys(labels: pd.DataFrame) -> pd.Series:
    """One string per row naming its scene (:data:`SCENE_KEYS`); the repeats of a scene share it."""
    return labels[list(SCENE_KEYS)].astype(str).agg("|".join, axis=1)


def scene_groups(labels: pd.DataFrame) -> np.ndarray:
    """Scene number of every row, shape (N,), int: rows of one scene (:data:`SCENE_KEYS`; its repeats) share it,
    numbered in order of first appearance. The numbers :func:`scene_keys` factorized would give, without building a
    string per row (a 3,000-row reference: 36 -> 2 ms, on every trained evaluation's split)."""
    return labels.groupby(list(SCENE_KEYS), sort=False, dropna=False, observed=True).ngroup().to_numpy()


@dataclass(frozen=True, eq=False)
class Dataset:
    """Histograms and labels.

    Parameters
    ----------
    histograms : ndarray, shape (N, rows, cols, bins)
        Counts (float32; a mean of repeats is fractional).
    labels : pandas.DataFrame
        N rows with at least :data:`LABEL_COLUMNS` (more are kept).
    bin_width_ps : float
        Width of one histogram bin, ps (jitter studies need it).

    Raises
    ------
    UserError
        Mismatched lengths, a histogram array that is not 4-D, missing columns.
    """

    histograms: np.ndarray
    labels: pd.DataFrame
    bin_width_ps: float

    def __post_init__(self) -> None:
        h = np.asarray(self.histograms, dtype=np.float32)
        if h.ndim != 4:
            raise UserError(f"dataset histograms must have shape (N, rows, cols, bins), got {h.shape}")
        missing = [c for c in LABEL_COLUMNS if c not in self.labels.columns]
        if missing:
            raise UserError(f"dataset labels miss column(s) {', '.join(missing)}")
        if len(self.labels) != h.shape[0]:
            raise UserError(f"dataset has {h.shape[0]} histograms but {len(self.labels)} label rows")
        if not (np.isfinite(self.bin_width_ps) and self.bin_width_ps > 0):
            raise UserError(f"bin_width_ps={self.bin_width_ps} must be > 0")
        object.__setattr__(self, "histograms", h)
        object.__setattr__(self, "labels", self.labels.reset_index(drop=True))

    def __len__(self) -> int:
        return int(self.histograms.shape[0])

    @property
    def zone_shape(self) -> tuple[int, int]:
        """(rows, cols) of the histograms."""
        return int(self.histograms.shape[1]), int(self.histograms.shape[2])

    def take(self, index) -> "Dataset":
        """Rows ``index`` (integer array or boolean mask), as a new dataset."""
        idx = np.asarray(index)
        if idx.dtype == bool:
            idx = np.flatnonzero(idx)
        return Dataset(self.histograms[idx], self.labels.iloc[idx], self.bin_width_ps)

    def where(self, **conditions) -> "Dataset":
        """Rows whose label columns equal the given values (a value may be a list of allowed values).

        Examples
        --------
        >>> ds.where(lights="off", zones="3x3", size=["4in", "8in"])  # doctest: +SKIP
        """
        mask = np.ones(len(self), bool)
        for col, value in conditions.items():
            if col not in self.labels.columns:
                raise UserError(f"no label column {col!r}; columns: {', '.join(self.labels.columns)}")
            allowed = value if isinstance(value, (list, tuple, set)) else [value]
            mask &= self.labels[col].isin(allowed).to_numpy()
        return self.take(mask)

    def mean_over_repeats(self) -> "Dataset":
        """One row per scene: the mean of its repeats (DENALI averages the 3x3 repeats), ``repeat = -1``."""
        if len(self) == 0:
            return self
        groups = pd.Series(np.arange(len(self))).groupby(scene_keys(self.labels).to_numpy(), sort=False)
        first = [g.iloc[0] for _, g in groups]
        hist = np.stack([self.histograms[g.to_numpy()].mean(axis=0) for _, g in groups])
        labels = self.labels.iloc[first].copy()
        labels["repeat"] = -1
        return Dataset(hist, labels, self.bin_width_ps)

    def centre_zone(self) -> "Dataset":
        """Only the centre zone, shape (N, 1, 1, bins) (DENALI's jitter study uses it)."""
        r, c = self.zone_shape
        return Dataset(self.histograms[:, r // 2: r // 2 + 1, c // 2: c // 2 + 1], self.labels, self.bin_width_ps)

    def with_jitter(self, fwhm_ps: float) -> "Dataset":
        """Histograms blurred by Gaussian timing jitter of FWHM ``fwhm_ps`` (exact box re-binning)."""
        if not (np.isfinite(fwhm_ps) and fwhm_ps >= 0):
            raise UserError(f"jitter fwhm_ps={fwhm_ps} must be >= 0")
        if fwhm_ps == 0:
            return self
        from nlosplan.sensor_models.pipeline import apply_jitter

        blurred = np.asarray(apply_jitter(self.histograms.astype(np.float64), fwhm_ps, self.bin_width_ps))
        return Dataset(blurred.astype(np.float32), self.labels, self.bin_width_ps)

    def concat(self, other: "Dataset") -> "Dataset":
        """Rows of ``self`` then ``other`` (same histogram shape and bin width)."""
        if other.histograms.shape[1:] != self.histograms.shape[1:] or other.bin_width_ps != self.bin_width_ps:
            raise UserError("datasets differ in histogram shape or bin width; cannot concatenate")
        return Dataset(np.concatenate([self.histograms, other.histograms]),
                       pd.concat([self.labels, other.labels], ignore_index=True), self.bin_width_ps)
