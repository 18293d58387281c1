"""The small commands a capture plan yields, and what the executor sends back.

A *plan* is a generator (STYLE.md 1, after bluesky's plan stubs): it yields
:class:`Move`, :class:`Capture`, :class:`SetLights` and :class:`Checkpoint`
objects and receives, through ``send``, the executor's answer to each one.
A plan never touches a serial port; the same plan runs on the rig, on the
pty emulators and dry (:func:`nlosplan.hardware.executor.dry_run`).

What each command gets back (the value of the ``yield`` expression)
--------------------------------------------------------------------
``Move``        ``None``. Moves are lazy: the executor remembers the target and
                drives the gantry there right before the next capture it
                actually takes (a capture already in the store is not taken
                again, so resuming a run does not move the gantry for it).
``SetLights``   ``None``; also lazy, applied before the next capture taken.
``Capture``     a :class:`CaptureResult` (histogram, store key and id, the
                commanded and reported gantry position, ``resumed`` when it came
                from the store instead of the sensor, ``dry`` in a dry run).
``Checkpoint``  ``None``; the executor honours a pause request here.

Captures are numbered by the executor in the order the plan yields them
(``step`` 0, 1, 2, ...); the store key of a capture is its run id and step,
so a plan must yield the same captures in the same order when it is run
again with the same results sent back (every built-in plan does; a planner
that decides from results gets the stored results back on resume).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Generator, Mapping

import numpy as np

from nlosplan.errors import UserError

__all__ = ["Capture", "CaptureResult", "Checkpoint", "Command", "Move", "Plan", "SetLights"]


def _finite(name: str, value: Any) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise UserError(f"{name}={value!r} is not a number") from None
    if not math.isfinite(v):
        raise UserError(f"{name}={value!r} must be finite")
    return v


@dataclass(frozen=True)
class Move:
    """Move the object (gantry) to ``(x_mm, y_mm)``, gantry frame, millimetres.

    Parameters
    ----------
    x_mm, y_mm : float
        Absolute target in the gantry's machine frame (mm).
    settle_s : float
        Seconds to wait after the gantry reports Idle at the target, before
        the next capture (DENALI waits 0.5 s).
    """

    x_mm: float
    y_mm: float
    settle_s: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "x_mm", _finite("x_mm", self.x_mm))
        object.__setattr__(self, "y_mm", _finite("y_mm", self.y_mm))
        s = _finite("settle_s", self.settle_s)
        if s < 0:
            raise UserError(f"settle_s={s} must be >= 0")
        object.__setattr__(self, "settle_s", s)


@dataclass(frozen=True)
class Capture:
    """Take one histogram frame at the current target and store it.

    Parameters
    ----------
    repeat : int
        Repeat index at this position (a label, >= 0).
    labels : mapping
        Extra capture labels for the store (e.g. ``position`` to override the
        grid index); the executor fills object, size, lights, x, y, source.
    meta : mapping
        Extra JSON metadata stored with the capture (e.g. the planner's score).
    """

    repeat: int = 0
    labels: Mapping[str, Any] = field(default_factory=dict)
    meta: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not isinstance(self.repeat, (int, np.integer)) or isinstance(self.repeat, bool) or self.repeat < 0:
            raise UserError(f"repeat={self.repeat!r} must be an integer >= 0")
        object.__setattr__(self, "repeat", int(self.repeat))
        object.__setattr__(self, "labels", dict(self.labels))
        object.__setattr__(self, "meta", dict(self.meta))


@dataclass(frozen=True)
class SetLights:
    """Room lights on or off for the following captures (the ``lights`` label)."""

    on: bool

    def __post_init__(self) -> None:
        if not isinstance(self.on, (bool, np.bool_)):
            raise UserError(f"SetLights(on={self.on!r}) takes true or false")
        object.__setattr__(self, "on", bool(self.on))


@dataclass(frozen=True)
class Checkpoint:
    """A safe point to pause: the executor waits here while a pause is requested."""


Command = Move | Capture | SetLights | Checkpoint
#: A capture plan: yields commands, receives each command's answer.
Plan = Generator[Command, Any, None]


@dataclass(frozen=True)
class CaptureResult:
    """What a :class:`Capture` sends back into the plan.

    Attributes
    ----------
    step : int
        The capture's number in the run (0, 1, ...).
    repeat : int
    key : str
        The store key (``None`` in a dry run).
    store_id : int or None
        The stored capture's id (``None`` in a dry run).
    histogram : ndarray of int64, shape (rows, cols, bins), or None
        Counts (``None`` in a dry run).
    commanded_mm : tuple of float
        The target (x, y) in mm.
    reported_mm : tuple of float or None
        The gantry's reported position at the capture (``None`` in a dry run).
    label_xy_m : tuple of float or None
        The object's localization label (x, y) in metres, when the rig
        geometry knows it.
    resumed : bool
        True when the capture was found in the store (taken by an earlier run).
    dry : bool
        True in a dry run (nothing was measured).
    """

    step: int
    repeat: int
    key: str | None
    store_id: int | None
    histogram: np.ndarray | None
    commanded_mm: tuple
    reported_mm: tuple | None
    label_xy_m: tuple | None
    resumed: bool = False
    dry: bool = False
