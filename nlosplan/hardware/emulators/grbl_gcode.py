"""The g-code, motion and homing half of the emulated GRBL 1.1h (:class:`~.grbl.EmulatedGrbl` mixes it in).

Targets are work coordinates: machine = work + WCO (the selected G54..G59
offset plus the G92 offset), or machine coordinates with G53. The planner's
limits are per axis as in GRBL: a move's speed and acceleration are the
largest that keep every axis within its ``$110..$112`` rate and
``$120..$122`` acceleration. Positions end on the step grid (``$100..$102``).
"""

from __future__ import annotations

import math
import time

from nlosplan.hardware.emulators.motion import Segment
from nlosplan.hardware.grbl_protocol import machine_space

__all__ = ["GcodeMixin"]

_AXES = "XYZ"
_MODAL = {0: "motion", 1: "motion", 90: "distance", 91: "distance", 20: "units", 21: "units", 17: "plane",
          18: "plane", 19: "plane", 93: "feed", 94: "feed", 54: "coord", 55: "coord", 56: "coord", 57: "coord",
          58: "coord", 59: "coord"}
_NON_MODAL = {4, 10, 53, 92, 92.1}


class _Fail(Exception):
    def __init__(self, code: int) -> None:
        self.code = code


def _words(line: str) -> list[tuple[str, float]]:
    out, i = [], 0
    while i < len(line):
        letter = line[i]
        if not letter.isalpha():
            raise _Fail(1)
        j = i + 1
        while j < len(line) and (line[j].isdigit() or line[j] in ".-+"):
            j += 1
        try:
            out.append((letter, float(line[i + 1:j])))
        except ValueError:
            raise _Fail(2) from None
        i = j
    return out


