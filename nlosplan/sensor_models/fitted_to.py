"""What real data a sensor's values were fitted to: its ``fitted_to`` record.

A record is a list of :class:`RealSource`, one per real source of values:
the source (``"DENALI Table 2"``), what of it was used and how, where it is
(``ref``: a path or an outside reference, with its ``sha256`` when it is a
file the project ships), whether its values were fitted on data of this
sensor (``use = "fitted"``) or measured on another unit or mode and assumed
for this one (``"assumed"``), and the sensor fields it gave with their values
(``parameters``). A calibration also records the scene parameters and protocol
nuisances it fitted with them (``scene``), what it held fixed (``held``) and
the command that made it (``by``).

Every preset has one (:func:`.preset_sources.preset_record`), written from
the facts of :mod:`.presets` and :mod:`.presets_denali`;
:func:`.preset_sources.sensor_record` finds the record of any sensor spec.
``nlosplan calibrate --stats`` writes one into its sensor file as
``[[fitted_to]]`` tables; a sensor file
loaded back keeps it, a file with ``base`` and no record takes its base
preset's, and a file with neither has none ("not recorded"). An empty record
(``fitted_to = []``) means values from datasheets alone. Parameters whose
value in the sensor differs from the record's (a field a file changed) are
no longer fitted to the source: :func:`current_record` drops them and names
them. The record is not a :class:`~.config.SensorConfig` field, so it changes
no sensor's equality or the caches keyed by its fields.
"""

from __future__ import annotations

import dataclasses
import math
import re
from dataclasses import dataclass, field

from nlosplan.errors import UserError, check_keys

#: Kinds of use: fitted on data of this sensor, or measured on another unit or mode and assumed for this one.
USES = ("fitted", "assumed")
#: The keys of one entry, required first.
REQUIRED_KEYS = ("source", "what", "ref", "use", "parameters")
OPTIONAL_KEYS = ("sha256", "by", "scene", "held")


@dataclass(frozen=True)
class RealSource:
    """One real source of a sensor's values (see the module docstring).

    Attributes
    ----------
    source : str
        Its name, e.g. ``"DENALI Table 2"``.
    what : str
        What of it was used, and how.
    ref : str
        A path (package data, ``../shared/data``, a file given to a command) or an outside reference.
    use : {"fitted", "assumed"}
    parameters : dict
        Sensor field -> the value this source gave (numbers, or lists for ``pulse_shape`` and per-zone fields).
    sha256 : str
        Content hash of the file ``ref`` names ("" when not a file).
    by : str
        The command or method that made the values.
    scene : dict
        Scene parameters and protocol nuisances fitted with the sensor fields -> value (not sensor fields).
    held : dict
        Parameters the fit held fixed -> value.
    """

    source: str
    what: str
    ref: str
    use: str
    parameters: dict
    sha256: str = ""
    by: str = ""
    scene: dict = field(default_factory=dict)
    held: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        """Plain data for JSON and TOML (empty optional fields left out)."""
        out = {"source": self.source, "what": self.what, "ref": self.ref, "use": self.use,
               "parameters": {k: list(v) if isinstance(v, tuple) else v for k, v in self.parameters.items()}}
        for k in OPTIONAL_KEYS:
            v = getattr(self, k)
            if v:
                out[k] = dict(v) if isinstance(v, dict) else v
        return out

    @classmethod
    def from_dict(cls, data, where: str = "fitted_to[0]") -> "RealSource":
        """Parse one entry; a missing, extra or wrongly typed key is a one-line :class:`UserError` naming it."""
        if not isinstance(data, dict):
            raise UserError(f"{where} must be a table of {', '.join(REQUIRED_KEYS)}")
        check_keys(data, REQUIRED_KEYS + OPTIONAL_KEYS, "key(s)", prefix=f"{where}: ")
        for k in REQUIRED_KEYS:
            if k not in data:
                raise UserError(f"{where}: missing key {k}")
        for k in ("source", "what", "ref", "sha256", "by"):
            if k in data and not isinstance(data[k], str):
                raise UserError(f"{where}.{k} must be a string, got {data[k]!r}")
        if data["use"] not in USES:
            raise UserError(f"{where}.use is {data['use']!r}; allowed: {', '.join(USES)}")
        sha = data.get("sha256", "")
        if sha and not re.fullmatch(r"[0-9a-f]{64}", sha):
            raise UserError(f"{where}.sha256 must be 64 lower-case hex digits, got {sha!r}")
        fields = {f.name for f in dataclasses.fields(_sensor_config())}
        params = _values(data["parameters"], f"{where}.parameters")
        bad = [k for k in params if k not in fields or k in ("name", "notes")]
        if bad:
            raise UserError(f"{where}.parameters: {bad[0]!r} is not a sensor field")
        return cls(source=data["source"], what=data["what"], ref=data["ref"], use=data["use"], parameters=params,
                   sha256=sha, by=data.get("by", ""), scene=_values(data.get("scene", {}), f"{where}.scene"),
                   held=_values(data.get("held", {}), f"{where}.held"))


def _sensor_config():
    from nlosplan.sensor_models.config import SensorConfig

    return SensorConfig


