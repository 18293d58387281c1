"""The simulators' benchmarks, as the commands see them: error against run time of both backends.

``nlosplan bench simulate`` (:mod:`nlosplan.cli.bench`) runs :func:`bench_simulate`, the fast backend's
(:mod:`nlosplan.simulators.fast.bench`); ``bench fidelity`` and ``bench crossval`` run the twin's comparisons with it
(:mod:`nlosplan.simulators.mitsuba.bench`, :mod:`~nlosplan.simulators.mitsuba.crossval`). This module is their face
outside the simulators' room, so no room above imports a backend's modules (``tests/test_floors.py`` keeps that).
"""

from nlosplan.simulators.fast.bench import (DEFAULT_LEVELS, DEFAULT_OBJECTS, DEFAULT_PLOT, DEFAULT_REFERENCE_POSITIONS,
                                            DEFAULT_SIZES, Progress, bench_simulate, bench_steps, check_levels)
from nlosplan.simulators.mitsuba.bench import FAST_LEVELS, TWIN_LEVELS, bench_fidelity, format_bench_fidelity
from nlosplan.simulators.mitsuba.crossval import check_models, cross_validate, format_table

__all__ = ["DEFAULT_LEVELS", "DEFAULT_OBJECTS", "DEFAULT_PLOT", "DEFAULT_REFERENCE_POSITIONS", "DEFAULT_SIZES",
           "FAST_LEVELS", "TWIN_LEVELS", "Progress", "bench_fidelity", "bench_simulate", "bench_steps", "check_levels",
           "check_models", "cross_validate", "format_bench_fidelity", "format_table"]
