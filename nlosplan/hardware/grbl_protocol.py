"""GRBL 1.1 messages and rules: status reports, settings, build info, error and alarm codes.

Facts from the GRBL 1.1h source and documentation (gnea/grbl ``doc/markdown``,
``doc/csv``, ``grbl/settings.c``, ``grbl/system.c``, ``grbl/protocol.c``),
checked against the real firmware built with grbl-sim (``tests/grbl_firmware.py``):

- Every ``\\r`` and every ``\\n`` ends a line and every line, empty ones too,
  is answered ``ok`` or ``error:N``.
- The machine space of every axis is ``[-max_travel, 0]`` (``$130..$132``);
  only a build with ``HOMING_FORCE_SET_ORIGIN`` (``$I`` option ``Z``) and a
  negative homing direction (``$23`` bit set) gives ``[0, max_travel]``.
- G0/G1 targets are work coordinates: machine = work + WCO (G54..G59 offset
  plus G92 offset); ``MPos`` in status reports is the machine position.
- Soft limits (``$20=1``) need homing enabled (``$22=1``), else ``error:10``;
  ``$22=0`` also switches soft limits off.
- After ALARM:1 (hard limit) or ALARM:2 (soft limit) GRBL ignores everything,
  status requests and ``$X`` included, until a soft reset (0x18); after the
  reset it is locked in Alarm until ``$X`` (unlock) or ``$H`` (home).
- At power-up with homing enabled GRBL starts locked in Alarm
  (``[MSG:'$H'|'$X' to unlock]``); stock ``config.h`` homes Z first.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["ALARMS", "CRITICAL_ALARMS", "ERRORS", "BuildInfo", "GrblAlarm", "GrblError", "Status", "machine_space",
           "parse_build_info", "parse_ngc_parameters", "parse_settings", "parse_status", "setting_error"]

#: ``error:N`` meanings (GRBL 1.1 ``doc/csv/error_codes_en_US.csv``).
ERRORS = {
    1: "G-code words consist of a letter and a value; letter was not found",
    2: "numeric value format is not valid or missing an expected value",
    3: "'$' system command was not recognized or supported",
    4: "negative value received for an expected positive value",
    5: "homing cycle is not enabled via settings ($22)",
    6: "minimum step pulse time must be greater than 3 us ($0)",
    7: "EEPROM read failed; defaults restored",
    8: "'$' command only valid when Idle",
    9: "G-code locked out during alarm or jog state",
    10: "soft limits ($20) cannot be enabled without homing ($22) also enabled",
    11: "max characters per line exceeded",
    12: "setting value makes the step rate exceed the maximum supported",
    13: "safety door detected as opened",
    14: "build info or startup line exceeded the EEPROM line length",
    15: "jog target exceeds machine travel",
    16: "jog command has no '=' or contains prohibited g-code",
    17: "laser mode requires PWM output",
    20: "unsupported or invalid g-code command found in block",
    21: "more than one g-code command from the same modal group in block",
    22: "feed rate has not yet been set or is undefined",
    23: "g-code command in block requires an integer value",
    24: "more than one g-code command that requires axis words in block",
    25: "repeated g-code word found in block",
    26: "no axis words found in block for a command that requires them",
    27: "line number value is invalid",
    28: "g-code command is missing a required value word",
    29: "G59.x work coordinate systems are not supported",
    30: "G53 only allowed with G0 and G1 motion modes",
    31: "axis words found in block when no command or modal state uses them",
    32: "G2 and G3 arcs require at least one in-plane axis word",
    33: "motion command target is invalid",
    34: "arc radius value is invalid",
    35: "G2 and G3 arcs require at least one in-plane offset word",
    36: "unused value words found in block",
    37: "G43.1 dynamic tool length offset is not assigned to the tool length axis",
    38: "tool number greater than max supported value",
}
#: ``ALARM:N`` meanings (``doc/csv/alarm_codes_en_US.csv``).
ALARMS = {
    1: "hard limit triggered; machine position is likely lost",
    2: "soft limit: motion target exceeds machine travel; machine position retained",
    3: "reset while in motion; machine position is likely lost",
    4: "probe fail: the probe is not in the expected initial state",
    5: "probe fail: the probe did not contact the workpiece",
    6: "homing fail: reset during the homing cycle",
    7: "homing fail: safety door opened during homing",
    8: "homing fail: pull-off failed to clear the limit switch",
    9: "homing fail: could not find the limit switch within the search distance",
    10: "homing fail: second dual-axis limit switch did not trigger",
}
#: Alarms after which GRBL ignores everything (status requests and $X too) until a soft reset.
CRITICAL_ALARMS = frozenset({1, 2})
#: Alarms after which the machine position is likely lost (re-homing recommended).
POSITION_LOST = frozenset({1, 3})


def alarm_needs(code: int) -> str:
    """What GRBL needs after ``ALARM:code`` before it moves again (one clause)."""
    if code in CRITICAL_ALARMS:
        then = "re-home ($H)" if code in POSITION_LOST else "unlock ($X, the position is retained) or home ($H)"
        return f"GRBL ignores everything, status requests and $X included, until a soft reset (0x18); then {then}"
    if code in POSITION_LOST:
        return "GRBL is locked until $H (home; recommended, the position is likely lost) or $X (unlock)"
    return "GRBL is locked until $X (unlock) or $H (home)"


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
    """GRBL raised ``ALARM:N`` (or reports the Alarm state): it stopped and locks out motion.

    Attributes
    ----------
    code : int
        The alarm number (0: the state is Alarm but no number was seen, e.g. the power-up lock).
    """

    def __init__(self, code: int, context: str = "", detail: str = "") -> None:
        self.code = int(code)
        where = f" {context}" if context else ""
        meaning = ALARMS.get(self.code, "locked in the Alarm state")
        text = detail or alarm_needs(self.code)
        super().__init__(f"gantry alarm{where}: ALARM:{code} ({meaning}); {text}")

    @property
    def critical(self) -> bool:
        """True when GRBL ignores everything until a soft reset (ALARM:1, ALARM:2)."""
        return self.code in CRITICAL_ALARMS


@dataclass(frozen=True)
class Status:
    """One ``<...>`` status report.

    Attributes
    ----------
    state : str
        Idle, Run, Hold, Jog, Alarm, Door, Check, Home or Sleep.
    substate : str
        After the ``:`` (``Hold:0`` ready to resume, ``Hold:1`` decelerating), else "".
    mpos : tuple of float or None
        Machine position (x, y, z), mm.
    wpos : tuple of float or None
        Work position (x, y, z), mm (machine position minus the work offset).
    feed : float or None
        Current feed rate, mm/min.
    wco : tuple of float or None
        The work coordinate offset in this report (GRBL sends it now and then), or None.
    pins : str
        Active input pins (``Pn:``): P probe, X/Y/Z limits, D door, R reset, H hold, S start.
    raw : str
    """

    state: str
    mpos: tuple | None
    wpos: tuple | None
    feed: float | None
    raw: str
    wco: tuple | None = None
    pins: str = ""
    substate: str = ""

    @property
    def position(self) -> tuple:
        """Machine position when known, else work position (mm)."""
        return self.mpos if self.mpos is not None else self.wpos


def _floats(text: str) -> tuple:
    return tuple(float(v) for v in text.split(","))


def parse_status(line: str, wco: tuple | None = None) -> Status:
    """Parse ``<Idle|MPos:0.000,0.000,0.000|FS:0,0|WCO:...>``.

    Parameters
    ----------
    line : str
    wco : tuple, optional
        The last known work coordinate offset, to derive MPos from WPos or the
        reverse when the report has no ``WCO`` field.

    Raises
    ------
    ValueError
        Not a status report.
    """
    s = line.strip()
    if not (s.startswith("<") and s.endswith(">")):
        raise ValueError(f"not a GRBL status report: {line!r}")
    fields = s[1:-1].split("|")
    state, _, sub = fields[0].partition(":")
    mpos = wpos = feed = own_wco = None
    pins = ""
    for f in fields[1:]:
        key, _, val = f.partition(":")
        try:
            if key == "MPos":
                mpos = _floats(val)
            elif key == "WPos":
                wpos = _floats(val)
            elif key == "WCO":
                own_wco = _floats(val)
            elif key in ("FS", "F"):
                feed = float(val.split(",")[0])
            elif key == "Pn":
                pins = val
        except ValueError:
            raise ValueError(f"bad field {f!r} in GRBL status {line!r}") from None
    if mpos is None and wpos is None:
        raise ValueError(f"GRBL status {line!r} has neither MPos nor WPos")
    offset = own_wco if own_wco is not None else wco
    if offset is not None:
        if mpos is None:
            mpos = tuple(a + b for a, b in zip(wpos, offset))
        elif wpos is None:
            wpos = tuple(a - b for a, b in zip(mpos, offset))
    return Status(state, mpos, wpos, feed, s, own_wco, pins, sub)


def parse_settings(lines) -> dict[int, float]:
    """``$N=value`` lines (the answer to ``$$``) as ``{N: value}``."""
    out: dict[int, float] = {}
    for line in lines:
        if line.startswith("$") and "=" in line:
            k, _, v = line[1:].partition("=")
            try:
                out[int(k)] = float(v.split()[0])
            except (ValueError, IndexError):
                continue
    return out


@dataclass(frozen=True)
class BuildInfo:
    """The answer to ``$I``: ``[VER:1.1h.20190830:]`` and ``[OPT:V,15,128]``.

    Attributes
    ----------
    version : str
        e.g. ``1.1h``.
    build : str
        Build date, e.g. ``20190830``.
    options : str
        Build option letters (``Z``: HOMING_FORCE_SET_ORIGIN, ``C``: CoreXY, ...).
    blocks, rx_buffer : int or None
        Planner blocks and serial receive buffer size.
    """

    version: str
    build: str
    options: str = ""
    blocks: int | None = None
    rx_buffer: int | None = None

    @property
    def force_origin(self) -> bool:
        """Built with HOMING_FORCE_SET_ORIGIN (option ``Z``)."""
        return "Z" in self.options


def parse_build_info(lines) -> BuildInfo | None:
    """Parse the ``$I`` answer; None when it has no ``[VER:`` line."""
    version = build = None
    options, blocks, rx = "", None, None
    for line in lines:
        if line.startswith("[VER:"):
            ver = line[5:].rstrip("]").split(":")[0]
            version, _, build = ver.rpartition(".") if ver.count(".") >= 2 else (ver, "", "")
        elif line.startswith("[OPT:"):
            parts = line[5:].rstrip("]").split(",")
            options = parts[0]
            try:
                blocks, rx = int(parts[1]), int(parts[2])
            except (IndexError, ValueError):
                pass
    if version is None:
        return None
    return BuildInfo(version, build, options, blocks, rx)


def parse_ngc_parameters(lines) -> dict[str, tuple]:
    """The answer to ``$#`` as ``{"G54": (x, y, z), ..., "G92": (...), "TLO": (v,)}``."""
    out: dict[str, tuple] = {}
    for line in lines:
        if line.startswith("[") and ":" in line:
            key, _, val = line[1:].rstrip("]").partition(":")
            try:
                out[key] = tuple(float(v) for v in val.split(":")[0].split(","))
            except ValueError:
                continue
    return out


def machine_space(settings: dict, force_origin: bool = False) -> tuple[tuple[float, float], ...]:
    """The machine space ``((xmin, xmax), (ymin, ymax), (zmin, zmax))`` in mm that soft limits allow.

    ``[-max_travel, 0]`` per axis; ``[0, max_travel]`` only for an axis that
    homes toward negative (``$23`` bit set) on a build with HOMING_FORCE_SET_ORIGIN.
    """
    mask = int(settings.get(23, 0))
    out = []
    for axis in range(3):
        travel = float(settings.get(130 + axis, 200.0))
        out.append((0.0, travel) if force_origin and mask & (1 << axis) else (-travel, 0.0))
    return tuple(out)


def setting_error(settings: dict, number: int, value: float, *, variable_spindle: bool = True) -> int | None:
    """The ``error:N`` GRBL 1.1h answers to ``$number=value`` with these settings, or None (accepted).

    The rules of ``settings_store_global_setting``: negative values (4),
    ``$0`` below 3 us (6), soft limits without homing (10), unknown numbers (3),
    laser mode without a PWM spindle (17).
    """
    if value < 0:
        return 4
    known = {0, 1, 2, 3, 4, 5, 6, 10, 11, 12, 13, 20, 21, 22, 23, 24, 25, 26, 27, 30, 31, 32}
    known |= {b + a for b in (100, 110, 120, 130) for a in range(3)}
    if number not in known:
        return 3
    if number == 0 and int(value) < 3:
        return 6
    if number == 20 and int(value) and not int(settings.get(22, 0)):
        return 10
    if number == 32 and not variable_spindle:
        return 17
    return None
