"""The room-lights condition (DENALI captures with lights on and off).

There is no standard lights device, so the default asks a person
(:class:`ManualLights`); the emulated rig uses :class:`EmulatedLights`, which
also switches the simulated scene's ambient light.
"""

from __future__ import annotations

import sys
from typing import Callable

from nlosplan.errors import UserError

__all__ = ["EmulatedLights", "FixedLights", "ManualLights"]


class ManualLights:
    """Ask a person to switch the lights and press Enter.

    Parameters
    ----------
    ask : callable, optional
        ``ask(prompt) -> str`` (default :func:`input`, only at a terminal).
    initial : bool or None
        The state the lights are known to be in (None: unknown, the first set asks).
    """

    def __init__(self, ask: Callable[[str], str] | None = None, initial: bool | None = None) -> None:
        self._ask = ask
        self.state = initial

    def set(self, on: bool) -> None:
        if self.state is on:
            return
        prompt = f"Switch the room lights {'ON' if on else 'OFF'} and press Enter: "
        if self._ask is None:
            if not sys.stdin.isatty():
                raise UserError(f"the plan needs the room lights {'on' if on else 'off'} and no one can be asked "
                                "(stdin is not a terminal); run at a terminal or keep the lights fixed")
            input(prompt)
        else:
            self._ask(prompt)
        self.state = bool(on)


class FixedLights:
    """Lights that stay as they are: asking for the other state is an error."""

    def __init__(self, on: bool) -> None:
        self.state = bool(on)

    def set(self, on: bool) -> None:
        if bool(on) != self.state:
            raise UserError(f"the plan switches the lights {'on' if on else 'off'} but they are fixed "
                            f"{'on' if self.state else 'off'} for this run")


class EmulatedLights:
    """Lights of the emulated rig: switching them changes the simulated ambient light."""

    def __init__(self, initial: bool = False) -> None:
        self.state = bool(initial)
        self.changes = 0

    def set(self, on: bool) -> None:
        if bool(on) != self.state:
            self.changes += 1
        self.state = bool(on)
