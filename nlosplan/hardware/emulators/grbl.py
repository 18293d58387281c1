"""An emulated GRBL 1.1 gantry on a pty: line protocol, real-time bytes, motion with feed and acceleration.

Machine frame: positive space, (0, 0) after reset or homing, travel ``$130``
x ``$131`` mm. Moves follow a trapezoidal speed profile (feed capped by
``$110``/``$111`` mm/min, acceleration ``$120``/``$121`` mm/s²) on a clock
that runs ``time_scale`` times faster than real time, so tests stay short.
Soft limits (``$20=1``) raise ``ALARM:2`` as GRBL does; ``$X`` unlocks any
alarm here (a real GRBL wants a reset first after a hard-limit alarm).
Feed hold stops at once (no deceleration ramp) and ``~`` resumes the rest.
"""

from __future__ import annotations

import math
import threading
import time

from nlosplan.hardware.emulators.faults import GantryFaults, garble
from nlosplan.hardware.emulators.pty import PtyDevice

__all__ = ["EmulatedGrbl"]

BANNER = "Grbl 1.1h ['$' for help]"
DEFAULT_SETTINGS = {0: 10, 1: 25, 2: 0, 3: 0, 4: 0, 5: 0, 6: 0, 10: 1, 11: 0.010, 12: 0.002, 13: 0, 20: 1, 21: 0,
                    22: 0, 23: 0, 24: 25, 25: 500, 26: 250, 27: 1, 30: 1000, 31: 0, 32: 0, 100: 80, 101: 80,
                    102: 250, 110: 6000, 111: 6000, 112: 500, 120: 500, 121: 500, 122: 10, 130: 320, 131: 320,
                    132: 200}


def _profile(distance: float, v: float, a: float) -> tuple[float, float, float]:
    """(total time, acceleration time, peak speed) of a trapezoid over ``distance`` mm."""
    if distance <= 0:
        return 0.0, 0.0, 0.0
    if distance <= v * v / a:   # triangle: never reaches v
        t_acc = math.sqrt(distance / a)
        return 2 * t_acc, t_acc, a * t_acc
    t_acc = v / a
    return 2 * t_acc + (distance - v * v / a) / v, t_acc, v


def _travelled(t: float, total: float, t_acc: float, vpk: float, a: float, distance: float) -> float:
    if t <= 0:
        return 0.0
    if t >= total:
        return distance
    if t < t_acc:
        return 0.5 * a * t * t
    if t <= total - t_acc:
        return 0.5 * a * t_acc * t_acc + vpk * (t - t_acc)
    left = total - t
    return distance - 0.5 * a * left * left


