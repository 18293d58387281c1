"""Gantry motion time: straight moves with a trapezoidal speed profile.

A GRBL gantry moves both axes together along a straight line (``G1``) at
the programmed feed, accelerating and braking at the configured
acceleration. The time to travel a distance ``d`` (mm) is

- ``2 sqrt(d / a)`` when the move is too short to reach the feed
  (``d < v^2 / a``: a triangular profile),
- ``d / v + v / a`` otherwise (accelerate, cruise, brake),

plus a fixed settle time after every move (DENALI waits 0.5 s) and the
capture time at every position.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from nlosplan.errors import UserError

__all__ = ["MotionModel"]


@dataclass(frozen=True)
class MotionModel:
    """Feed/acceleration model of the gantry and the time a capture takes.

    Parameters
    ----------
    feed_mm_s : float
        Cruise speed along the path, mm/s (GRBL ``F`` / 60).
    accel_mm_s2 : float
        Acceleration and braking, mm/s^2 (GRBL ``$120``/``$121``).
    settle_s : float
        Wait after each move before capturing, s (DENALI: 0.5).
    capture_s : float
        Time to take the capture(s) at one position, s (3 frames at about
        3 frames/s over serial: 1 s).
    """

    feed_mm_s: float = 20.0
    accel_mm_s2: float = 50.0
    settle_s: float = 0.5
    capture_s: float = 1.0

    def __post_init__(self) -> None:
        for name in ("feed_mm_s", "accel_mm_s2"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise UserError(f"{name}={v!r} must be a finite number > 0")
        for name in ("settle_s", "capture_s"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise UserError(f"{name}={v!r} must be a finite number >= 0")

    def move_time(self, distance_mm) -> np.ndarray:
        """Travel time of straight moves, s (0 for a zero-length move; no settle).

        Parameters
        ----------
        distance_mm : array_like, any shape
            Move lengths, mm (>= 0).

        Returns
        -------
        ndarray of float64, same shape
        """
        d = np.abs(np.asarray(distance_mm, dtype=np.float64))
        v, a = self.feed_mm_s, self.accel_mm_s2
        return np.where(d < v * v / a, 2.0 * np.sqrt(d / a), d / v + v / a)

    def travel_matrix(self, points_mm) -> np.ndarray:
        """Move time between every pair of points, s, shape (K, K) for points (K, 2) mm."""
        p = np.asarray(points_mm, dtype=np.float64)
        return self.move_time(np.linalg.norm(p[:, None, :] - p[None, :, :], axis=-1))

    def route_seconds(self, start_mm, points_mm) -> float:
        """Time to visit ``points_mm`` (K, 2) in order from ``start_mm`` (2,): moves + settles + captures, s."""
        p = np.asarray(points_mm, dtype=np.float64).reshape(-1, 2)
        if not len(p):
            return 0.0
        path = np.vstack([np.asarray(start_mm, dtype=np.float64).reshape(1, 2), p])
        moves = self.move_time(np.linalg.norm(np.diff(path, axis=0), axis=1))
        return float(moves.sum() + len(p) * (self.settle_s + self.capture_s))

    def to_dict(self) -> dict:
        """The four settings (JSON)."""
        return asdict(self)
