"""Straight-line motion with a trapezoidal speed profile, and a stop by deceleration (feed hold).

Shared by the gantry emulators. Times are in emulated seconds, distances in
the caller's unit (mm or steps), speeds per second, accelerations per second².
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["Segment", "trapezoid", "travelled"]


def trapezoid(distance: float, v: float, a: float) -> tuple[float, float, float]:
    """(total time, acceleration time, peak speed) of a rest-to-rest move over ``distance``.

    ``a <= 0`` means no acceleration limit (constant speed ``v`` from the start).
    """
    if distance <= 0 or v <= 0:
        return 0.0, 0.0, 0.0
    if a <= 0:
        return distance / v, 0.0, v
    if distance <= v * v / a:   # triangle: never reaches v
        t_acc = math.sqrt(distance / a)
        return 2 * t_acc, t_acc, a * t_acc
    t_acc = v / a
    return 2 * t_acc + (distance - v * v / a) / v, t_acc, v


def travelled(t: float, total: float, t_acc: float, vpk: float, a: float, distance: float) -> float:
    """Distance covered ``t`` seconds into a :func:`trapezoid` move."""
    if t <= 0:
        return 0.0
    if t >= total:
        return distance
    if t_acc <= 0:
        return vpk * t
    if t < t_acc:
        return 0.5 * a * t * t
    if t <= total - t_acc:
        return 0.5 * a * t_acc * t_acc + vpk * (t - t_acc)
    left = total - t
    return distance - 0.5 * a * left * left


@dataclass
class Segment:
    """One straight move from ``start`` to ``target`` (tuples of equal length) starting at time ``t0``.

    ``v0 > 0`` makes it a stop: the move starts at speed ``v0`` and
    decelerates at ``a`` to rest at ``target`` (a feed hold).
    """

    start: tuple
    target: tuple
    t0: float
    v: float
    a: float
    v0: float = 0.0

    def __post_init__(self) -> None:
        self.distance = math.dist(self.start, self.target)
        if self.v0 > 0:
            self.total = self.v0 / self.a if self.a > 0 else 0.0
        else:
            self.total, self.t_acc, self.vpk = trapezoid(self.distance, self.v, self.a)

    def _s(self, t: float) -> float:
        if self.v0 > 0:
            t = min(max(t, 0.0), self.total)
            return min(self.v0 * t - 0.5 * self.a * t * t, self.distance)
        return travelled(t, self.total, self.t_acc, self.vpk, self.a, self.distance)

    def position(self, now: float) -> tuple:
        """Where the move is at time ``now``."""
        if self.distance == 0:
            return tuple(self.target)
        f = self._s(now - self.t0) / self.distance
        return tuple(p + (q - p) * f for p, q in zip(self.start, self.target))

    def speed(self, now: float) -> float:
        """Speed at time ``now``."""
        t = now - self.t0
        if t <= 0 or t >= self.total:
            return 0.0 if t >= self.total else self.v0
        if self.v0 > 0:
            return max(self.v0 - self.a * t, 0.0)
        if self.t_acc <= 0:
            return self.vpk
        if t < self.t_acc:
            return self.a * t
        if t <= self.total - self.t_acc:
            return self.vpk
        return self.a * (self.total - t)

    def done(self, now: float) -> bool:
        return now - self.t0 >= self.total

    def stop(self, now: float) -> "Segment":
        """The deceleration from ``now`` to rest along this move (never past its target)."""
        here, v = self.position(now), self.speed(now)
        if v <= 0 or self.a <= 0 or self.distance == 0:
            return Segment(here, here, now, self.v, self.a)
        d = min(v * v / (2 * self.a), math.dist(here, self.target))
        f = d / math.dist(here, self.target) if math.dist(here, self.target) > 0 else 0.0
        end = tuple(p + (q - p) * f for p, q in zip(here, self.target))
        return Segment(here, end, now, self.v, self.a, v0=v)
