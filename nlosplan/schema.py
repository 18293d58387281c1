"""Configuration files (TOML, JSON) and numbers: read with one-line errors, type- and range-checked.

:func:`read_text` turns every way a file can fail to be text (missing, a
folder, a FIFO or device, too large, unreadable, binary, not UTF-8) into one
line; :func:`load_table` parses ``.toml`` or ``.json`` into a mapping, capped
in nesting depth (:data:`MAX_DEPTH`) and in items per array or table
(:data:`MAX_ITEMS`), a JSON key given twice refused. :func:`check_table`
checks a mapping against a schema of :class:`Spec` values (:data:`INT`,
:func:`int_in`, :data:`NUMBER`, :func:`number_in`, :func:`quantity`,
:data:`STRING`, :func:`one_of`, :data:`BOOL`, :func:`list_of`) when the file
is read, before any work: a wrong type is one line naming the key (with its
table) and the expected type.

Numbers have one layer shared by the command line and the files:
:func:`parse_int` and :func:`parse_number` read text strictly (ASCII digits
only: no ``1_0``, no other scripts' digits) and :data:`QUANTITIES` holds the
physical range of every physical quantity a flag or a file field may set
(a bin width, a jitter, a feed rate, ...); :func:`check_quantity` and
:func:`quantity` apply it.
"""

from __future__ import annotations

import json
import math
import os
import re
import stat
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Mapping

from nlosplan.errors import UserError, check_keys

__all__ = ["Spec", "INT", "NUMBER", "STRING", "BOOL", "int_in", "number_in", "one_of", "predicate", "list_of", "pair_of",
           "table_of", "check_table", "check_types", "check_value", "read_text", "load_table", "loads",
           "MAX_DEPTH", "MAX_ITEMS", "MAX_FILE_BYTES", "Quantity", "QUANTITIES", "check_quantity", "quantity",
           "parse_int", "parse_number", "shown", "regular_file"]

#: Deepest nesting of tables and arrays a configuration file may have (the files nlosplan reads need 4).
MAX_DEPTH = 32
#: Most items one array (or keys one table) of a configuration file may hold.
MAX_ITEMS = 100_000
#: Largest configuration file read (bytes).
MAX_FILE_BYTES = 64 * 2**20


# ----------------------------------------------------------------------------- numbers
_INT_TEXT = re.compile(r"[+-]?[0-9]+", re.ASCII)
_NUMBER_TEXT = re.compile(r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?|[+-]?(?:inf|infinity|nan)",
                          re.ASCII | re.IGNORECASE)


def shown(value, limit: int = 40) -> str:
    """``value`` for a message (a string quoted), cut to ``limit`` characters: a message never carries a huge value."""
    text = value if isinstance(value, str) else repr(value)
    if len(text) <= limit:
        return repr(value) if isinstance(value, str) else text
    return repr(text[:limit]) + f"... ({len(text)} characters)"


def parse_int(text: str) -> int:
    """An integer written in ASCII digits (an optional sign; spaces around allowed).

    Stricter than ``int()``, which also takes ``1_0`` and digits of other
    scripts (``٣``). Raises ValueError with a one-line message.
    """
    t = str(text).strip(" \t")
    if len(t) > 400 or not _INT_TEXT.fullmatch(t):
        raise ValueError(f"{shown(text)} is not an integer (ASCII digits only)")
    return int(t)


def parse_number(text: str) -> float:
    """A decimal number written in ASCII (``12``, ``-0.5``, ``1e-3``; ``inf``/``nan`` parse, the caller refuses them).

    Stricter than ``float()``, which also takes ``1_0`` and digits of other
    scripts. Raises ValueError with a one-line message.
    """
    t = str(text).strip(" \t")
    if len(t) > 400 or not _NUMBER_TEXT.fullmatch(t):
        raise ValueError(f"{shown(text)} is not a number")
    return float(t)


