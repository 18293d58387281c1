"""Built-in capture plans (generators of :mod:`~nlosplan.hardware.commands`) and plan wrappers.

- :func:`raster_plan`: DENALI's 10 x 10 snake raster, repeats and settle time.
- :func:`positions_plan`: a list of (x, y) mm positions, e.g. from a file
  (:func:`read_positions`).
- :func:`ask_tell_plan`: positions suggested by a planner in batches, results
  told back (the capture planner plugs in here).
- :func:`finalize_wrapper`: run a cleanup plan after a plan, also when it fails.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Callable, Iterable, Sequence

from nlosplan.errors import UserError
from nlosplan.schema import loads, parse_number, read_text, shown
from nlosplan.hardware.commands import Capture, CaptureResult, Checkpoint, Move, Plan, SetLights
from nlosplan.denali.geometry import GRID_N, grid_index, grid_mm

__all__ = ["ask_tell_plan", "finalize_wrapper", "positions_plan", "raster_plan", "read_positions"]


def _check_repeats(repeats: int) -> int:
    if not isinstance(repeats, int) or isinstance(repeats, bool) or repeats < 1:
        raise UserError(f"repeats={repeats!r} must be an integer >= 1")
    return repeats


def _capture_at(x_mm: float, y_mm: float, repeats: int, settle_s: float, meta: dict | None = None) -> Plan:
    """Move, ``repeats`` captures, checkpoint; returns the list of CaptureResults."""
    yield Move(x_mm, y_mm, settle_s)
    results = []
    position = grid_index(x_mm, y_mm)
    for r in range(repeats):
        results.append((yield Capture(repeat=r, labels={"position": position}, meta=meta or {})))
    yield Checkpoint()
    return results


def raster_plan(*, repeats: int = 3, settle_s: float = 0.5, positions: Iterable[int] | None = None,
                lights: bool | None = None) -> Plan:
    """DENALI's snake raster: every grid position in order, ``repeats`` captures each.

    Parameters
    ----------
    repeats : int
        Captures per position (DENALI: 3).
    settle_s : float
        Seconds after each move before capturing (DENALI: 0.5).
    positions : iterable of int, optional
        Grid indices (0-99, snake order) to visit, in this order; default all 100.
    lights : bool, optional
        Emit ``SetLights(lights)`` first.

    Yields
    ------
    Move, Capture, Checkpoint (and SetLights)
    """
    _check_repeats(repeats)
    order = list(range(GRID_N * GRID_N)) if positions is None else [int(p) for p in positions]
    points = [grid_mm(p) for p in order]   # validates every index before anything is yielded
    if lights is not None:
        yield SetLights(bool(lights))
    for x, y in points:
        yield from _capture_at(x, y, repeats, settle_s)


def positions_plan(points: Sequence[tuple[float, float]], *, repeats: int = 3, settle_s: float = 0.5,
                   lights: bool | None = None) -> Plan:
    """Capture at each (x, y) mm of ``points`` in order, ``repeats`` times each."""
    _check_repeats(repeats)
    pts = [(float(x), float(y)) for x, y in points]
    if not pts:
        raise UserError("the position list is empty")
    if lights is not None:
        yield SetLights(bool(lights))
    for x, y in pts:
        yield from _capture_at(x, y, repeats, settle_s)


def read_positions(path) -> list[tuple[float, float]]:
    """Read gantry positions (mm) from a file.

    Formats: CSV or whitespace text with two numbers per line (``x_mm,y_mm``;
    a header line and ``#`` comments are skipped), or JSON (a list of
    ``[x, y]`` pairs or of ``{"x_mm": .., "y_mm": ..}`` objects).

    Raises
    ------
    UserError
        Missing file, or a line/entry that is not two finite numbers (named with its line).
    """
    p = Path(path)
    text = read_text(p, "positions file")   # a FIFO, a device, a folder, binary: one line
    out: list[tuple[float, float]] = []
    if p.suffix.lower() == ".json":
        data = loads(text, "json", f"positions file {p}")   # depth, length and duplicate keys capped
        if not isinstance(data, list):
            raise UserError(f"positions file {p}: expected a JSON list of [x_mm, y_mm] pairs")
        for i, item in enumerate(data):
            pair = (item.get("x_mm"), item.get("y_mm")) if isinstance(item, dict) else item
            out.append(_pair(pair, f"{p} entry {i}"))
    else:
        rows = csv.reader(line.replace("\t", ",").replace(" ", ",") for line in text.splitlines())
        for n, row in enumerate(rows, 1):
            cells = [c for c in row if c.strip()]
            if not cells or cells[0].lstrip().startswith("#"):
                continue
            if n == 1 and not _is_number(cells[0]):
                continue  # header
            out.append(_pair(cells, f"{p} line {n}"))
    if not out:
        raise UserError(f"positions file {p} holds no positions")
    return out


def _is_number(text: str) -> bool:
    try:
        parse_number(text)
        return True
    except ValueError:
        return False


def _number(v) -> float:
    """A number of a positions file: a JSON number, or text in ASCII digits (``1_0`` is refused)."""
    if isinstance(v, bool):
        raise TypeError(v)
    return float(v) if isinstance(v, (int, float)) else parse_number(v)


def _pair(item, where: str) -> tuple[float, float]:
    try:
        if len(item) != 2:
            raise ValueError
        x, y = (_number(v) for v in item)
    except (TypeError, ValueError):
        raise UserError(f"{where}: expected two numbers x_mm, y_mm, got {shown(item)}") from None
    if not (math.isfinite(x) and math.isfinite(y)):
        raise UserError(f"{where}: position ({x}, {y}) is not finite")
    return x, y


def ask_tell_plan(suggest: Callable[[int], Sequence[tuple[float, float]]],
                  ingest: Callable[[list[tuple[tuple[float, float], list[CaptureResult]]]], None], *,
                  batch: int = 1, repeats: int = 1, settle_s: float = 0.5, max_positions: int | None = None) -> Plan:
    """Positions from a planner, in batches, with the results ingested back after each batch.

    The executor side of the planners' ask/tell protocol (``suggest(n)`` /
    ``ingest(results)``, :mod:`nlosplan.planner.protocol`), taken as two
    callables so that this room needs no planner type.

    Parameters
    ----------
    suggest : callable
        ``suggest(n)`` returns up to ``n`` (x_mm, y_mm) positions; an empty
        list ends the plan.
    ingest : callable
        Called with ``[((x_mm, y_mm), [CaptureResult, ...]), ...]`` for the batch.
        On resume the results come from the store (``resumed=True``), so a
        deterministic planner makes the same suggestions again and the run
        continues where it stopped.
    batch, repeats, settle_s
    max_positions : int, optional
        Stop after this many positions.
    """
    _check_repeats(repeats)
    done = 0
    while max_positions is None or done < max_positions:
        n = batch if max_positions is None else min(batch, max_positions - done)
        points = [(float(x), float(y)) for x, y in suggest(n)]
        if not points:
            return
        told = []
        for x, y in points:
            results = yield from _capture_at(x, y, repeats, settle_s)
            told.append(((x, y), results))
            done += 1
        ingest(told)


def finalize_wrapper(plan: Plan, final: Callable[[], Plan]) -> Plan:
    """Run ``plan``, then the plan ``final()`` whatever happened (bluesky's finalize_wrapper).

    When the executor throws an error into the plan (a driver fault,
    Ctrl-C), ``final()``'s commands still run before the error goes on.
    """
    try:
        return (yield from plan)
    finally:
        yield from final()
