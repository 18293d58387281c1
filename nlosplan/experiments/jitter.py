"""DENALI's timing-jitter study: how much timing jitter can each task tolerate?

Design (DENALI, CVPR 2026)
--------------------------
Only the centre zone of the 3x3 sensor is used, so the models see one
histogram per scene and must read the object from timing alone. Every
capture is blurred by Gaussian timing jitter of FWHM ``j`` (0, 50, 100 and
600 ps) for training *and* for evaluation, and the benchmark models are
trained and tested on the three tasks at every level: localization (RMSE,
MAE, metres), 30-way shape (top-1, top-5, macro F1) and 4 in vs 8 in size
(accuracy, precision, recall).

This module only composes the rooms that own the work:
:meth:`Dataset.centre_zone <nlosplan.data.dataset.Dataset.centre_zone>`,
:meth:`Dataset.with_jitter <nlosplan.data.dataset.Dataset.with_jitter>`
(exact re-binning of each bin through the Gaussian) and
:func:`~nlosplan.tasks.benchmark.run_benchmark` (split, training, metrics
and breakdowns). Jitter is linear, so blurring each capture and then
averaging its repeats (done here, per capture, as on the sensor) equals
averaging first and blurring the mean.

The split depends only on the labels and the seed, so every jitter level
trains and tests on the same scenes: the levels differ only by the jitter.

Examples
--------
>>> study = JitterStudy(jitter_ps=(0, 100, 600), models=("mlp",), epochs=5)      # doctest: +SKIP
>>> ds = load_study_dataset("captures.sqlite", {"lights": "off"})              # doctest: +SKIP
>>> result = run_jitter_study(ds, study)                                         # doctest: +SKIP
>>> [lv["peak_counts"] for lv in result["levels"]]                               # doctest: +SKIP
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, fields, replace
from typing import Callable

import numpy as np

from nlosplan.errors import UserError, check_keys
from nlosplan.data.dataset import Dataset, scene_keys
from nlosplan.data.load import load_dataset
from nlosplan.tasks.names import DEFAULT_PATIENCE, DEFAULT_WIDTH, MODEL_NAMES, PROFILES, SMALL, SPLITS, TASKS, check_names

__all__ = ["DEFAULT_JITTER_PS", "DEFAULT_MODELS", "STUDY_ZONES", "ZONE_VIEWS", "JitterStudy", "level_summary",
           "load_study_dataset", "run_jitter_study"]

#: DENALI's jitter levels, FWHM in ps.
DEFAULT_JITTER_PS: tuple[float, ...] = (0.0, 50.0, 100.0, 600.0)
#: Default models on a CPU: one zone leaves the 3D CNN nothing spatial to learn, the Transformer is the slowest.
DEFAULT_MODELS: tuple[str, ...] = ("mlp", "cnn1d")
#: Zone mode the study loads when the filter names none (DENALI's).
STUDY_ZONES = "3x3"
#: Which zones the models see: the centre zone (DENALI's study) or all of them (a comparison).
ZONE_VIEWS: tuple[str, ...] = ("centre", "all")


def _levels(values) -> tuple[float, ...]:
    """Jitter FWHMs as sorted unique floats, each finite and >= 0 (ps)."""
    if isinstance(values, (int, float, np.number)):
        values = [values]
    out = []
    for v in values:
        try:
            f = float(v)
        except (TypeError, ValueError):
            raise UserError(f"jitter level {v!r} is not a number (FWHM in ps)") from None
        if not (math.isfinite(f) and f >= 0):
            raise UserError(f"jitter level {v!r} ps is not allowed; jitter FWHMs must be finite and >= 0 ps")
        out.append(f)
    if not out:
        raise UserError("no jitter levels given; give at least one FWHM in ps, e.g. 0,50,100,600")
    return tuple(sorted(set(out)))


@dataclass(frozen=True)
class JitterStudy:
    """The settings of one jitter study (validated, frozen).

    Parameters
    ----------
    jitter_ps : tuple of float
        Jitter FWHMs, ps (stored sorted and unique; 0 = the data as captured).
    models : tuple of str
        Among :data:`~nlosplan.tasks.models.MODEL_NAMES`.
    tasks : tuple of str
        Among ``"loc"``, ``"shape"``, ``"size"``.
    zone : {"centre", "all"}
        ``"centre"``: the centre zone only (DENALI); ``"all"``: every zone.
    split : str
        One of :data:`~nlosplan.tasks.splits.SPLITS`.
    seed : int
        Seed of the split and the training (the same at every level).
    epochs : int, optional
        Epoch cap per model (None: the profile's default).
    width : float
        Model size factor, 1 = the paper's.
    patience : int or None
        Early-stopping patience, epochs (None: no early stopping).
    average_repeats : bool
        Average each scene's (jittered) repeats before training (DENALI does).
    profile : {"cpu", "denali"}
        Training settings of :func:`~nlosplan.tasks.benchmark.train_config`.
    max_seconds : float, optional
        Wall-clock budget per trained model, s.

    Raises
    ------
    UserError
        A negative, NaN or non-numeric jitter level, an unknown model, task,
        zone view, split or profile, ``width <= 0``, ``epochs < 1``,
        ``patience < 0``.
    """

    jitter_ps: tuple[float, ...] = DEFAULT_JITTER_PS
    models: tuple[str, ...] = DEFAULT_MODELS
    tasks: tuple[str, ...] = TASKS
    zone: str = "centre"
    split: str = "random"
    seed: int = 42
    epochs: int | None = None
    width: float = DEFAULT_WIDTH
    patience: int | None = DEFAULT_PATIENCE
    average_repeats: bool = True
    profile: str = "cpu"
    max_seconds: float | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "jitter_ps", _levels(self.jitter_ps))
        object.__setattr__(self, "models", tuple(check_names("model(s)", self.models, MODEL_NAMES)))
        object.__setattr__(self, "tasks", tuple(check_names("task(s)", self.tasks, TASKS)))
        if self.zone not in ZONE_VIEWS:
            raise UserError(f"unknown zone view {self.zone!r}; allowed: {', '.join(ZONE_VIEWS)}")
        if self.split not in SPLITS:
            raise UserError(f"unknown split {self.split!r}; allowed: {', '.join(SPLITS)}")
        if self.profile not in PROFILES:
            raise UserError(f"unknown profile {self.profile!r}; allowed: {', '.join(PROFILES)}")
        if not (isinstance(self.width, (int, float)) and math.isfinite(self.width) and self.width > 0):
            raise UserError(f"width={self.width} must be a number > 0")
        if self.epochs is not None and not (int(self.epochs) == self.epochs and self.epochs >= 1):
            raise UserError(f"epochs={self.epochs} must be an integer >= 1")
        if self.patience is not None and not (int(self.patience) == self.patience and self.patience >= 0):
            raise UserError(f"patience={self.patience} must be an integer >= 0 (or None for no early stopping)")
        if self.max_seconds is not None and not self.max_seconds > 0:
            raise UserError(f"max_seconds={self.max_seconds} must be > 0")

    @classmethod
    def small(cls, **overrides) -> "JitterStudy":
        """The quick run (the benchmark's ``SMALL`` epochs and width) with ``overrides``."""
        return cls(**{"epochs": SMALL["epochs"], "width": SMALL["width"], **overrides})

    @classmethod
    def from_dict(cls, data: dict) -> "JitterStudy":
        """A study from a plain dict (e.g. a JSON config file); unknown keys are an error."""
        check_keys(data, sorted(f.name for f in fields(cls)), "jitter-study setting(s)")
        return cls(**data)

    def to_dict(self) -> dict:
        """The settings as JSON-ready plain types (lists for tuples)."""
        return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}

    def replace(self, **changes) -> "JitterStudy":
        """A copy with ``changes`` (validated again)."""
        return replace(self, **changes)


def load_study_dataset(store, where: dict | None = None, *, drop_backgrounds: bool = True) -> Dataset:
    """The captures of a store the jitter study can use: :func:`~nlosplan.data.load.load_dataset` with the study's
    zone mode :data:`STUDY_ZONES` (3x3) unless ``where`` names one, DENALI's background captures left out
    (``drop_backgrounds``), and a message that says what the study needs when the store lacks that zone mode.
    """
    return load_dataset(store, where, default_zones=STUDY_ZONES, drop_backgrounds=drop_backgrounds,
                        zones_hint=f"the jitter study uses the centre zone of {STUDY_ZONES} captures (an odd zone "
                                   f"grid): build or import {STUDY_ZONES} captures, or pass zones= with an odd grid "
                                   "in the filter")


def _check_grid(dataset: Dataset, zone: str) -> None:
    r, c = dataset.zone_shape
    if zone == "centre" and (r % 2 == 0 or c % 2 == 0):
        raise UserError(f"the centre zone needs an odd zone grid (1x1, 3x3, 5x5, ...); the captures are {r}x{c}, "
                        f"whose middle falls between zones: use {STUDY_ZONES} captures (filter zones={STUDY_ZONES})")


def level_summary(dataset: Dataset) -> dict:
    """What the jitter did to the histograms fed to training (one row per capture).

    Parameters
    ----------
    dataset : Dataset
        Histograms (N, rows, cols, bins), counts.

    Returns
    -------
    dict
        ``peak_counts``: mean over histograms of the highest bin, counts;
        ``total_counts``: mean counts per histogram (jitter keeps them, except
        what is blurred past the window's ends); ``peak_width_ps``: mean
        number of bins at or above half the highest bin, times the bin width,
        ps (the width of the dominant, direct-wall peak).
    """
    h = dataset.histograms.reshape(-1, dataset.histograms.shape[-1]).astype(np.float64)
    peak = h.max(axis=1)
    wide = (h >= 0.5 * peak[:, None]).sum(axis=1) * dataset.bin_width_ps
    return {"peak_counts": float(peak.mean()), "total_counts": float(h.sum(axis=1).mean()),
            "peak_width_ps": float(wide[peak > 0].mean()) if (peak > 0).any() else 0.0}


def _n_scenes(dataset: Dataset) -> int:
    return int(scene_keys(dataset.labels).nunique())


def run_jitter_study(dataset: Dataset, config: JitterStudy | None = None,
                     progress: Callable[[dict], None] | None = None) -> dict:
    """Train and test the benchmark models at every jitter level.

    For each level ``j`` of ``config.jitter_ps``: the centre zone of every
    capture (``config.zone == "centre"``), blurred by Gaussian jitter of FWHM
    ``j`` ps, goes to :func:`~nlosplan.tasks.benchmark.run_benchmark` with
    the study's models, tasks, split, seed and training settings.

    Parameters
    ----------
    dataset : Dataset
        Captures, histograms (N, rows, cols, bins) in counts, with labels
        (object, size, class_group, position, x, y); repeats may be kept (they
        are blurred one by one, then averaged if ``config.average_repeats``).
    config : JitterStudy, optional
        The study (default: DENALI's levels and :data:`DEFAULT_MODELS`).
    progress : callable, optional
        Called with dicts: ``{"event": "level", "jitter_ps", "level", "levels",
        "summary", "dataset"}`` before a level trains (``dataset``: the
        blurred :class:`Dataset` it trains on), every event of
        :func:`run_benchmark` with ``jitter_ps``, ``level`` and ``levels``
        added, and ``{"event": "level_done", ..., "seconds"}`` after it.

    Returns
    -------
    dict
        ``rows``: the benchmark's tidy rows ({model, task, metric, group_by,
        group, value, n}) with ``jitter_ps`` added, for every level x model x
        task x metric x group; ``runs``: one per level x model x task (status,
        epochs, ``train_seconds``, ...) with ``jitter_ps``; ``levels``: one
        per level with ``jitter_ps``, ``seconds`` (level total),
        ``jitter_seconds``, ``train_seconds`` (sum over its models),
        ``n_rows`` (rows trained and tested on) and the
        :func:`level_summary` of the blurred captures; ``config``: the study
        settings, the data (``n_scenes``, ``n_captures``, histogram shape
        given and used, ``bin_width_ps``, sources, ``n_classes``), versions
        and torch threads; ``n_scenes``; ``seconds``: total wall time.

    Raises
    ------
    UserError
        An empty dataset, an even zone grid with ``zone="centre"``, or any
        error of :func:`run_benchmark` (e.g. a task with one class).
    """
    config = JitterStudy() if config is None else config
    if not isinstance(config, JitterStudy):
        raise UserError(f"config must be a JitterStudy, got {type(config).__name__}")
    if len(dataset) == 0:
        raise UserError("the dataset is empty (no captures match the filter)")
    _check_grid(dataset, config.zone)
    t0 = time.perf_counter()
    say = progress or (lambda _event: None)
    base = dataset.centre_zone() if config.zone == "centre" else dataset
    rows, runs, levels, bench_config = [], [], [], {}
    n_levels = len(config.jitter_ps)
    for li, jitter in enumerate(config.jitter_ps):
        tag = {"jitter_ps": jitter, "level": li, "levels": n_levels}
        t_level = time.perf_counter()
        blurred = base.with_jitter(jitter)
        jitter_seconds = time.perf_counter() - t_level
        summary = level_summary(blurred)
        say({"event": "level", **tag, "summary": summary, "dataset": blurred})
        from nlosplan.tasks.benchmark import run_benchmark  # torch: only when a study runs

        res = run_benchmark(blurred, models=config.models, tasks=config.tasks, split=config.split, seed=config.seed,
                            epochs=config.epochs, width=config.width, average_repeats=config.average_repeats,
                            profile=config.profile, patience=config.patience, max_seconds=config.max_seconds,
                            progress=lambda event: say({**event, **tag}))
        rows += [{"jitter_ps": jitter, **r} for r in res["rows"]]
        runs += [{"jitter_ps": jitter, **r} for r in res["runs"]]
        bench_config = res["config"]
        seconds = time.perf_counter() - t_level
        levels.append({"jitter_ps": jitter, "seconds": seconds, "jitter_seconds": jitter_seconds,
                       "train_seconds": float(sum(r.get("train_seconds", 0.0) for r in res["runs"])),
                       "n_rows": res["config"]["n_rows"], **summary})
        say({"event": "level_done", **tag, "seconds": seconds})
    n_scenes = _n_scenes(dataset)
    cfg = {**config.to_dict(), "n_scenes": n_scenes, "n_captures": len(dataset),
           "histogram_shape_given": list(dataset.histograms.shape[1:]),
           "histogram_shape": list(base.histograms.shape[1:]), "bin_width_ps": dataset.bin_width_ps,
           "sources": sorted(dataset.labels["source"].astype(str).unique().tolist()),
           **{k: bench_config.get(k) for k in ("n_classes", "versions", "torch_threads", "test_size")}}
    return {"rows": rows, "runs": runs, "levels": levels, "config": cfg, "n_scenes": n_scenes,
            "seconds": time.perf_counter() - t0}