@dataclass(frozen=True)
class Quantity:
    """The physical range of a quantity a flag or a file field sets (one statement, used everywhere).

    Attributes
    ----------
    lo, hi : float
        Smallest and largest value allowed (inclusive; ``lo`` exclusive with ``lo_open``).
    unit : str
    what : str
        What it is, for messages and the documentation.
    lo_open : bool
    """

    lo: float
    hi: float
    unit: str
    what: str
    lo_open: bool = False

    def allowed(self) -> str:
        """``"1 to 1e+06 ps"`` (``"> 0 and <= 10 m"`` when the low end is open)."""
        unit = f" {self.unit}" if self.unit else ""
        if self.lo_open:
            return f"> {self.lo:g} and <= {self.hi:g}{unit}"
        return f"{self.lo:g} to {self.hi:g}{unit}"

    def contains(self, value: float) -> bool:
        return (value > self.lo if self.lo_open else value >= self.lo) and value <= self.hi


#: The physical range of every quantity a flag or a file field may set: the sensor model's fields (a sensor file,
#: ``SensorConfig``), the flags that set them (``--jitter-ps``, ``--bin-width-ps``, ``--photon-scale``) and the rig's
#: motion (``--settle``, ``--feed``, ``--time-scale``, ``--limits``, ``--work-offset``). Wide enough for every
#: sensor, rig and stability case the project knows, narrow enough that no value inside makes the arithmetic
#: overflow, underflow to zero or take forever.
QUANTITIES: dict[str, Quantity] = {
    "bin_width_ps": Quantity(1.0, 1e6, "ps", "histogram bin width (1 ps: finer than any TDC; 1 us: a 150 m bin)"),
    "jitter_fwhm_ps": Quantity(0.0, 1e7, "ps", "timing jitter FWHM (10 us: ~800 TMF8828 windows, beyond the "
                               "stability catalog's widest)"),
    "pulse_fwhm_ps": Quantity(0.0, 1e7, "ps", "laser pulse FWHM"),
    "start_offset_ps": Quantity(-1e7, 1e7, "ps", "time of bin 0's left edge"),
    "pulse_shape_step_ps": Quantity(1.0, 1e6, "ps", "width of one pulse-shape sample"),
    "pulse_shape_t0_ps": Quantity(-1e7, 1e7, "ps", "start of the pulse shape"),
    "pulse_tail_decay_ps": Quantity(1.0, 1e7, "ps", "e-folding time of the pulse tail"),
    "dead_time_ps": Quantity(0.01, 1e12, "ps", "a detector's dead time"),
    "zone_time_offsets_ps": Quantity(-1e7, 1e7, "ps", "a zone's time offset"),
    "photon_scale": Quantity(0.0, 1e12, "", "detected photons per iteration per unit response"),
    "ambient_rate_hz": Quantity(0.0, 1e12, "Hz", "ambient photon rate per zone"),
    "dark_rate_hz": Quantity(0.0, 1e12, "Hz", "dark-count rate per zone"),
    "crosstalk": Quantity(0.0, 1e9, "", "crosstalk photons per iteration per zone"),
    "sensitivity_cos_power": Quantity(0.0, 100.0, "", "off-axis sensitivity exponent"),
    "zone_gains": Quantity(0.0, 1e6, "", "a zone's relative gain"),
    "zone_overlap_m": Quantity(0.0, 1e3, "m", "a zone's near-field overlap distance"),
    "albedo": Quantity(0.0, 1.0, "", "an albedo"),
    "settle_s": Quantity(0.0, 3600.0, "s", "wait after each gantry move"),
    "feed_mm_min": Quantity(1.0, 100_000.0, "mm/min", "gantry feed rate"),
    "time_scale": Quantity(0.1, 10_000.0, "", "how much faster an emulated gantry moves"),
    "gantry_mm": Quantity(-10_000.0, 10_000.0, "mm", "a gantry coordinate: limits, work offset (within 10 m)"),
    "position_m": Quantity(-100.0, 100.0, "m", "a position label"),
    "scene_m": Quantity(-100.0, 100.0, "m", "a coordinate or size in a scene"),
    "distance_m": Quantity(0.0, 100.0, "m", "a distance in a scene", lo_open=True),
    "min_distance_m": Quantity(0.0, 100.0, "m", "the nearest capture scored"),
    "object_size_m": Quantity(0.0, 10.0, "m", "a hidden object's size", lo_open=True),
    "angle_deg": Quantity(-360.0, 360.0, "deg", "a turn or tilt"),
    "wall_samples": Quantity(1, 256, "", "sub-rays per zone axis (the wall scene's fidelity)"),
    "seconds": Quantity(0.01, 3600.0, "s", "a timed duration"),
    "budget_s": Quantity(0.01, 1e7, "s", "a wall-clock budget"),
    "model_width": Quantity(0.01, 16.0, "", "a model size factor (1: the paper's)"),
    "threads": Quantity(1, 1024, "", "CPU threads"),
    "target_rmse_m": Quantity(0.0, 10.0, "m", "a localization RMSE target", lo_open=True),
}