class EmulatedGrbl(PtyDevice):
    """GRBL 1.1 on a pty (use :attr:`port` as the gantry port).

    Parameters
    ----------
    time_scale : float
        Motion and homing run this many times faster than real time.
    settings : dict, optional
        ``$N`` values overriding :data:`DEFAULT_SETTINGS`.
    faults : GantryFaults, optional
    boot_s : float
        Delay between the port being opened and the banner (an Arduino's reset).
    """

    def __init__(self, *, time_scale: float = 1.0, settings: dict | None = None, faults: GantryFaults | None = None,
                 boot_s: float = 0.05) -> None:
        super().__init__("gantry")
        self.time_scale = float(time_scale)
        self.settings = {**DEFAULT_SETTINGS, **(settings or {})}
        self.faults = faults or GantryFaults()
        self.boot_s = boot_s
        self._mlock = threading.Lock()
        self.state = "Alarm" if self.settings[22] else "Idle"
        self._pos = [0.0, 0.0, 0.0]
        self._queue: list[tuple[float, float, float]] = []  # (x, y, feed mm/min)
        self._motion = None       # (start xyz, target xyz, t0, total, t_acc, vpk, a, distance)
        self._held_at = None
        self._line = bytearray()
        self._feed = 0.0
        self._absolute = True
        self._pending: list[tuple[float, str]] = []  # (due time, text) delayed output
        self._boot_due: float | None = None
        self.moves = 0
        self.lines: list[str] = []
        self._status_n = 0
        self._alarm_done = False

    # ------------------------------------------------------------------ clock
    def _now(self) -> float:
        return time.monotonic() * self.time_scale

    def position(self) -> tuple[float, float]:
        """Current (x, y) machine position, mm (thread-safe; the emulated sensor reads it)."""
        with self._mlock:
            self._advance(self._now())
            return self._pos[0], self._pos[1]

    def _advance(self, now: float) -> None:
        m = self._motion
        if m is None or self.state != "Run":
            return
        start, target, t0, total, t_acc, vpk, a, dist = m
        s = _travelled(now - t0, total, t_acc, vpk, a, dist)
        f = 1.0 if dist == 0 else s / dist
        self._pos = [p + (q - p) * f for p, q in zip(start, target)]
        if (self.faults.alarm_on_move and self.moves == self.faults.alarm_on_move and not self._alarm_done
                and f >= 0.5):
            self._alarm_done = True
            self._motion, self._queue = None, []
            self.state = "Alarm"
            self._say("ALARM:1")
            self._say("[MSG:Reset to continue]")
            return
        if now - t0 >= total:
            self._motion = None
            self._start_next(now)

    def _start_next(self, now: float) -> None:
        if not self._queue:
            self.state = "Idle"
            return
        x, y, feed = self._queue.pop(0)
        start, target = list(self._pos), [x, y, self._pos[2]]
        dist = math.dist(start, target)
        v = min(feed, self.settings[110], self.settings[111]) / 60.0
        a = min(self.settings[120], self.settings[121])
        total, t_acc, vpk = _profile(dist, v, a)
        self._motion = (start, target, now, total, t_acc, vpk, a, dist)
        self.moves += 1
        self.state = "Run"

    # ------------------------------------------------------------------ output
    def _say(self, text: str, delay: float = 0.0) -> None:
        if delay > 0:
            self._pending.append((time.monotonic() + delay, text))
        else:
            self.send(text + "\r\n")

    def _ok(self) -> None:
        self._say("ok", self.faults.slow_ok_s)

    def _error(self, code: int) -> None:
        self._say(f"error:{code}", self.faults.slow_ok_s)

    def _status(self) -> str:
        self._status_n += 1
        x, y, z = self._pos
        feed = 0 if self.state != "Run" else self._feed
        text = f"<{self.state}|MPos:{x:.3f},{y:.3f},{z:.3f}|FS:{feed:.0f},0>"
        n = self.faults.garble_status_every
        if n and self._status_n % n == 0:
            import numpy as np

            text = garble(text, np.random.default_rng(self._status_n))
        return text

    # ------------------------------------------------------------------ hooks
    def on_open(self) -> None:
        with self._mlock:
            self._reset(during_motion=False)
        self._boot_due = time.monotonic() + self.boot_s

    def _reset(self, during_motion: bool) -> None:
        self._queue, self._motion, self._line = [], None, bytearray()
        self.drop_output()
        self._pending.clear()
        if during_motion:
            self.state = "Alarm"
        elif self.state != "Alarm":
            self.state = "Alarm" if self.settings[22] else "Idle"

    def _greet(self) -> None:
        self._say("")
        self._say(BANNER)
        if self.state == "Alarm":
            self._say("[MSG:'$H'|'$X' to unlock]")

    def tick(self, now: float) -> None:
        with self._mlock:
            self._advance(self._now())
            if self._boot_due is not None and now >= self._boot_due:
                self._boot_due = None
                self._greet()
            due = [t for t in self._pending if t[0] <= now]
            if due:
                self._pending = [t for t in self._pending if t[0] > now]
                for _, text in due:
                    self._say(text)

    def on_bytes(self, data: bytes) -> None:
        with self._mlock:
            self._advance(self._now())
            for b in data:
                ch = bytes([b])
                if ch == b"?":
                    self._say(self._status())
                elif ch == b"!":
                    if self.state == "Run":
                        self.state, self._held_at = "Hold", self._now()
                elif ch == b"~":
                    if self.state == "Hold":
                        m = self._motion
                        if m is not None:   # restart the rest of the move from where it stopped
                            self._queue.insert(0, (m[1][0], m[1][1], self._feed))
                            self._motion = None
                            self.moves -= 1
                        self.state = "Idle"
                        self._start_next(self._now())
                elif b == 0x18:
                    was_moving = self.state in ("Run", "Hold")
                    self._reset(during_motion=was_moving)
                    if was_moving:
                        self._say("ALARM:3")
                    self._greet()
                elif b == 0x85:  # jog cancel: the emulator runs no $J jogs, so there is nothing to cancel
                    continue
                elif ch in (b"\n", b"\r"):
                    if self._line:
                        line = self._line.decode("ascii", errors="replace").strip()
                        self._line = bytearray()
                        self._execute(line)
                    elif ch == b"\n":
                        self._ok()   # GRBL acknowledges empty lines
                else:
                    self._line += ch

    # ------------------------------------------------------------------ lines
    def _execute(self, line: str) -> None:
        self.lines.append(line)
        up = line.upper().replace(" ", "")
        if up == "$$":
            for k in sorted(self.settings):
                self._say(f"${k}={self.settings[k]:g}")
            return self._ok()
        if up == "$X":
            if self.state == "Alarm":
                self.state = "Idle"
                self._say("[MSG:Caution: Unlocked]")
            return self._ok()
        if up == "$H":
            if not self.settings[22]:
                return self._error(5)
            self._pos = [0.0, 0.0, 0.0]
            self.state = "Idle"
            return self._ok()
        if up.startswith("$") and "=" in up:
            try:
                k, v = up[1:].split("=")
                if int(k) not in self.settings:
                    return self._error(3)
                self.settings[int(k)] = float(v)
            except ValueError:
                return self._error(2)
            return self._ok()
        if up.startswith("$"):
            return self._error(3)
        if self.state == "Alarm":
            return self._error(9)
        return self._gcode(up)

    def _gcode(self, up: str) -> None:
        words, i = {}, 0
        gs = []
        while i < len(up):
            letter = up[i]
            j = i + 1
            while j < len(up) and (up[j].isdigit() or up[j] in ".-"):
                j += 1
            if not letter.isalpha() or j == i + 1:
                return self._error(1 if not letter.isalpha() else 2)
            try:
                value = float(up[i + 1:j])
            except ValueError:
                return self._error(2)
            if letter == "G":
                gs.append(value)
            else:
                words[letter] = value
            i = j
        for g in gs:
            if g == 90:
                self._absolute = True
            elif g == 91:
                self._absolute = False
            elif g not in (0, 1, 21, 20, 17, 94):
                return self._error(20)
        if "F" in words:
            self._feed = words["F"]
        motion = [g for g in gs if g in (0, 1)]
        if "X" in words or "Y" in words:
            if motion == [1] and self._feed <= 0:
                return self._error(22)
            last = self._queue[-1][:2] if self._queue else (self._motion[1][:2] if self._motion else self._pos[:2])
            x = words.get("X", last[0] if self._absolute else 0.0)
            y = words.get("Y", last[1] if self._absolute else 0.0)
            if not self._absolute:
                x, y = last[0] + x, last[1] + y
            feed = self.settings[110] if motion == [0] else self._feed
            if self.settings[20] and not (0 <= x <= self.settings[130] and 0 <= y <= self.settings[131]):
                self._queue, self._motion = [], None
                self.state = "Alarm"
                self._say("ALARM:2")
                return None
            self._queue.append((x, y, feed))
            if self.state == "Idle":
                self._start_next(self._now())
        return self._ok()
