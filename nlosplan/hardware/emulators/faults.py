"""Fault injection for the emulators: what goes wrong on a real rig, on purpose and reproducibly."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["GantryFaults", "SensorFaults", "garble", "truncate"]


@dataclass
class SensorFaults:
    """Faults of the emulated TMF8828 (counters over data lines; 0 turns a fault off).

    Attributes
    ----------
    garble_every : int
        Every Nth data line gets a few characters replaced by noise.
    truncate_every : int
        Every Nth data line is cut short (its line ending kept).
    drop_every : int
        Every Nth data line is left out.
    disconnect_after_frames : int
        Unplug once after this many frames (back after ``down_s``).
    down_s : float
    slow_answer_s : float
        Extra delay before answering each command.
    seed : int
    """

    garble_every: int = 0
    truncate_every: int = 0
    drop_every: int = 0
    disconnect_after_frames: int = 0
    down_s: float = 0.3
    slow_answer_s: float = 0.0
    seed: int = 0


@dataclass
class GantryFaults:
    """Faults of the emulated GRBL.

    Attributes
    ----------
    alarm_on_move : int
        The Nth move (1-based) stops halfway with ``ALARM:1`` (hard limit), once.
    slow_ok_s : float
        Extra delay before every ``ok``.
    garble_status_every : int
        Every Nth status report is garbled.
    """

    alarm_on_move: int = 0
    slow_ok_s: float = 0.0
    garble_status_every: int = 0


def garble(line: str, rng: np.random.Generator) -> str:
    """``line`` with 3 characters replaced by printable noise or bytes the protocol never sends."""
    chars = list(line)
    for i in rng.choice(len(chars), size=min(3, len(chars)), replace=False):
        chars[i] = chr(int(rng.choice([ord("?"), ord("#"), 0x7F, ord("x")])))
    return "".join(chars)


def truncate(line: str, rng: np.random.Generator) -> str:
    """The first part of ``line`` (a line cut off mid-transfer)."""
    return line[: int(rng.integers(1, max(2, len(line) - 1)))]
