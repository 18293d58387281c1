"""GRBL 1.1 messages: status reports, error and alarm codes (gnea/grbl ``doc/markdown/interface.md``)."""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["ALARMS", "ERRORS", "GrblAlarm", "GrblError", "Status", "parse_status"]

#: ``error:N`` meanings (the ones a gantry meets; GRBL 1.1 ``error_codes``).
ERRORS = {
    1: "G-code words consist of a letter and a value; letter was not found",
    2: "numeric value format is not valid or missing an expected value",
    3: "'$' system command was not recognized or supported",
    4: "negative value received for an expected positive value",
    5: "homing cycle is not enabled via settings ($22)",
    8: "'$' command only valid when Idle",
    9: "G-code locked out during alarm or jog state",
    10: "soft limits cannot be enabled without homing also enabled",
    11: "max characters per line exceeded",
    15: "jog target exceeds machine travel",
    20: "unsupported or invalid G-code command found in block",
    22: "feed rate has not yet been set or is undefined",
    33: "motion command target is invalid",
}
#: ``ALARM:N`` meanings.
ALARMS = {
    1: "hard limit triggered; machine position is likely lost, re-homing is recommended",
    2: "soft limit: motion target exceeds machine travel; machine position retained, unlock with $X",
    3: "reset while in motion; machine position is likely lost, re-homing is recommended",
    4: "probe fail: the probe is not in the expected initial state",
    5: "probe fail: the probe did not contact the workpiece",
    6: "homing fail: reset during the homing cycle",
    7: "homing fail: safety door opened during homing",
    8: "homing fail: cycle failed to clear the limit switch when pulling off",
    9: "homing fail: could not find the limit switch within the search distance",
}


class GrblError(RuntimeError):
    """GRBL answered ``error:N`` to a line.

    Attributes
    ----------
    code : int
    line : str
        The line that was refused.
    """

    def __init__(self, code: int, line: str = "") -> None:
        self.code, self.line = int(code), line
        super().__init__(f"gantry refused {line!r}: error:{code} ({ERRORS.get(int(code), 'unknown error')})")


class GrblAlarm(RuntimeError):
    """GRBL raised ``ALARM:N``: the gantry stopped and locks out motion until ``$X`` or ``$H``."""

    def __init__(self, code: int, context: str = "") -> None:
        self.code = int(code)
        where = f" {context}" if context else ""
        super().__init__(f"gantry alarm{where}: ALARM:{code} ({ALARMS.get(int(code), 'unknown alarm')}); "
                         "it needs $X (unlock) or $H (home) before it moves again")


@dataclass(frozen=True)
class Status:
    """One ``<...>`` status report.

    Attributes
    ----------
    state : str
        Idle, Run, Hold, Jog, Alarm, Door, Check, Home or Sleep (sub-state after ``:`` dropped).
    mpos : tuple of float or None
        Machine position (x, y, z), mm.
    wpos : tuple of float or None
        Work position, mm.
    feed : float or None
        Current feed rate, mm/min.
    raw : str
    """

    state: str
    mpos: tuple | None
    wpos: tuple | None
    feed: float | None
    raw: str

    @property
    def position(self) -> tuple:
        """Machine position when reported, else work position (mm)."""
        return self.mpos if self.mpos is not None else self.wpos


def _floats(text: str) -> tuple:
    return tuple(float(v) for v in text.split(","))


def parse_status(line: str, wco: tuple | None = None) -> Status:
    """Parse ``<Idle|MPos:0.000,0.000,0.000|FS:0,0>``.

    Parameters
    ----------
    line : str
    wco : tuple, optional
        The last work coordinate offset (GRBL sends ``WCO`` only now and then),
        to derive MPos from WPos or the reverse.

    Raises
    ------
    ValueError
        Not a status report.
    """
    s = line.strip()
    if not (s.startswith("<") and s.endswith(">")):
        raise ValueError(f"not a GRBL status report: {line!r}")
    fields = s[1:-1].split("|")
    state = fields[0].split(":")[0]
    mpos = wpos = feed = None
    for f in fields[1:]:
        key, _, val = f.partition(":")
        try:
            if key == "MPos":
                mpos = _floats(val)
            elif key == "WPos":
                wpos = _floats(val)
            elif key == "WCO":
                wco = _floats(val)
            elif key in ("FS", "F"):
                feed = float(val.split(",")[0])
        except ValueError:
            raise ValueError(f"bad field {f!r} in GRBL status {line!r}") from None
    if mpos is None and wpos is None:
        raise ValueError(f"GRBL status {line!r} has neither MPos nor WPos")
    if wco is not None:
        if mpos is None:
            mpos = tuple(a + b for a, b in zip(wpos, wco))
        elif wpos is None:
            wpos = tuple(a - b for a, b in zip(mpos, wco))
    return Status(state, mpos, wpos, feed, s)