def _values(table, where: str) -> dict:
    """A table of name -> number, bool or list of numbers (lists become tuples)."""
    if not isinstance(table, dict):
        raise UserError(f"{where} must be a table of name = value")
    out = {}
    for k, v in table.items():
        if isinstance(v, list) and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v):
            out[k] = tuple(v)
        elif isinstance(v, (bool, int, float)):
            out[k] = v
        else:
            raise UserError(f"{where}.{k} must be a number, true/false or a list of numbers, got {v!r}")
    return out


def parse_record(value, where: str = "fitted_to") -> tuple[RealSource, ...]:
    """A ``fitted_to`` list as read from a sensor file (one-line :class:`UserError` naming a bad entry)."""
    if not isinstance(value, list):
        raise UserError(f"{where} must be a list of tables ([[fitted_to]] in TOML), got {type(value).__name__}")
    return tuple(RealSource.from_dict(d, f"{where}[{i}]") for i, d in enumerate(value))


def record_dicts(record) -> list[dict]:
    """The record as plain data (``[]`` for none)."""
    return [s.to_dict() for s in record or ()]


def same_value(a, b) -> bool:
    """Whether a record's value and a sensor's agree (floats to 1e-9 relative; lists element by element)."""
    if isinstance(a, (list, tuple)) or isinstance(b, (list, tuple)):
        return (isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)) and len(a) == len(b)
                and all(same_value(x, y) for x, y in zip(a, b)))
    if isinstance(a, bool) or isinstance(b, bool) or a is None or b is None:
        return a is b or a == b
    return math.isclose(float(a), float(b), rel_tol=1e-9, abs_tol=1e-12)


def current_record(sensor, record) -> tuple[tuple[RealSource, ...], list[str]]:
    """The record as far as it still holds for ``sensor``, and the parameters it no longer holds for.

    A parameter whose value in ``sensor`` differs from the record's was changed after the fit (a sensor file's
    own value, a hand edit): it is dropped from its entry and named. An entry left with no parameter is dropped
    (its scene values went with the sensor fields they were fitted with).
    """
    kept, changed = [], []
    for s in record or ():
        params = {k: v for k, v in s.parameters.items() if same_value(v, getattr(sensor, k))}
        changed += [k for k in s.parameters if k not in params and k not in changed]
        if params:
            kept.append(dataclasses.replace(s, parameters=params))
    return tuple(kept), changed


def without(record, names) -> tuple[RealSource, ...]:
    """The record with the parameters (sensor fields, scene values) in ``names`` removed: they were refitted.

    An entry left with no sensor parameter is dropped."""
    names = set(names)
    out = []
    for s in record or ():
        params = {k: v for k, v in s.parameters.items() if k not in names}
        if params:
            out.append(dataclasses.replace(s, parameters=params,
                                           scene={k: v for k, v in s.scene.items() if k not in names}))
    return tuple(out)


# ----------------------------------------------------------------------------------------------------- shown
def _shown(v) -> str:
    if isinstance(v, (list, tuple)):
        return f"({len(v)} values)"
    return f"{v:.6g}" if isinstance(v, float) else str(v)


def _pairs(d: dict) -> str:
    return ", ".join(f"{k} = {_shown(v)}" for k, v in d.items())


def _entry_lines(sources) -> list[str]:
    lines = []
    for s in sources:
        lines.append(f"  - {s.source}: {s.ref}" + (f" (sha256 {s.sha256[:16]}...)" if s.sha256 else ""))
        lines.append(f"      {s.what}")
        lines.append(f"      gave: {_pairs(s.parameters)}")
        if s.scene:
            lines.append(f"      with scene/nuisances: {_pairs(s.scene)}")
        if s.held:
            lines.append(f"      held fixed: {_pairs(s.held)}")
        if s.by:
            lines.append(f"      by: {s.by}")
    return lines


def record_lines(record, changed=(), origin: str = "") -> list[str]:
    """``sensor show``'s "fitted to:" section: each source with its reference, hash and values."""
    if record is None:
        return [f"fitted to: not recorded: {origin}"]
    fitted = [s for s in record if s.use == "fitted"]
    assumed = [s for s in record if s.use == "assumed"]
    if not record:  # an empty record in a file (datasheet values), or every recorded value changed since
        lines = ["fitted to no real data" + (" any more" if changed else " (datasheet values)")]
    elif not fitted:
        lines = ["fitted to no real data of this sensor; values assumed from real data of another unit or mode:"]
    else:
        lines = ["fitted to:"] + _entry_lines(fitted)
        if assumed:
            lines.append("assumed from real data of another unit or mode (not fitted to this sensor):")
    lines += _entry_lines(assumed)
    if changed:
        lines.append(f"  changed since the record (no longer fitted to it): {', '.join(changed)}")
    if origin:
        lines.append(f"  (record: {origin})")
    return lines


def record_summary(record) -> str:
    """A few words for ``sensor list``: the sources fitted to (``"DENALI Table 2 + checkpoint levels"``), else
    ``"none (assumed)"`` (values from real data of another unit or mode), ``"none (datasheet)"`` or
    ``"not recorded"``."""
    if record is None:
        return "not recorded"
    names = list(dict.fromkeys(s.source.split(":")[0] for s in record if s.use == "fitted"))
    if not names:
        return "none (assumed)" if record else "none (datasheet)"
    heads = {n.split(" ", 1)[0] for n in names}
    if len(names) > 1 and len(heads) == 1 and all(" " in n for n in names):  # "DENALI Table 2 + checkpoint levels"
        return heads.pop() + " " + " + ".join(n.split(" ", 1)[1] for n in names)
    return " + ".join(names)