class GcodeMixin:
    """G-code execution, the motion queue, feed hold and homing of the emulated GRBL."""

    # ------------------------------------------------------------------ parser state
    def _init_gcode(self) -> None:
        self.coord_select = 1
        self.g92 = [0.0, 0.0, 0.0]
        self.absolute, self.inches, self.rapid = True, False, True
        self._feed = 0.0

    def _parser_state(self) -> str:
        return (f"[GC:G{0 if self.rapid else 1} G{53 + self.coord_select} G17 G{20 if self.inches else 21} "
                f"G{90 if self.absolute else 91} G94 M5 M9 T0 F{self._feed:g} S0]")

    # ------------------------------------------------------------------ g-code
    def _gcode(self, line: str) -> None:
        try:
            self._gcode_block(line)
        except _Fail as exc:
            return self._error(exc.code)
        if not self._halted:
            self._ok()

    def _gcode_block(self, line: str) -> None:
        words = _words(line)
        groups: dict[str, float] = {}
        nonmodal = None
        values: dict[str, float] = {}
        for letter, v in words:
            if letter == "G":
                g = round(v, 1) if round(v, 1) == 92.1 else v
                if g in _MODAL:
                    if _MODAL[g] in groups:
                        raise _Fail(21)
                    groups[_MODAL[g]] = g
                elif g in _NON_MODAL:
                    if nonmodal is not None:
                        raise _Fail(21)
                    nonmodal = g
                else:
                    raise _Fail(20)
            elif letter == "M":
                if v not in (0, 1, 2, 3, 4, 5, 7, 8, 9, 30):
                    raise _Fail(20)
            elif letter in "XYZFPLSTN":
                if letter in values:
                    raise _Fail(25)
                values[letter] = v
            else:
                raise _Fail(20)
        if values.get("F", 0) < 0:
            raise _Fail(4)
        scale = 25.4 if (groups.get("units", 20 if self.inches else 21) == 20) else 1.0
        if "units" in groups:
            self.inches = groups["units"] == 20
        if "distance" in groups:
            self.absolute = groups["distance"] == 90
        if "coord" in groups:
            self.coord_select = int(groups["coord"]) - 53
            self._wco_counter = 0
        if "motion" in groups:
            self.rapid = groups["motion"] == 0
        if "F" in values:
            self._feed = values["F"] * scale
        axes = {a: values[a] * scale for a in _AXES if a in values}
        if nonmodal == 10:
            return self._g10(values, axes)
        if nonmodal == 92:
            if not axes:
                raise _Fail(26)
            wcs = self.coords[self.coord_select]
            for i, a in enumerate(_AXES):
                if a in axes:
                    self.g92[i] = self._planned()[i] - wcs[i] - axes[a]
            self._wco_counter = 0
            return None
        if nonmodal == 92.1:
            self.g92 = [0.0, 0.0, 0.0]
            self._wco_counter = 0
            return None
        if nonmodal == 4:
            if "P" not in values:
                raise _Fail(28)
            return None
        if not axes:
            return None
        if not self.rapid and self._feed <= 0:
            raise _Fail(22)
        here = self._planned()
        wco = (0.0, 0.0, 0.0) if nonmodal == 53 else self._wco()
        target = []
        for i, a in enumerate(_AXES):
            if a not in axes:
                target.append(here[i])
            elif self.absolute or nonmodal == 53:
                target.append(axes[a] + wco[i])
            else:
                target.append(here[i] + axes[a])
        if int(self.settings[20]) and not self._inside(target):
            return self._soft_limit()
        self._queue.append((tuple(target), None if self.rapid else self._feed))
        if self.state == "Idle":
            self._start_next(self._now())
        return None

    def _g10(self, values: dict, axes: dict) -> None:
        if not axes:
            raise _Fail(26)
        if "L" not in values or "P" not in values:
            raise _Fail(28)
        p, lnum = int(values["P"]), int(values["L"])
        if lnum not in (2, 20) or not 0 <= p <= 6:
            raise _Fail(20)
        n = p or self.coord_select
        here = self._planned()
        for i, a in enumerate(_AXES):
            if a in axes:
                self.coords[n][i] = axes[a] if lnum == 2 else here[i] - self.g92[i] - axes[a]
        self._wco_counter = 0

    def _planned(self) -> tuple:
        """The machine position at the end of what is queued (GRBL's parser position)."""
        if self._queue:
            return self._queue[-1][0]
        if self._seg is not None:
            return self._resume[0] if self._resume else self._seg.target
        return tuple(self.pos)

    def _inside(self, target) -> bool:
        space = machine_space(self.settings, "Z" in self.options)
        return all(lo - 1e-9 <= v <= hi + 1e-9 for v, (lo, hi) in zip(target, space))

    def _soft_limit(self) -> None:
        if self._seg is not None:
            self.pos = list(self._seg.position(self._now()))
        self._seg, self._queue, self._resume = None, [], None
        self.state = "Alarm"
        self._halted = self._halted_ok = True
        self._say("ALARM:2")
        self._say("[MSG:Reset to continue]")

    # ------------------------------------------------------------------ motion
    def _limits_along(self, start, target, feed):
        d = [q - p for p, q in zip(start, target)]
        dist = math.sqrt(sum(v * v for v in d))
        if dist == 0:
            return 0.0, 0.0
        rate, acc = math.inf, math.inf
        for i, di in enumerate(d):
            if di:
                u = abs(di) / dist
                rate = min(rate, self.settings[110 + i] / u)
                acc = min(acc, self.settings[120 + i] / u)
        v = rate if feed is None else min(feed, rate)
        return v / 60.0, acc

    def _start_next(self, now: float) -> None:
        self._resume = None
        if not self._queue:
            self._seg = None
            if self.state in ("Run", "Idle"):
                self.state = "Idle"
            return
        target, feed = self._queue.pop(0)
        v, a = self._limits_along(self.pos, target, feed)
        self._seg = Segment(tuple(self.pos), target, now, v, a)
        self._seg_feed = feed
        self.moves += 1
        self.state = "Run"

    def _quantized(self, xyz) -> list:
        return [round(v * self.settings[100 + i]) / self.settings[100 + i] for i, v in enumerate(xyz)]

    def _advance(self, now: float) -> None:
        if self._homing is not None:
            if now >= self._homing[0]:
                self._finish_homing()
            return
        seg = self._seg
        if seg is None or self.state not in ("Run", "Hold"):
            return
        self.pos = list(seg.position(now))
        f = self.faults
        if (self.state == "Run" and f.alarm_on_move and self.moves == f.alarm_on_move and not self._alarm_done
                and seg.distance and math.dist(seg.start, self.pos) >= 0.5 * seg.distance):
            self._alarm_done = True   # a hard limit switch hit halfway
            self._seg, self._queue, self._resume = None, [], None
            self.state = "Alarm"
            self._halted, self._halted_ok = True, False
            self._say("ALARM:1")
            self._say("[MSG:Reset to continue]")
            return
        if seg.done(now):
            self.pos = self._quantized(seg.target) if self.state == "Run" else list(seg.target)
            if self.state == "Hold":
                self._seg, self._held = None, True
            else:
                self._start_next(now)

    def _feed_hold(self) -> None:
        now = self._now()
        if self.state == "Run" and self._seg is not None:
            self._resume = (self._seg.target, self._seg_feed)
            self._seg = self._seg.stop(now)
            self.pos = list(self._seg.start)
            self.state, self._held = "Hold", False
        elif self.state == "Idle":
            self.state, self._held, self._resume = "Hold", True, None

    def _cycle_start(self) -> None:
        if self.state != "Hold" or not self._held:
            return   # GRBL resumes only once the hold is complete (Hold:0)
        self._held = False
        if self._resume is not None:
            self._queue.insert(0, self._resume)
            self.moves -= 1
        self.state = "Idle"
        self._start_next(self._now())

    # ------------------------------------------------------------------ homing
    def _start_homing(self) -> None:
        """Stock cycles: Z, then X and Y together. Outcome and duration are decided now, applied at the end."""
        stuck = {a for a in self.pins if a in _AXES}
        pulloff = float(self.settings[27])
        seek = max(float(self.settings[25]), 1e-6) / 60.0
        force = "Z" in self.options
        pos, t, outcome = list(self.pos), 0.0, None
        for cycle in ("Z", "XY"):
            axes = [_AXES.index(a) for a in cycle]
            if any(_AXES[i] in stuck for i in axes):   # pulled off, still triggered
                for i in axes:
                    pos[i] -= -pulloff if int(self.settings[23]) & (1 << i) else pulloff
                t += pulloff / seek
                outcome = 8
                break
            missing = [i for i in axes if _AXES[i] not in self.switches]
            if missing:
                travel = 1.5 * max(float(self.settings[130 + i]) for i in axes)
                for i in axes:
                    pos[i] += -travel if int(self.settings[23]) & (1 << i) else travel
                t += travel / seek
                outcome = 9
                break
            for i in axes:
                travel = float(self.settings[130 + i])
                if force:
                    pos[i] = 0.0
                elif int(self.settings[23]) & (1 << i):
                    pos[i] = -travel + pulloff
                else:
                    pos[i] = -pulloff
            t += 0.5 + 2 * pulloff / seek
        self.state = "Home"
        self._homing = (self._now() + t, pos, outcome)

    def _finish_homing(self) -> None:
        _, pos, outcome = self._homing
        self._homing = None
        self.pos = self._quantized(pos)
        deferred, self._deferred = self._deferred, []
        if outcome is None:
            self.state = "Idle"
            self._wco_counter = 0
            self._ok()
        else:   # the firmware resets itself after a failed cycle (after the switch debounce, $26 ms):
            self.state = "Alarm"   # the $H line's ok, then a banner; what arrives meanwhile is lost
            self._say(f"ALARM:{outcome}")
            due = time.monotonic() + float(self.settings[26]) / 1000.0 / self.time_scale
            self._pending.append((due, "ok"))
            self._soft_state()
            self._boot_due = due
            return
        for line in deferred:
            if line is None:
                self._error(11)
            else:
                self._execute(line)
