"""The one-at-a-time lines of the design search and what the evidence says along them.

A *line* varies one design axis from a base design (the space's reference design, or it at another zone
layout for the trade-off curves), the others kept. :func:`line_points` reads every design of a line that was
evaluated from the :class:`~nlosplan.planner.design.evidence.Evidence`: its bound, its learner's
:class:`~nlosplan.planner.design.verdicts.Estimate`, whether the bound screened it out and whether a costlier
design of the line being *not met* implies it is not met either (on an axis the metric is monotone in). The
search walks the lines (curves, refine), the summary reads them (the least hardware per parameter, the curves).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from nlosplan.planner.design.evaluation import Status
from nlosplan.planner.design.requirements import Requirement
from nlosplan.planner.design.space import Design, DesignSpace
from nlosplan.planner.design.verdicts import MET, NOT_MET, UNDECIDED, Estimate

__all__ = ["CONTINUOUS", "MORE_IS_BETTER", "CURVE_AXES", "MONOTONE", "Line", "LinePoint", "axis_grid", "lines",
           "line_points", "bracket", "undecided_lines"]

CONTINUOUS = ("jitter_fwhm_ps", "pulse_fwhm_ps", "photon_fraction")
#: Axes along which a larger value is more (better, costlier) hardware.
MORE_IS_BETTER = {"zones": True, "bin_factor": False, "n_bins": True, "jitter_fwhm_ps": False,
                  "pulse_fwhm_ps": False, "photon_fraction": True}
#: Axes scanned at every zone layout too (the trade-off curves).
CURVE_AXES = ("jitter_fwhm_ps", "photon_fraction")
#: Axes the learner's metric is taken to be monotone in (bisection; implied verdicts on the curves).
MONOTONE = CONTINUOUS + ("n_bins",)
_FIELDS = ("zones", "bin_factor", "n_bins", "jitter_fwhm_ps", "pulse_fwhm_ps", "photon_fraction")


def axis_grid(space: DesignSpace, axis: str, points: int, base: Design) -> list[Design]:
    """Designs along one axis from ``base`` (others fixed), cheapest to costliest order not implied."""
    if axis == "zones":
        return [base.replace(zones=z) for z in space.zones]
    if axis == "bin_factor":  # same window: bins shrink as they widen
        return [base.replace(bin_factor=f, n_bins=max(1, min(space.max_bins(f), base.n_bins * 1 // f)))
                for f in space.bin_factors]
    if axis == "n_bins":
        lo, hi = space.n_bins[0], space.max_bins(base.bin_factor)
        vals = sorted({int(round(v)) for v in np.linspace(lo, hi, points)})
        return [base.replace(n_bins=v) for v in vals]
    lo, hi = getattr(space, axis)
    if axis == "photon_fraction":
        vals = np.geomspace(lo, hi, points)
    else:
        vals = np.linspace(lo, hi, points)
    return [base.replace(**{axis: float(round(v, 6))}) for v in vals]


@dataclass(frozen=True)
class Line:
    """One line: ``axis`` varied from ``base`` (whose zone layout is ``layout``), through ``designs``."""

    axis: str
    layout: str
    base: Design
    designs: tuple[Design, ...]


def lines(space: DesignSpace, base: Design, points: int) -> list[Line]:
    """The one-at-a-time lines: every axis of the space from ``base``, then :data:`CURVE_AXES` at the other
    zone layouts."""
    out = [Line(axis, base.layout, base, tuple(axis_grid(space, axis, points, base))) for axis in space.axes]
    for z in space.zones:
        if z == base.zones:
            continue
        b = base.replace(zones=z)
        out += [Line(axis, b.layout, b, tuple(axis_grid(space, axis, points, b))) for axis in CURVE_AXES
                if axis in space.axes]
    return out


@dataclass(frozen=True)
class LinePoint:
    """An evaluated design of a line.

    Attributes
    ----------
    x : float
        Its axis value in the axis's unit (:meth:`Design.value`).
    design : Design
    bound : float or None
        Its bound's metric (None: not evaluated, or not ``ok``).
    bound_status : Status or None
    bound_reason : str
    trained : Estimate or None
        Its learner's metric over the seeds run.
    screened : bool
        The bound failed the requirement: never trained.
    implied : bool
        Not trained: a costlier design of the line, on a :data:`MONOTONE` axis, is not met.
    """

    x: float
    design: Design
    bound: float | None
    bound_status: Status | None
    bound_reason: str
    trained: Estimate | None
    screened: bool
    implied: bool = False

    @property
    def judged(self) -> bool:
        """Trained, screened out or implied: a point a verdict along the line can rest on."""
        return self.trained is not None or self.screened or self.implied


def _on_line(space: DesignSpace, d: Design, axis: str, base: Design) -> bool:
    if any(getattr(d, f) != getattr(base, f) for f in _FIELDS if f != axis and not (axis == "bin_factor"
                                                                                    and f == "n_bins")):
        return False
    return axis != "bin_factor" or d.n_bins == max(1, min(space.max_bins(d.bin_factor), base.n_bins // d.bin_factor))


def line_points(evidence, req: Requirement, axis: str, base: Design) -> list[LinePoint]:
    """Every evaluated design on the line through ``base`` along ``axis``, sorted by the axis value.

    Parameters
    ----------
    evidence : Evidence
    req : Requirement
    axis : str
    base : Design
    """
    pts: list[LinePoint] = []
    for d in evidence.designs(req):
        if not _on_line(evidence.space, d, axis, base):
            continue
        b = evidence.bound(req, d)
        pts.append(LinePoint(d.value(axis, evidence.space.sensor), d, None if b is None or not b.ok else b.value,
                             None if b is None else b.status, "" if b is None else b.reason,
                             evidence.trained_value(req, d),
                             b is not None and b.ok and not evidence.bound_meets(req, d)))
    out = sorted(pts, key=lambda p: p.x)
    failed = [p.x for p in out if p.trained is not None and p.trained.verdict == NOT_MET]
    return [replace(p, implied=axis in MONOTONE and p.trained is None and not p.screened and any(
        (x > p.x) == MORE_IS_BETTER[axis] and x != p.x for x in failed)) for p in out]


def _met(req: Requirement, value: float) -> bool:
    return math.isfinite(value) and req.met(value)


def bracket(points: list[LinePoint], req: Requirement, more_is_better: bool) -> tuple[float, float] | None:
    """Adjacent axis values (meets, misses) by the trained metric, or None."""
    seq = [p for p in points if p.judged]
    if not more_is_better:
        seq = seq[::-1]  # walk from the cheapest end (more jitter) to the costliest
    # now: along seq hardware increases; find the first index that meets
    for i in range(1, len(seq)):
        prev_ok = seq[i - 1].trained is not None and _met(req, seq[i - 1].trained.value)
        cur_ok = seq[i].trained is not None and _met(req, seq[i].trained.value)
        if cur_ok and not prev_ok:
            a, b = seq[i].x, seq[i - 1].x
            if abs(a - b) <= 1e-6 * max(abs(a), abs(b), 1.0):
                return None
            return a, b
    return None


def undecided_lines(evidence, req: Requirement) -> list[Design]:
    """Per axis of the space, the design that would decide the requirement's undecided per-parameter row.

    A row (the least hardware along one axis from the reference design) is *met* when some design of its line
    is met, *undecided* when none is but some is undecided. For each undecided row this is its undecided design
    with the best learner's mean (the likeliest to be met), while it has fewer than the run's ``max_seeds``: one
    more seed narrows its interval, so a re-run at another seed reaches the same verdict more often.

    Returns
    -------
    list of Design
        At most one per axis, without repeats, in the space's axis order.
    """
    out: list[Design] = []
    for axis in evidence.space.axes:
        pts = [p for p in line_points(evidence, req, axis, evidence.base) if p.trained is not None]
        if not pts or any(p.trained.verdict == MET for p in pts):
            continue
        open_pts = [p for p in pts if p.trained.verdict == UNDECIDED and p.trained.seeds < evidence.config.max_seeds]
        if not open_pts:
            continue
        best = (min if req.smaller_is_better else max)(open_pts, key=lambda p: p.trained.value)
        if best.design not in out:
            out.append(best.design)
    return out
