"""Why a GRBL homing cycle failed, in one clause that says what to change.

Stock GRBL 1.1 (``config.h``) homes in cycles: ``HOMING_CYCLE_0`` is Z alone,
then X and Y together. An XY gantry without a Z limit switch therefore fails
in the first cycle (ALARM:9, Z searched and found nothing) before X or Y
moves. A limit pin that reads triggered before homing (``Pn:`` in the status
report; a normally-closed switch without ``$5=1``, or every pin as in
grbl-sim) makes the pull-off fail (ALARM:8).
"""

from __future__ import annotations

from nlosplan.hardware.grbl_protocol import ALARMS, Status

__all__ = ["homing_diagnosis"]

_MOVED_MM = 0.0005


def homing_diagnosis(code: int, before: Status | None, after: Status | None) -> str:
    """What went wrong in a failed ``$H`` and what to change (for :class:`GrblAlarm`'s message).

    Parameters
    ----------
    code : int
        The homing alarm (6-10).
    before, after : Status or None
        Status reports before ``$H`` and after the failure.
    """
    parts = []
    stuck = [a for a in "XYZ" if before is not None and a in before.pins]
    if stuck:
        parts.append(f"limit pin(s) {', '.join(stuck)} read triggered before homing started (Pn:{before.pins}): "
                     "normally-closed switches need $5=1, else check for a shorted or floating input")
    if before is not None and after is not None and before.mpos and after.mpos:
        moved = [abs(a - b) > _MOVED_MM for a, b in zip(before.mpos, after.mpos)]
        if not moved[0] and not moved[1]:
            z = "after Z moved, " if moved[2] else ""
            parts.append(f"the cycle stopped {z}before X or Y moved: stock GRBL homes Z first (HOMING_CYCLE_0 in "
                         "config.h); an XY gantry without a Z switch needs a Z limit switch or GRBL rebuilt with "
                         "HOMING_CYCLE_0 ((1<<X_AXIS)|(1<<Y_AXIS)) and no Z cycle")
    if not parts:
        parts.append(f"{ALARMS.get(code, 'homing failed')}: check the switches' wiring, the homing direction ($23) "
                     "and pull-off ($27)")
    return "; ".join(parts) + "; GRBL is locked until $X (unlock) or a successful $H"
