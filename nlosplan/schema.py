"""Configuration files (TOML, JSON): read as text with one-line errors, type-checked by a small schema.

:func:`read_text` turns every way a file can fail to be text (missing, a
folder, unreadable, binary, not UTF-8) into one line; :func:`load_table`
parses ``.toml`` or ``.json`` into a mapping. :func:`check_table` checks a
mapping against a schema of :class:`Spec` values (:data:`INT`, :func:`int_in`,
:data:`NUMBER`, :func:`number_in`, :data:`STRING`, :func:`one_of`,
:data:`BOOL`, :func:`list_of`) when the file is read, before any work: a
wrong type is one line naming the key (with its table) and the expected type.
"""

from __future__ import annotations

import json
import math
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Mapping

from nlosplan.errors import UserError, check_keys

__all__ = ["Spec", "INT", "NUMBER", "STRING", "BOOL", "int_in", "number_in", "one_of", "predicate", "list_of", "pair_of",
           "table_of", "check_table", "check_types", "check_value", "read_text", "load_table"]


# ----------------------------------------------------------------------------- reading
def read_text(path, what: str = "file") -> str:
    """The UTF-8 text of ``path``; UserError (one line) when it cannot be read as text.

    Parameters
    ----------
    path : str or Path
    what : str
        What the file is, for the message (e.g. ``"sensor file"``).
    """
    p = Path(path)
    try:
        data = p.read_bytes()
    except FileNotFoundError:
        raise UserError(f"{what} {p} does not exist") from None
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


def load_table(path, what: str = "file", *, suffixes=(".toml", ".json")) -> dict:
    """A ``.toml`` or ``.json`` file as a mapping (a JSON file must hold an object).

    Raises
    ------
    UserError
        Unknown suffix, unreadable or non-text file, a syntax error (with its
        line), or a JSON value that is not an object.
    """
    p = Path(path)
    if p.suffix not in suffixes:
        raise UserError(f"{what} {p} must end in {' or '.join(suffixes)}")
    text = read_text(p, what)
    if p.suffix == ".toml":
        try:
            return tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise UserError(f"{what} {p} is not valid TOML: {exc}") from None
    if not text.strip():
        raise UserError(f"{what} {p} is empty")
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise UserError(f"{what} {p} is not valid JSON: {exc.msg} at line {exc.lineno}") from None
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
