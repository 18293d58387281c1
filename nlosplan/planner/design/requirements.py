"""What a task must achieve: one threshold on one metric, optionally under one condition.

Defaults (DENALI-scale goals for a lab): localization RMSE <= 0.05 m
(``loc_rmse``, DENALI's: x and y errors pooled, see
:data:`nlosplan.tasks.metrics.METRIC_DEFINITIONS`), shape top-1 accuracy >=
0.35, size accuracy >= 0.90, over all test captures. A
:class:`Condition` restricts the rows a metric is computed on, e.g.
``size=4in``, ``lights=off`` or ``quadrant=far`` (the far quadrant of the
gantry, see :func:`nlosplan.tasks.metrics.position_quadrants`); it is parsed
once, where a requirement is made, and travels as data (its text
``col=value`` only in files and logs).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from enum import StrEnum
from typing import NamedTuple

import numpy as np

from nlosplan.errors import UserError
from nlosplan.schema import QUANTITIES, parse_number

__all__ = ["Condition", "Requirement", "DEFAULT_REQUIREMENTS", "METRIC_OF_TASK", "Task", "parse_requirement"]


class Task(StrEnum):
    """The tasks a design is judged on (the tasks room's :data:`~nlosplan.tasks.names.TASKS`, as an enum).

    A member is its name (``Task.LOC == "loc"``): it reads, prints and logs as the plain string.
    """

    LOC = "loc"
    SHAPE = "shape"
    SIZE = "size"


#: The metric each task is judged by, whether smaller is better, and its unit.
METRIC_OF_TASK: dict[Task, tuple[str, bool, str]] = {
    Task.LOC: ("loc_rmse", True, "m"),
    Task.SHAPE: ("top1_acc", False, ""),
    Task.SIZE: ("top1_acc", False, ""),
}
_CONDITIONS = {"size": ("4in", "8in"), "lights": ("on", "off"), "quadrant": ("near", "far")}


class Condition(NamedTuple):
    """``column == value``: the rows a requirement's metric is computed on (size, lights or quadrant)."""

    column: str
    value: str

    @classmethod
    def parse(cls, text: str | None) -> "Condition | None":
        """``"col=value"`` as a condition (None for None or a text without ``=``)."""
        if not text or "=" not in text:
            return None
        col, val = text.split("=", 1)
        return cls(col, val)

    def __str__(self) -> str:
        return f"{self.column}={self.value}"

    def mask(self, labels) -> np.ndarray:
        """Which rows of a label table (pandas, with ``x``, ``y`` for ``quadrant``) meet it, shape (N,) bool."""
        if self.column == "quadrant":
            from nlosplan.tasks.metrics import position_quadrants  # scikit-learn: only when evaluated

            return position_quadrants(labels)["quadrant"].to_numpy() == self.value
        return labels[self.column].astype(str).to_numpy() == self.value


#: Largest localization requirement, metres (the physical range of a localization RMSE: ``target_rmse_m``).
LOC_MAX_M = QUANTITIES["target_rmse_m"].hi


@dataclass(frozen=True)
class Requirement:
    """``metric <= threshold`` (localization) or ``>= threshold`` (classification) for one task.

    Parameters
    ----------
    task : Task or {"loc", "shape", "size"}
        Kept as a :class:`Task`.
    threshold : float
        Metres for the localization RMSE (``loc_rmse``), a fraction for accuracies.
    condition : Condition or (str, str), optional
        ``(column, value)`` among size / lights / quadrant (kept as a :class:`Condition`).
    """

    task: Task
    threshold: float
    condition: Condition | None = None

    def __post_init__(self) -> None:
        if self.task not in METRIC_OF_TASK:
            raise UserError(f"unknown task {self.task!r}; allowed: {', '.join(METRIC_OF_TASK)}")
        object.__setattr__(self, "task", Task(self.task))
        t = float(self.threshold)
        if not (t > 0) or (not self.smaller_is_better and t > 1) or (self.smaller_is_better and t > LOC_MAX_M):
            raise UserError(f"{self.task} threshold {self.threshold} must be "
                            f"{f'> 0 and <= {LOC_MAX_M:g} (metres)' if self.smaller_is_better else 'in (0, 1]'}")
        object.__setattr__(self, "threshold", t)
        if self.condition is not None:
            col, val = self.condition
            if col not in _CONDITIONS or val not in _CONDITIONS[col]:
                allowed = "; ".join(f"{k}={'|'.join(v)}" for k, v in _CONDITIONS.items())
                raise UserError(f"unknown condition {col}={val}; allowed: {allowed}")
            object.__setattr__(self, "condition", Condition(str(col), str(val)))

    @property
    def metric(self) -> str:
        return METRIC_OF_TASK[self.task][0]

    @property
    def smaller_is_better(self) -> bool:
        return METRIC_OF_TASK[self.task][1]

    @property
    def name(self) -> str:
        """E.g. ``loc loc_rmse <= 0.05 m`` or ``shape top1_acc >= 0.35 [size=4in]``."""
        op = "<=" if self.smaller_is_better else ">="
        unit = METRIC_OF_TASK[self.task][2]
        cond = f" [{self.condition}]" if self.condition else ""
        return f"{self.task} {self.metric} {op} {self.threshold:g}{' ' + unit if unit else ''}{cond}"

    def met(self, value: float) -> bool:
        return value <= self.threshold if self.smaller_is_better else value >= self.threshold

    def margin(self, value: float) -> float:
        """Relative margin: > 0 met, < 0 missed (e.g. 0.2 = 20 % better than required)."""
        if self.smaller_is_better:
            return (self.threshold - value) / self.threshold
        return (value - self.threshold) / self.threshold

    def to_dict(self) -> dict:
        return {"task": self.task, "threshold": self.threshold,
                "condition": None if self.condition is None else str(self.condition)}

    @classmethod
    def from_dict(cls, data: dict) -> "Requirement":
        cond = data.get("condition")
        if isinstance(cond, str):
            cond = Condition.parse(cond)
        return cls(data["task"], data["threshold"], cond)


DEFAULT_REQUIREMENTS: tuple[Requirement, ...] = (
    Requirement("loc", 0.05), Requirement("shape", 0.35), Requirement("size", 0.90))

_PATTERN = re.compile(r"^\s*(loc|shape|size)\s*(<=|>=|=)\s*([0-9.eE+-]+)\s*(?:@\s*(\w+)=(\w+))?\s*$")


def parse_requirement(text: str) -> Requirement:
    """``"loc<=0.05"``, ``"shape>=0.35"``, ``"size>=0.9@size=4in"`` -> :class:`Requirement`.

    The comparison must be the task's: ``<=`` for localization (an error),
    ``>=`` for the accuracies; anything else is refused, never rewritten.
    """
    m = _PATTERN.match(text)
    if not m:
        raise UserError(f"requirement {text!r} must look like loc<=0.05, shape>=0.35 or size>=0.9@lights=on")
    task, op, value, col, val = m.groups()
    want = "<=" if METRIC_OF_TASK[task][1] else ">="
    if op != want:
        what = "an error (smaller is better)" if want == "<=" else "an accuracy (larger is better)"
        raise UserError(f"requirement {text!r}: {task}'s {METRIC_OF_TASK[task][0]} is {what}; "
                        f"write {task}{want}{value}")
    try:
        threshold = parse_number(value)
    except ValueError:
        raise UserError(f"requirement {text!r}: {value!r} is not a number") from None
    return Requirement(task, threshold, Condition(col, val) if col else None)
