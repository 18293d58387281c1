"""The rig file of a Telemetrix gantry (TOML): pins, steps per mm, speed, acceleration, flips, power-up origin.

DENALI's gantry (the DENALI capture code through cc-hardware's
``telemetrix_stepper.py``, SENSOR_FACTS.md) is the default: an Arduino with a
CNC shield on Telemetrix4Arduino, X step/dir pins 2/5, Y 3/6, the shield's
enable pin 8 (active low: enable inverted), 2850 steps per 28 mm (101.79
steps/mm), max speed 32767 steps/s, constant speed (no acceleration ramps:
``run_speed_to_position``), no axis flipped, no limit switches: position 0 is
wherever the carriage was when the board last reset (the port was opened).

The firmware does its arithmetic in 16-bit AVR ``int`` values
(:mod:`~nlosplan.hardware.telemetrix_protocol`): step targets beyond
+-32,767 steps from the origin (321.9 mm at DENALI's 101.79 steps/mm) and
speeds or accelerations above 32,767 arrive as other numbers, so a rig file
that asks for them, and limits that reach beyond them
(:meth:`TelemetrixConfig.check_reach`), are refused before anything moves.

Example (``nlosplan/hardware/rigs/denali-telemetrix.toml``, the defaults)::

    [telemetrix]
    enable_pin = 8
    enable_inverted = true
    max_speed = 32767          # steps/s, at most 32767 (the firmware's 16-bit int); an Uno steps ~4000/s
    acceleration = 0           # steps/s^2; 0: constant speed (DENALI)
    origin_mm = [0.0, 0.0]     # user-frame position of the carriage when the board resets

    [telemetrix.x]
    step_pin = 2
    dir_pin = 5
    steps_per_mm = 101.78571428571429   # 2850 steps per 28 mm
    flip = false

    [telemetrix.y]
    step_pin = 3
    dir_pin = 6
    steps_per_mm = 101.78571428571429
    flip = false
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

from nlosplan.errors import UserError
from nlosplan.hardware.telemetrix_protocol import SPEED_LIMIT, STEP_LIMIT

__all__ = ["DENALI_STEPS_PER_MM", "AxisConfig", "TelemetrixConfig", "load_rig_file"]

DENALI_STEPS_PER_MM = 2850 / 28.0
DEFAULT_RIG_FILE = Path(__file__).with_name("rigs") / "denali-telemetrix.toml"
_TOP_KEYS = {"enable_pin", "enable_inverted", "max_speed", "acceleration", "origin_mm", "x", "y"}
_AXIS_KEYS = {"step_pin", "dir_pin", "steps_per_mm", "flip"}


@dataclass(frozen=True)
class AxisConfig:
    """One stepper axis: its pins, steps per mm and whether its direction is flipped."""

    step_pin: int
    dir_pin: int
    steps_per_mm: float = DENALI_STEPS_PER_MM
    flip: bool = False


@dataclass(frozen=True)
class TelemetrixConfig:
    """A Telemetrix gantry (defaults: DENALI's).

    Attributes
    ----------
    x, y : AxisConfig
    enable_pin : int
    enable_inverted : bool
        The CNC shield's enable input is active low.
    max_speed : int
        Steps/s, the stepper's maximum and (constant-speed mode) its speed.
    acceleration : int
        Steps/s²; 0 runs at constant speed without ramps (DENALI's
        ``run_speed_to_position``), > 0 uses AccelStepper's ramps (``run``).
    origin_mm : (float, float)
        User-frame position of the carriage when the board resets (positions
        count in steps from there).
    source : str
        Where the values came from (a file, or ``DENALI defaults``).
    """

    x: AxisConfig = field(default_factory=lambda: AxisConfig(2, 5))
    y: AxisConfig = field(default_factory=lambda: AxisConfig(3, 6))
    enable_pin: int = 8
    enable_inverted: bool = True
    max_speed: int = 32767
    acceleration: int = 0
    origin_mm: tuple = (0.0, 0.0)
    source: str = "DENALI defaults"

    def __post_init__(self) -> None:
        where = self.source
        for name, ax in (("x", self.x), ("y", self.y)):
            if not (isinstance(ax.steps_per_mm, (int, float)) and math.isfinite(ax.steps_per_mm)
                    and ax.steps_per_mm > 0):
                raise UserError(f"telemetrix {name}.steps_per_mm = {ax.steps_per_mm!r} in {where} must be > 0")
            for pin_name in ("step_pin", "dir_pin"):
                _pin(getattr(ax, pin_name), f"{name}.{pin_name}", where)
        _pin(self.enable_pin, "enable_pin", where)
        if not (isinstance(self.max_speed, int) and not isinstance(self.max_speed, bool)
                and 1 <= self.max_speed <= SPEED_LIMIT):
            raise UserError(f"telemetrix max_speed = {self.max_speed!r} in {where} must be an integer 1..{SPEED_LIMIT} "
                            "steps/s: Telemetrix4Arduino reads it as a 16-bit AVR int (above 32767 it arrives "
                            "negative; 65535 runs at 1 step/s)")
        if not (isinstance(self.acceleration, int) and not isinstance(self.acceleration, bool)
                and 0 <= self.acceleration <= SPEED_LIMIT):
            raise UserError(f"telemetrix acceleration = {self.acceleration!r} in {where} must be an integer "
                            f"0..{SPEED_LIMIT} steps/s^2 (0: constant speed; the firmware's 16-bit AVR int)")
        if len(self.origin_mm) != 2 or not all(isinstance(v, (int, float)) and math.isfinite(v)
                                               for v in self.origin_mm):
            raise UserError(f"telemetrix origin_mm = {self.origin_mm!r} in {where} must be two finite numbers (mm)")

    def axes(self) -> tuple[AxisConfig, AxisConfig]:
        return self.x, self.y

    def to_steps(self, x_mm: float, y_mm: float) -> tuple[int, int]:
        """Stepper targets (steps from the power-up position) of a user-frame position."""
        out = []
        for ax, v, o in zip(self.axes(), (x_mm, y_mm), self.origin_mm):
            s = round((v - o) * ax.steps_per_mm)
            out.append(-s if ax.flip else s)
        return out[0], out[1]

    def reach_mm(self) -> tuple[tuple[float, float], tuple[float, float]]:
        """The user-frame box the firmware can address: +-32,767 steps from ``origin_mm`` per axis, mm."""
        out = []
        for ax, o in zip(self.axes(), self.origin_mm):
            half = STEP_LIMIT / ax.steps_per_mm
            out.append((o - half, o + half))
        return out[0], out[1]

    def check_reach(self, limits_mm) -> None:
        """Raise a one-line UserError when ``limits_mm`` reach beyond the firmware's step range.

        Parameters
        ----------
        limits_mm : ((xmin, xmax), (ymin, ymax))
            The gantry limits in the user frame, mm.
        """
        for name, (u0, u1), (r0, r1), ax, o in zip("xy", limits_mm, self.reach_mm(), self.axes(), self.origin_mm):
            for v in (u0, u1):
                if not r0 - 1e-9 <= v <= r1 + 1e-9:
                    steps = round((v - o) * ax.steps_per_mm)
                    raise UserError(f"gantry limit {name} = {v:g} mm is {abs(steps):,} steps from origin_mm "
                                    f"{o:g} mm; Telemetrix4Arduino decodes step targets as 16-bit AVR ints "
                                    f"(+-{STEP_LIMIT:,} steps = {name} {r0:.1f}..{r1:.1f} mm at "
                                    f"{ax.steps_per_mm:.2f} steps/mm; beyond, it drives the other way): "
                                    "narrow --limits or move origin_mm")

    def checked_steps(self, x_mm: float, y_mm: float) -> tuple[int, int]:
        """:meth:`to_steps`, refused (LimitError, one line) beyond the firmware's +-32,767 step targets."""
        from nlosplan.hardware.gantry import LimitError

        targets = self.to_steps(float(x_mm), float(y_mm))
        for name, t in zip("xy", targets):
            if abs(t) > STEP_LIMIT:
                raise LimitError(f"gantry target ({x_mm:.3f}, {y_mm:.3f}) mm is {t:,} steps on {name}; "
                                 f"Telemetrix4Arduino decodes step targets as 16-bit AVR ints (+-{STEP_LIMIT:,} "
                                 "steps); nothing was sent")
        return targets

    def to_mm(self, x_steps: int, y_steps: int) -> tuple[float, float]:
        """User-frame position of stepper positions."""
        out = []
        for ax, s, o in zip(self.axes(), (x_steps, y_steps), self.origin_mm):
            out.append((-s if ax.flip else s) / ax.steps_per_mm + o)
        return out[0], out[1]

    def speed_mm_s(self, step_rate_limit: float = 4000.0) -> float:
        """The slower axis' speed in mm/s, at most ``step_rate_limit`` steps/s (AccelStepper on a 16 MHz AVR)."""
        rate = min(self.max_speed, step_rate_limit)
        return min(rate / ax.steps_per_mm for ax in self.axes())

    def describe(self) -> dict:
        return {"source": self.source, "enable_pin": self.enable_pin, "enable_inverted": self.enable_inverted,
                "max_speed_steps_s": self.max_speed, "acceleration_steps_s2": self.acceleration,
                "origin_mm": list(self.origin_mm),
                **{f"{n}": {"step_pin": a.step_pin, "dir_pin": a.dir_pin, "steps_per_mm": a.steps_per_mm,
                            "flip": a.flip} for n, a in (("x", self.x), ("y", self.y))}}


def _pin(v, name: str, where: str) -> None:
    if not (isinstance(v, int) and not isinstance(v, bool) and 0 <= v <= 254):
        raise UserError(f"telemetrix {name} = {v!r} in {where} must be a pin number 0..254")


def load_rig_file(path) -> TelemetrixConfig:
    """Read a rig file; unset values keep DENALI's defaults.

    Raises
    ------
    UserError
        Missing or unreadable file, bad TOML, unknown keys (typos), values out of range.
    """
    from nlosplan.schema import loads, read_text

    p = Path(path)
    data = loads(read_text(p, "rig file"), "toml", f"rig file {path}")  # one line: missing, FIFO, binary, too deep
    extra = set(data) - {"telemetrix"}
    if extra:
        raise UserError(f"rig file {path}: unknown table(s) {', '.join(sorted(extra))}; it holds [telemetrix]")
    t = data.get("telemetrix", {})
    unknown = set(t) - _TOP_KEYS
    if unknown:
        raise UserError(f"rig file {path}: unknown key(s) {', '.join(sorted(unknown))} in [telemetrix]; "
                        f"allowed: {', '.join(sorted(_TOP_KEYS))}")
    base = TelemetrixConfig()
    axes = {}
    for name, default in (("x", base.x), ("y", base.y)):
        a = t.get(name, {})
        if not isinstance(a, dict) or set(a) - _AXIS_KEYS:
            raise UserError(f"rig file {path}: [telemetrix.{name}] allows {', '.join(sorted(_AXIS_KEYS))}")
        axes[name] = AxisConfig(a.get("step_pin", default.step_pin), a.get("dir_pin", default.dir_pin),
                                a.get("steps_per_mm", default.steps_per_mm), bool(a.get("flip", default.flip)))
    origin = t.get("origin_mm", base.origin_mm)
    return TelemetrixConfig(axes["x"], axes["y"], t.get("enable_pin", base.enable_pin),
                            bool(t.get("enable_inverted", base.enable_inverted)), t.get("max_speed", base.max_speed),
                            t.get("acceleration", base.acceleration),
                            tuple(origin) if isinstance(origin, list) else origin, source=str(path))
