"""Named fidelity levels shared by the simulator backends: a level name, a dict of knobs, or the knobs' dataclass."""

from __future__ import annotations

import dataclasses
from typing import Any

from nlosplan.errors import UserError, check_keys


def resolve_level(value: Any, levels: dict, cls: type, what: str):
    """An instance of ``cls`` from a name in ``levels``, a mapping of its fields, or an instance.

    Parameters
    ----------
    value : str, dict or cls
    levels : dict of str -> cls
        The named levels.
    cls : type
        A dataclass of knobs.
    what : str
        How errors name it, e.g. ``"fidelity"`` or ``"twin fidelity"``.
    """
    if isinstance(value, cls):
        return value
    if isinstance(value, str):
        if value not in levels:
            raise UserError(f"unknown {what} {value!r}; allowed: {', '.join(levels)}")
        return levels[value]
    if isinstance(value, dict):
        check_keys(value, sorted(f.name for f in dataclasses.fields(cls)), f"{what} knob(s)")
        return cls(**value)
    raise UserError(f"{what} must be a level name ({', '.join(levels)}), a dict of knobs or a {cls.__name__}, "
                    f"not {value!r}")