def check_quantity(name: str, value, shown_as: str | None = None) -> float:
    """``value`` as a float when it is a finite number within ``QUANTITIES[name]``, else UserError.

    The message is ``{shown_as}={value} is out of range; allowed: {lo} to {hi} {unit}`` (``shown_as``
    defaults to ``name``).
    """
    q = QUANTITIES[name]
    label = shown_as or name
    if isinstance(value, bool) or not isinstance(value, (int, float)) and not hasattr(value, "__float__"):
        raise UserError(f"{label}={value!r} must be a number")
    v = float(value)
    if not math.isfinite(v):
        raise UserError(f"{label}={v} must be finite")
    if not q.contains(v):
        raise UserError(f"{label}={v:g} is out of range; allowed: {q.allowed()}")
    return v


def quantity(name: str) -> "Spec":
    """A :class:`Spec` for a config-file value: a finite number within ``QUANTITIES[name]``, as a float."""
    q = QUANTITIES[name]
    return Spec(f"a number from {q.allowed()}" if not q.lo_open else f"a number {q.allowed()}",
                lambda v: float(v) if _is_number(v) and q.contains(float(v)) else _BAD)


# ----------------------------------------------------------------------------- reading
_KINDS = ((stat.S_ISFIFO, "a FIFO (named pipe)"), (stat.S_ISCHR, "a character device"),
          (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"))


def regular_file(path, what: str = "file") -> os.stat_result:
    """``os.stat(path)`` of an existing regular file; UserError naming a folder, a FIFO, a device or a socket.

    Checked before a file is opened: opening a FIFO waits for a writer and a device may never end.
    """
    p = Path(path)
    try:
        st = p.stat()
    except FileNotFoundError:
        raise UserError(f"{what} {p} does not exist") from None
    except OSError as exc:
        raise UserError(f"cannot read {what} {p}: {exc.strerror or exc}") from None
    if stat.S_ISDIR(st.st_mode):
        raise UserError(f"{what} {p} is a folder, not a file")
    for test, kind in _KINDS:
        if test(st.st_mode):
            raise UserError(f"{what} {p} is {kind}, not a regular file")
    return st


def read_text(path, what: str = "file", *, max_bytes: int = MAX_FILE_BYTES) -> str:
    """The UTF-8 text of ``path``; UserError (one line) when it cannot be read as text.

    Parameters
    ----------
    path : str or Path
    what : str
        What the file is, for the message (e.g. ``"sensor file"``).
    max_bytes : int
        Largest file read (a configuration file: :data:`MAX_FILE_BYTES`; data files may allow more).
    """
    p = Path(path)
    st = regular_file(p, what)
    if st.st_size > max_bytes:
        raise UserError(f"{what} {p} holds {st.st_size / 2**20:.0f} MB; it may hold at most "
                        f"{max_bytes // 2**20} MB")
    try:
        data = p.read_bytes()
    except IsADirectoryError:
        raise UserError(f"{what} {p} is a folder, not a file") from None
    except OSError as exc:
        raise UserError(f"cannot read {what} {p}: {exc.strerror or exc}") from None
    nul = data.find(b"\x00")
    if nul >= 0:
        raise UserError(f"{what} {p} is a binary file, not text (a NUL byte at offset {nul})")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise UserError(f"{what} {p} is not UTF-8 text (byte 0x{data[exc.start]:02x} at offset {exc.start})") from None


class _DuplicateKey(ValueError):
    def __init__(self, key: str):
        super().__init__(key)
        self.key = key


def _no_duplicates(pairs):
    out = {}
    for key, value in pairs:
        if key in out:
            raise _DuplicateKey(key)
        out[key] = value
    return out


def loads(text: str, kind: str, where: str) -> Any:
    """Parse TOML or JSON text (``kind`` ``"toml"`` or ``"json"``) with the limits of every configuration file.

    JSON keys given twice in one object, nesting deeper than :data:`MAX_DEPTH`
    and arrays or tables of more than :data:`MAX_ITEMS` items are refused
    with one line naming the key (never the value). ``where`` starts the
    message (e.g. ``"sensor file s.json"``).

    Raises
    ------
    UserError
    """
    try:
        if kind == "toml":
            data = tomllib.loads(text)
        else:
            data = json.loads(text, object_pairs_hook=_no_duplicates)
    except RecursionError:
        raise UserError(f"{where}: {_deep_key(text, kind)} is nested deeper than {MAX_DEPTH} levels") from None
    except tomllib.TOMLDecodeError as exc:
        raise UserError(f"{where} is not valid TOML: {exc}") from None
    except _DuplicateKey as exc:
        raise UserError(f"{where}: the key {shown(exc.key)} is given twice in one object; give each key once") \
            from None
    except json.JSONDecodeError as exc:
        raise UserError(f"{where} is not valid JSON: {exc.msg} at line {exc.lineno}") from None
    except ValueError as exc:  # e.g. an integer of more than 4300 digits
        raise UserError(f"{where} is not valid {kind.upper()}: {str(exc).splitlines()[0][:120]}") from None
    _check_size(data, where)
    return data


def _name(path: list) -> str:
    """The field a key path names, for a message: its keys joined by dots (``space.zones``; array indices left
    out), each cut to 40 characters, at most 6."""
    keys = [str(p) if len(str(p)) <= 40 else str(p)[:40] + "..." for p in path if not isinstance(p, int)]
    return ".".join(keys[:6]) + ("..." if len(keys) > 6 else "") if keys else "the top level"


def _check_size(data, where: str) -> None:
    """Depth and width of parsed data within the limits (iterative: any depth is walked without recursion)."""
    stack = [(data, [], 0)]
    while stack:
        value, path, depth = stack.pop()
        if isinstance(value, dict):
            items = list(value.items())
        elif isinstance(value, list):
            items = list(enumerate(value))
        else:
            continue
        if depth >= MAX_DEPTH:
            raise UserError(f"{where}: {_name(path)} is nested deeper than {MAX_DEPTH} levels")
        if len(items) > MAX_ITEMS:
            kind = "keys" if isinstance(value, dict) else "items"
            raise UserError(f"{where}: {_name(path)} holds {len(items)} {kind}; at most {MAX_ITEMS} are allowed")
        stack.extend((v, path + [k], depth + 1) for k, v in items)


def _deep_key(text: str, kind: str) -> str:
    """The key under which ``text`` nests too deep (for the message; the parser gave up on it)."""
    depth, key, table, i, n = 0, None, "", 0, len(text)
    line_start = 0
    while i < n:
        c = text[i]
        if c == "\n":
            line_start = i + 1
        elif kind == "toml" and c == "#":
            j = text.find("\n", i)
            i = n if j < 0 else j
            continue
        elif c == '"' or (kind == "toml" and c == "'"):
            quote = text[i: i + 3] if text[i: i + 3] in ('"""', "'''") else c
            j = i + len(quote)
            while j < n and not text.startswith(quote, j):
                j += 2 if (text[j] == "\\" and quote[0] == '"') else 1
            if kind == "json" and depth == 1 and text[j + 1: j + 40].lstrip().startswith(":"):
                key = text[i + 1: j]
            i = j + len(quote)
            continue
        elif kind == "toml" and depth == 0 and c == "[" and not text[line_start:i].strip():
            j = text.find("\n", i)
            table = text[i: n if j < 0 else j].strip("[] \t\r")
            i = n if j < 0 else j
            continue
        elif kind == "toml" and depth == 0 and c == "=":
            key = text[line_start:i].strip().strip("\"'")
        elif c in "[{":
            depth += 1
            if depth > MAX_DEPTH:
                parts = [p for p in (table, key) if p]
                return _name([".".join(parts)]) if parts else "the top level"
        elif c in "]}":
            depth -= 1
        i += 1
    return "a value"


def load_table(path, what: str = "file", *, suffixes=(".toml", ".json")) -> dict:
    """A ``.toml`` or ``.json`` file as a mapping (a JSON file must hold an object).

    Raises
    ------
    UserError
        Unknown suffix, a file that is not a readable regular text file, a
        syntax error (with its line), a JSON key given twice, nesting or
        arrays beyond the limits (naming the key), or a JSON value that is
        not an object.
    """
    p = Path(path)
    if p.suffix not in suffixes:
        raise UserError(f"{what} {p} must end in {' or '.join(suffixes)}")
    text = read_text(p, what)
    if p.suffix == ".toml":
        return loads(text, "toml", f"{what} {p}")
    if not text.strip():
        raise UserError(f"{what} {p} is empty")
    data = loads(text, "json", f"{what} {p}")
    if not isinstance(data, dict):
        raise UserError(f"{what} {p} must hold a JSON object of keys and values, not a {type(data).__name__}")
    return data


# ----------------------------------------------------------------------------- schema
@dataclass(frozen=True)
class Spec:
    """An expected value: a description for messages and a check returning the (normalized) value or None if bad."""

    expected: str
    accept: Callable[[Any], Any]

    def check(self, value: Any, name: str) -> Any:
        """The accepted value, or UserError ``{name} = {value!r} must be {expected}``."""
        try:
            out = self.accept(value)
        except (TypeError, ValueError, OverflowError):
            out = _BAD
        if out is _BAD:
            raise UserError(f"{name} = {_show(value)} must be {self.expected}")
        return out


_BAD = object()


def _show(value: Any) -> str:
    text = json.dumps(value, default=str) if not isinstance(value, float) else repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _is_int(v) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def int_in(lo: int | None = None, hi: int | None = None) -> Spec:
    """An integer in ``[lo, hi]`` (either end open when None)."""
    rng = _range_text(lo, hi)
    return Spec(f"an integer{rng}", lambda v: v if _is_int(v) and (lo is None or v >= lo) and (hi is None or v <= hi)
                else _BAD)


def number_in(lo: float | None = None, hi: float | None = None, *, lo_open: bool = False) -> Spec:
    """A finite number (int or float) in ``[lo, hi]`` (``(lo, hi]`` with ``lo_open``), as a float."""
    rng = _range_text(lo, hi, lo_open)

    def accept(v):
        if not _is_number(v):
            return _BAD
        if lo is not None and (v <= lo if lo_open else v < lo):
            return _BAD
        if hi is not None and v > hi:
            return _BAD
        return float(v)

    return Spec(f"a number{rng}", accept)


def _range_text(lo, hi, lo_open: bool = False) -> str:
    if lo is not None and hi is not None:
        return f" from {lo} to {hi}" if not lo_open else f" > {lo} and <= {hi}"
    if lo is not None:
        return f" {'>' if lo_open else '>='} {lo}"
    if hi is not None:
        return f" <= {hi}"
    return ""


INT = int_in()
NUMBER = number_in()
STRING = Spec("a string", lambda v: v if isinstance(v, str) else _BAD)
BOOL = Spec("true or false", lambda v: v if isinstance(v, bool) else _BAD)


def predicate(expected: str, test: Callable[[Any], bool]) -> Spec:
    """Any value for which ``test(value)`` is true (``expected`` describes it for messages)."""
    return Spec(expected, lambda v: v if test(v) else _BAD)


def one_of(*choices: str) -> Spec:
    """One of the given strings."""
    return Spec(f"one of {', '.join(map(repr, choices))}", lambda v: v if isinstance(v, str) and v in choices else _BAD)


def list_of(item: Spec, *, min_len: int = 0) -> Spec:
    """A list (TOML array) whose items all pass ``item``; returned as a tuple."""

    def accept(v):
        if not isinstance(v, (list, tuple)) or len(v) < min_len:
            return _BAD
        out = []
        for x in v:
            try:
                y = item.accept(x)
            except (TypeError, ValueError, OverflowError):
                return _BAD
            if y is _BAD:
                return _BAD
            out.append(y)
        return tuple(out)

    kind = "a non-empty list" if min_len == 1 else f"a list of at least {min_len}" if min_len else "a list"
    return Spec(f"{kind} whose items are each {item.expected}", accept)


def pair_of(item: Spec) -> Spec:
    """Two values (low, high) that pass ``item``, with low <= high; returned as a tuple."""
    inner = list_of(item)

    def accept(v):
        out = inner.accept(v)
        if out is _BAD or len(out) != 2 or out[0] > out[1]:
            return _BAD
        return out

    return Spec(f"[low, high] with low <= high, each {item.expected}", accept)


def table_of() -> Spec:
    """A table (mapping); its keys are checked by the caller."""
    return Spec("a table", lambda v: v if isinstance(v, dict) else _BAD)


def check_value(value: Any, spec: Spec, name: str) -> Any:
    """``spec.check(value, name)``."""
    return spec.check(value, name)


def check_types(table: Mapping, schema: Mapping[str, Spec], where: str = "") -> dict:
    """Check the types of the keys of ``table`` that ``schema`` knows (others pass: another check names them).

    Returns ``table`` with the known keys' accepted values (lists as tuples).
    """
    head = f"{where}: " if where else ""
    if not isinstance(table, Mapping):
        raise UserError(f"{head}must be a table of keys and values, not {_show(table)}")
    return {k: (schema[k].check(v, f"{head}{k}") if k in schema else v) for k, v in table.items()}


def check_table(table: Mapping, schema: Mapping[str, Spec], where: str = "", *, what: str = "key(s)",
                required: tuple[str, ...] = ()) -> dict:
    """Check the keys and value types of ``table``; return the accepted values.

    Parameters
    ----------
    table : mapping
        E.g. one TOML table.
    schema : mapping of str to Spec
        The allowed keys and what each must hold.
    where : str
        Prefix of messages, e.g. ``"d.toml: [search]"``.
    what : str
        What the keys are, for the unknown-key message.
    required : tuple of str
        Keys that must be present.

    Raises
    ------
    UserError
        An unknown key, a missing required key, or a value of the wrong type
        or range: ``{where} {key} = {value} must be {expected}``.
    """
    head = f"{where}: " if where else ""
    if not isinstance(table, Mapping):
        raise UserError(f"{head}must be a table of keys and values, not {_show(table)}")
    check_keys(table, tuple(schema), what, prefix=head)
    missing = [k for k in required if k not in table]
    if missing:
        raise UserError(f"{head}missing {', '.join(missing)}")
    return {k: schema[k].check(v, f"{head}{k}") for k, v in table.items()}
