"""Argparse types of what a command selects: DENALI objects, gantry positions, name lists, simulator fidelity levels.

Shared by ``dataset``, ``evaluate`` and the ``bench`` group; each returns the parsed value or raises
``argparse.ArgumentTypeError`` with one line naming what is allowed.
"""

from __future__ import annotations

import argparse

from nlosplan.schema import parse_int

__all__ = ["choice_list", "fidelity_level", "object_list", "position_list"]


def object_list(text: str) -> list[str]:
    """``all``, or DENALI objects and class groups separated by commas (``i``, ``halfcircle`` accepted)."""
    from nlosplan.denali import CLASS_GROUPS, DENALI_OBJECTS
    from nlosplan.data.denali_io import OBJECT_ALIASES

    out: list[str] = []
    for tok in (t.strip() for t in text.split(",")):
        if tok == "all":
            out += DENALI_OBJECTS
        elif tok in CLASS_GROUPS:
            out += CLASS_GROUPS[tok]
        elif OBJECT_ALIASES.get(tok, tok) in DENALI_OBJECTS:
            out.append(OBJECT_ALIASES.get(tok, tok))
        else:
            raise argparse.ArgumentTypeError(f"unknown object {tok!r}; allowed: all, {', '.join(CLASS_GROUPS)}, "
                                             f"{', '.join(DENALI_OBJECTS)}")
    return list(dict.fromkeys(out))


def position_list(text: str) -> list[int]:
    """``0-99``, ``0,5,9`` or a mix such as ``0-9,20-29`` (gantry positions 0..99)."""
    from nlosplan.denali import N_POSITIONS

    out: list[int] = []
    for tok in (t.strip() for t in text.split(",")):
        lo, sep, hi = tok.partition("-")
        try:
            a, b = parse_int(lo), parse_int(hi if sep else lo)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{tok!r} is not a position N or a range N-M "
                                             "(e.g. 0-99 or 0,5,9)") from None
        if a > b:
            raise argparse.ArgumentTypeError(f"range {tok!r} goes down; write it low-high, e.g. {b}-{a}")
        if a < 0 or b >= N_POSITIONS:
            raise argparse.ArgumentTypeError(f"{tok!r} is out of range; allowed: positions 0 to {N_POSITIONS - 1}")
        out += range(a, b + 1)
    return sorted(set(out))


def choice_list(allowed: tuple[str, ...]):
    """An argparse type: a comma-separated list of ``allowed`` names."""

    def parse(text: str) -> list[str]:
        out = [t.strip() for t in text.split(",") if t.strip()]
        bad = [t for t in out if t not in allowed]
        if bad or not out:
            raise argparse.ArgumentTypeError(f"{', '.join(bad) or repr(text)} not allowed; "
                                             f"allowed: {', '.join(allowed)}")
        return list(dict.fromkeys(out))

    return parse


def fidelity_level(text: str) -> str:
    from nlosplan.simulators import FIDELITY_LEVELS

    if text not in FIDELITY_LEVELS:
        raise argparse.ArgumentTypeError(f"unknown fidelity {text!r}; allowed: {', '.join(FIDELITY_LEVELS)}")
    return text
