"""Declarative studies: small frozen configurations and the runners that carry them out.

A study states *what* to vary and *what* to measure; the runner only
composes the rooms that own the work (datasets and jitter from
:mod:`nlosplan.data.dataset`, training and metrics from
:mod:`nlosplan.tasks.benchmark`) and records the settings and timings. The
reports room turns a study's result into tables and figures.

- :class:`JitterStudy`, :func:`run_jitter_study`, :func:`load_study_dataset`
  (``jitter``): DENALI's timing-jitter study (centre zone, Gaussian jitter at
  training and evaluation, the three tasks per jitter level).
"""

from nlosplan.experiments.jitter import (
    DEFAULT_JITTER_PS,
    DEFAULT_MODELS,
    JitterStudy,
    load_study_dataset,
    run_jitter_study,
)

__all__ = ["DEFAULT_JITTER_PS", "DEFAULT_MODELS", "JitterStudy", "load_study_dataset", "run_jitter_study"]
