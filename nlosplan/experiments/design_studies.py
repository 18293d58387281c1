"""Studies through the design planner: ``resolution`` (zones at equal photon budget) and ``bins``.

Each study is a TOML file beside this module (the same tables as a design
configuration, see :mod:`nlosplan.planner.design.config`) applied to the
full or quick configuration and run by
:func:`~nlosplan.planner.design.run.run_design`; the result is a design
result restricted to the study's axes, which the command turns into a design
report (:mod:`nlosplan.reports.design_report`: the reports room is above this
one).
"""

from __future__ import annotations

from importlib import resources

from nlosplan.errors import UserError

__all__ = ["DESIGN_STUDIES", "study_config", "run_design_study"]

#: Study name -> (TOML file, one line of what it shows).
DESIGN_STUDIES: dict[str, tuple[str, str]] = {
    "resolution": ("resolution.toml", "zones 1x1 to 8x8 at an equal photon budget (3x3 vs 8x8 as in DENALI)"),
    "bins": ("bins.toml", "bin width (merged bins, same window) and number of bins (shorter window), 3x3 zones"),
}


def study_config(name: str, *, quick: bool = False, requirements=None):
    """The :class:`~nlosplan.planner.design.run.DesignConfig` of a study."""
    from dataclasses import replace

    from nlosplan.planner.design.config import full_config, load_config, quick_config

    if name not in DESIGN_STUDIES:
        raise UserError(f"unknown study {name!r}; allowed: {', '.join(DESIGN_STUDIES)}")
    base = quick_config() if quick else full_config()
    with resources.as_file(resources.files("nlosplan.experiments") / DESIGN_STUDIES[name][0]) as path:
        cfg = load_config(path, base)
    if quick:  # keep the quick run's size: coarse grids, its scenes
        cfg = replace(cfg, label=f"quick {name} study")
    else:
        cfg = replace(cfg, label=f"{name} study")
    return replace(cfg, requirements=tuple(requirements)) if requirements else cfg


def run_design_study(name: str, out, *, quick: bool = False, requirements=None, resume: bool = False,
                     workers=None, cluster=None, progress=None) -> dict:
    """Run a study into ``out``; returns the design result (the command writes its report beside it)."""
    from nlosplan.planner.design.run import run_design

    cfg = study_config(name, quick=quick, requirements=requirements)
    return run_design(cfg, out, resume=resume, workers=workers, cluster=cluster, progress=progress)
