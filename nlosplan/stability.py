"""The stability catalog: stiff and extreme cases every room must survive.

Each room contributes an explicit list of :class:`~nlosplan.cases.Case`
objects (no registration by import side effect); :func:`all_cases` gathers
them and :func:`~nlosplan.cases.run_cases` runs them, timing each and turning
exceptions into failures with their message. This module sits above the
rooms it lists (sensor_models, simulators); the entry type and the runner
live below every room, in :mod:`nlosplan.cases`.
"""

from __future__ import annotations

from nlosplan.cases import Case, CaseResult, run_cases
from nlosplan.sensor_models.stability_cases import CASES as sensor_cases
from nlosplan.simulators.fast.stability_cases import CASES as transport_cases
from nlosplan.simulators.stability_cases import CASES as simulator_cases

__all__ = ["Case", "CaseResult", "all_cases", "run_cases"]


def all_cases() -> list[Case]:
    """Every case of every room that has one, sensor models first."""
    return list(sensor_cases) + list(simulator_cases) + list(transport_cases)
