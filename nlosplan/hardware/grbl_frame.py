"""The user frame on a GRBL gantry: a work offset the driver chooses, sets and checks.

GRBL moves in work coordinates (machine = work + WCO) and reports the
machine position (``MPos``). The driver makes the plan's gantry coordinates
(the *user frame*, DENALI's 0..320 mm) the work coordinates of G54:

- ``auto`` (default): with homing enabled (``$22=1``) the machine position is
  referenced to the switches and GRBL's machine space is ``[-max_travel, 0]``
  per axis (``[0, max_travel]`` only with build option ``Z`` and a negative
  homing direction); the user frame's minimum corner is put on the space's
  minimum corner (DENALI, ``$130=$131=320``: G54 = (-320, -320), so user
  (0, 0) is machine (-320, -320) and user (320, 320) machine (0, 0), the
  homing corner). Without homing the machine position counts from power-up
  and G54 is (0, 0): user = machine.
- ``keep``: the work offset active on the controller (whatever G54/G92 say).
- ``(x, y)``: G54 set to these machine coordinates of the user origin.

With homing enabled the whole user box, mapped to machine coordinates, must
lie inside the machine space (else soft limits, or the switches, stop the
gantry); the check runs before anything moves.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from nlosplan.errors import UserError
from nlosplan.hardware.grbl_protocol import machine_space

__all__ = ["FrameChanged", "WorkFrame", "parse_work_offset", "plan_frame"]

TOL_MM = 0.0015   # GRBL prints 3 decimals


class FrameChanged(RuntimeError):
    """The controller's work offset changed during the run (someone sent G10/G92): user positions are invalid."""


def parse_work_offset(text) -> str | tuple:
    """``auto``, ``keep`` or ``X,Y`` (mm, the machine coordinates of the user origin).

    Raises
    ------
    UserError
        Anything else.
    """
    if isinstance(text, tuple):
        return text
    t = str(text).strip().lower()
    if t in ("auto", "keep"):
        return t
    try:
        x, y = (float(v) for v in t.split(","))
    except ValueError:
        raise UserError(f"work offset {text!r}: use auto, keep, or X,Y in mm (e.g. -320,-320)") from None
    if not (math.isfinite(x) and math.isfinite(y)):
        raise UserError(f"work offset {text!r} must be finite")
    return x, y


@dataclass(frozen=True)
class WorkFrame:
    """machine = user + ``offset_mm`` (per axis x, y).

    Attributes
    ----------
    offset_mm : (float, float)
        The work coordinate offset (WCO) x, y in mm.
    mode : str
        ``auto``, ``keep`` or ``given``.
    space_mm : ((xmin, xmax), (ymin, ymax)) or None
        GRBL's machine space when homing references it, else None.
    soft_limits : bool
        ``$20=1``: GRBL itself refuses targets outside the space (ALARM:2).
    step_mm : (float, float)
        One step (1 / ``$100``, 1 / ``$101``): the resolution of reported positions.
    """

    offset_mm: tuple
    mode: str
    space_mm: tuple | None
    soft_limits: bool
    step_mm: tuple

    def to_machine(self, x: float, y: float) -> tuple[float, float]:
        return x + self.offset_mm[0], y + self.offset_mm[1]

    def to_user(self, mx: float, my: float) -> tuple[float, float]:
        return mx - self.offset_mm[0], my - self.offset_mm[1]

    def describe(self) -> dict:
        return {"work_offset_mm": list(self.offset_mm), "work_offset_mode": self.mode,
                "machine_space_mm": None if self.space_mm is None else [list(v) for v in self.space_mm],
                "soft_limits": self.soft_limits, "step_mm": list(self.step_mm)}


def plan_frame(mode, limits_mm, settings: dict, *, force_origin: bool = False, active_wco=(0.0, 0.0)) -> WorkFrame:
    """Choose the work offset and check the user limits against GRBL's machine space.

    Parameters
    ----------
    mode : "auto", "keep" or (x, y)
    limits_mm : ((xmin, xmax), (ymin, ymax))
        The user frame's limits.
    settings : dict
        ``$$`` (``$20``, ``$22``, ``$23``, ``$100``, ``$101``, ``$130``, ``$131``).
    force_origin : bool
        Built with HOMING_FORCE_SET_ORIGIN (``$I`` option ``Z``).
    active_wco : (x, y)
        The controller's work offset now (for ``keep``).

    Raises
    ------
    UserError
        The limits, mapped to machine coordinates, leave the machine space
        (one line naming the axis, both ranges and the settings to change).
    """
    homing, soft = bool(int(settings.get(22, 0))), bool(int(settings.get(20, 0)))
    space = machine_space(settings, force_origin)[:2] if homing else None
    (ux0, ux1), (uy0, uy1) = limits_mm
    if mode == "keep":
        offset, kind = (float(active_wco[0]), float(active_wco[1])), "keep"
    elif mode == "auto":
        offset, kind = ((space[0][0] - ux0, space[1][0] - uy0) if space else (0.0, 0.0)), "auto"
    else:
        offset, kind = (float(mode[0]), float(mode[1])), "given"
    steps = tuple(1.0 / max(float(settings.get(100 + i, 250.0)), 1e-9) for i in range(2))
    frame = WorkFrame(offset, kind, space, soft, steps)
    if space is not None:
        for axis, (u0, u1), (s0, s1), o in zip("xy", limits_mm, space, offset):
            m0, m1 = u0 + o, u1 + o
            if m0 < s0 - TOL_MM or m1 > s1 + TOL_MM:
                n = 130 + "xy".index(axis)
                why = ("raise $%d or narrow --limits" % n) if (u1 - u0) > (s1 - s0) + TOL_MM else \
                    "use --work-offset auto or another offset"
                raise UserError(f"gantry limits {axis} {u0:g}..{u1:g} mm map to machine {axis} {m0:g}..{m1:g} mm "
                                f"(work offset {o:g} mm), outside GRBL's machine space {axis} {s0:g}..{s1:g} mm "
                                f"(${n}={s1 - s0:g}, homing on{', soft limits on' if soft else ''}): {why}")
    return frame
