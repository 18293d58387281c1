"""The stability catalog's entry type and runner, below every room.

Each room lists its own :class:`Case` objects (``<room>/stability_cases.py``,
no registration by import side effect); :mod:`nlosplan.stability`, above the
rooms it lists, gathers them (:func:`~nlosplan.stability.all_cases`) and
:func:`run_cases` runs them, timing each and turning exceptions into failures
with their message.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable

__all__ = ["Case", "CaseResult", "run_cases"]


@dataclass(frozen=True)
class Case:
    """One catalog entry.

    Attributes
    ----------
    name : str
        Short identifier, e.g. ``"jitter-zero"``.
    requirement : str
        What must hold, in words.
    run : callable
        ``run() -> (passed: bool, measured: str)``.
    """

    name: str
    requirement: str
    run: Callable[[], tuple[bool, str]]


@dataclass(frozen=True)
class CaseResult:
    """Outcome of one case: name, requirement, pass/fail, what was measured, seconds."""

    name: str
    requirement: str
    passed: bool
    detail: str
    seconds: float


def run_cases(cases: list[Case], progress: Callable[[CaseResult], None] | None = None) -> list[CaseResult]:
    """Run cases in order; an exception is a failure whose detail is its message."""
    results = []
    for case in cases:
        t0 = time.perf_counter()
        try:
            passed, detail = case.run()
        except Exception as exc:  # noqa: BLE001 - a crash is a failed case, reported
            passed, detail = False, f"raised {type(exc).__name__}: {exc}"
        res = CaseResult(case.name, case.requirement, bool(passed), detail, time.perf_counter() - t0)
        results.append(res)
        if progress is not None:
            progress(res)
    return results
