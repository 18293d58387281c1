"""Worlds: verdicts under the model's own uncertainty.

The simulated references rest on values no data pins down (the object's
albedo, the background level, ...) and on calibrated values that carry an
uncertainty. A *world* is one plausible set of them: overrides of
:class:`~nlosplan.sensor_models.SensorConfig` fields and of
:func:`~nlosplan.simulators.denali_scene` keyword arguments. The design run
draws ``count`` worlds (default 8) from

(a) the ``[worlds]`` ranges of the configuration (defaults:
    :func:`default_ranges`), each drawn by Latin-hypercube sampling, uniform
    or log-uniform, absolute or ``relative`` to the reference sensor's value;
(b) the reference sensor's parameter uncertainty when it has one
    (:func:`~nlosplan.sensor_models.uncertainty.uncertainty_for`): its
    ``samples`` in turn when present, else independent normals clipped to
    ``[lo, hi]``; these replace ranges of the same name.

World 0 is the nominal model (no overrides) at the worlds' scenes: the
control. Each world's references are simulated once per zone layout and
reused (``OUT/reference/world{i}_{layout}_{key}.npz``). A design's metric in
world ``w`` is its verified value shifted by the world's effect, measured as
the paired difference (same seeds: same split, training seed and noise
stream) between world ``w`` and world 0 on the worlds' scenes, on the score
scale (:mod:`~nlosplan.planner.design.verdicts`); so fewer scenes per world
cost interval width (the run-to-run variance of a difference of two runs on
``1 / scene_step`` of the scenes), not a bias.

Jitter and pulse width are design axes: a world's ``jitter_fwhm_ps`` or
``pulse_fwhm_ps`` is blur the model does not know, added in quadrature to
the design's (:func:`world_sensor`).
"""

from __future__ import annotations

import inspect
import math
from dataclasses import dataclass, field

import numpy as np

from nlosplan.errors import UserError, check_keys
from nlosplan.sensor_models import SensorConfig
from nlosplan.sensor_models.impulse import in_quadrature

__all__ = ["WorldRange", "WorldsConfig", "World", "default_ranges", "scene_parameters", "sensor_parameters",
           "draw_worlds", "world_sensor", "BLUR_FIELDS"]

#: Design-axis fields a world adds to in quadrature instead of replacing.
BLUR_FIELDS = ("jitter_fwhm_ps", "pulse_fwhm_ps")
#: Sensor fields a world may not change: the design sets them (layout, timing grid, photon budget).
_DESIGN_FIELDS = ("zones_rows", "zones_cols", "n_bins", "bin_width_ps", "iterations")
#: Physical limits ``(low, high, low_inclusive)`` of the parameters worlds usually vary.
LIMITS: dict[str, tuple[float, float, bool]] = {
    "albedo": (0.0, 1.0, True), "diffuse_albedo": (0.0, 1.0, True), "wall_albedo": (0.0, 1.0, True),
    "table_albedo": (0.0, 1.0, True), "mount_albedo": (0.0, 1.0, True), "lobe_fwhm_deg": (0.0, 180.0, False),
    "ambient_rate_hz": (0.0, math.inf, True), "dark_rate_hz": (0.0, math.inf, True),
    "photon_scale": (0.0, math.inf, False), "jitter_fwhm_ps": (0.0, math.inf, True),
    "pulse_fwhm_ps": (0.0, math.inf, True), "crosstalk": (0.0, 1.0, True),
}


def scene_parameters() -> tuple[str, ...]:
    """Numeric keyword arguments :func:`denali_scene` accepts now (checked by signature)."""
    from nlosplan.simulators import denali_scene

    return tuple(n for n, p in inspect.signature(denali_scene).parameters.items()
                 if p.kind is inspect.Parameter.KEYWORD_ONLY and isinstance(p.default, float))


def sensor_parameters() -> tuple[str, ...]:
    """Numeric sensor fields a world may override (not the design's own)."""
    from nlosplan.sensor_models.uncertainty import NUMERIC_FIELDS

    return tuple(f for f in NUMERIC_FIELDS if f not in _DESIGN_FIELDS)


@dataclass(frozen=True)
class WorldRange:
    """A declared range of one world parameter.

    Parameters
    ----------
    name : str
        A :func:`sensor_parameters` field or a :func:`scene_parameters` keyword.
    low, high : float
        Bounds (``low <= high``), in the parameter's unit, or factors of the
        reference sensor's value when ``relative``.
    relative : bool
        ``low``/``high`` multiply the reference sensor's value (sensor fields only).
    log : bool
        Draw log-uniformly (needs ``low > 0``).
    """

    name: str
    low: float
    high: float
    relative: bool = False
    log: bool = False

    def __post_init__(self) -> None:
        where = f"[worlds.ranges] {self.name}"
        allowed = sensor_parameters() + scene_parameters()
        if self.name not in allowed:
            raise UserError(f"{where}: unknown world parameter; allowed: {', '.join(allowed)}")
        for k in ("low", "high"):
            v = getattr(self, k)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise UserError(f"{where}: {k} must be a finite number, got {v!r}")
            object.__setattr__(self, k, float(v))
        if self.low > self.high:
            raise UserError(f"{where}: low {self.low:g} > high {self.high:g}")
        if self.relative and self.name not in sensor_parameters():
            raise UserError(f"{where}: relative ranges apply to sensor parameters only")
        if (self.log or self.relative) and self.low <= 0:
            raise UserError(f"{where}: a {'log' if self.log else 'relative'} range needs low > 0, got {self.low:g}")

    def check(self, reference: SensorConfig) -> None:
        """Raise if the range leaves the parameter's physical limits (relative ranges: on ``reference``)."""
        lo, hi = self.absolute(reference)
        lim = LIMITS.get(self.name)
        where = f"[worlds.ranges] {self.name}"
        if lim is not None:
            a, b, inclusive = lim
            if lo < a or hi > b or (not inclusive and lo <= a):
                rng = f"{'[' if inclusive else '('}{a:g}, {b:g}]"
                raise UserError(f"{where}: {lo:g}..{hi:g} leaves the physical range {rng}")
        if self.name in sensor_parameters():
            for v in (lo, hi):
                try:
                    reference.replace(**{self.name: v})
                except UserError as exc:
                    raise UserError(f"{where}: {exc}") from None

    def absolute(self, reference: SensorConfig) -> tuple[float, float]:
        """``(low, high)`` in the parameter's unit."""
        if self.relative:
            base = float(getattr(reference, self.name))
            return self.low * base, self.high * base
        return self.low, self.high

    def to_dict(self) -> dict:
        return {"name": self.name, "low": self.low, "high": self.high, "relative": self.relative, "log": self.log}


def default_ranges(lights: str = "off", model: str = "") -> tuple[WorldRange, ...]:
    """What no data pins down on the DENALI rig, as ranges (assumed; state yours in ``[worlds.ranges]``).

    With a sensor of no calibrated scene model (``model=""``, e.g. ``tmf8828-3x3-short``):

    - ``albedo`` 0.3-0.7: the objects' retroreflective albedo (the preset assumes 0.5);
    - ``diffuse_albedo`` 0-0.2: a diffuse base under the retroreflection, where
      :func:`denali_scene` accepts it (DENALI's Table 2 cannot separate the two);
    - the background: ``ambient_rate_hz`` x0.5-2 with the lights on, ``dark_rate_hz``
      x0.5-5 with them off (the room light the measured rate came from is not DENALI's);
    - ``photon_scale`` x0.5-2 (log): the photon budget was measured on another TMF882x and target;
    - ``jitter_fwhm_ps`` 0-150 ps: timing blur beyond the measured pulse shape.

    With a DENALI-calibrated sensor (``model="denali-tmf8828-3x3"``, the default reference) the fit
    pins the photon scale, the floor and the albedo: the scene parameters' ranges are the fit's
    intervals (:data:`~nlosplan.sensor_models.presets_denali.DENALI_SCENE_INTERVALS`: its bootstrap and
    model-variant refits), the diffuse base spans the variants Table 2 cannot decide, the sensor
    parameters come from the preset's shipped uncertainty (:func:`draw_worlds`), and only the timing
    blur beyond the measured pulse stays a declared range.
    """
    if model:
        from nlosplan.sensor_models.presets_denali import DENALI_SCENE_INTERVALS

        scene = set(scene_parameters())
        ranges = [WorldRange(n, float(iv[2]), float(iv[3])) for n, iv in sorted(DENALI_SCENE_INTERVALS.items())
                  if n in scene and iv[2] < iv[3]]
        return tuple(ranges) + (WorldRange("jitter_fwhm_ps", 0.0, 150.0),)
    ranges = [WorldRange("albedo", 0.3, 0.7)]
    if "diffuse_albedo" in scene_parameters():
        ranges.append(WorldRange("diffuse_albedo", 0.0, 0.2))
    if lights == "on":
        ranges.append(WorldRange("ambient_rate_hz", 0.5, 2.0, relative=True, log=True))
    else:
        ranges.append(WorldRange("dark_rate_hz", 0.5, 5.0, relative=True, log=True))
    ranges += [WorldRange("photon_scale", 0.5, 2.0, relative=True, log=True), WorldRange("jitter_fwhm_ps", 0.0, 150.0)]
    return tuple(ranges)


@dataclass(frozen=True)
class WorldsConfig:
    """How the run checks its answer under the model's uncertainty (the ``[worlds]`` table).

    Parameters
    ----------
    count : int
        Worlds drawn (>= 1).
    quorum : float
        Fraction of worlds a design must be met in to be the minimum hardware (0 < quorum <= 1).
    ranges : tuple of WorldRange, optional
        Declared ranges (default :func:`default_ranges` of the run's scenes).
    scene_step : int
        The worlds' scenes: every ``scene_step``-th gantry position of the run's (1: the same scenes,
        and world 0 is the run's own reference).
    candidates : int
        Most candidates per requirement checked in the worlds, until one holds (the cheapest met one, then
        designs robust to the losses seen: :func:`~nlosplan.planner.design.robust.next_candidate`).
    budget : int
        Extra evaluations the worlds may spend deciding undecided worlds (each extra seed of a world is a pair: the
        world's run and the control's), apart from the search's ``[search] budget`` so that the per-parameter
        rows never starve the answer's check. A world evaluation trains the learner on the worlds' scenes
        (about 0.25 s for the nearest-neighbour learner on 2 cores).
    seed : int
        Seed of the worlds' draw. The worlds sample the model's uncertainty, not a run's noise: they stay the
        same for every ``--seed`` (which redraws noise, splits and training), so two seeds judge their
        designs in the same worlds; change it to see other worlds.
    """

    count: int = 8
    quorum: float = 0.9
    ranges: tuple[WorldRange, ...] | None = None
    scene_step: int = 2
    candidates: int = 4
    budget: int = 48
    seed: int = 0

    def __post_init__(self) -> None:
        from nlosplan.resources import MAX_SEED

        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or not 0 <= self.seed <= MAX_SEED:
            raise UserError(f"[worlds] seed={self.seed!r} must be a whole number from 0 to {MAX_SEED}")
        for name, lo in (("count", 1), ("scene_step", 1), ("candidates", 1), ("budget", 0)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < lo:
                raise UserError(f"[worlds] {name}={v!r} must be a whole number >= {lo}")
        q = self.quorum
        if isinstance(q, bool) or not isinstance(q, (int, float)) or not 0 < q <= 1:
            raise UserError(f"[worlds] quorum={q!r} must be in (0, 1]")
        if self.ranges is not None:
            names = [r.name for r in self.ranges]
            dup = sorted({n for n in names if names.count(n) > 1})
            if dup:
                raise UserError(f"[worlds.ranges] {', '.join(dup)} given twice")

    def resolved_ranges(self, lights: str, model: str = "") -> tuple[WorldRange, ...]:
        """The declared ranges: the config's, else :func:`default_ranges` of the lights and scene model."""
        return self.ranges if self.ranges is not None else default_ranges(lights, model)

    def needed(self) -> int:
        """Worlds a design must be met in."""
        return int(math.ceil(self.quorum * self.count - 1e-9))

    def to_dict(self) -> dict:
        return {"count": self.count, "quorum": self.quorum, "scene_step": self.scene_step,
                "candidates": self.candidates, "budget": self.budget, "seed": self.seed,
                "ranges": None if self.ranges is None else [r.to_dict() for r in self.ranges]}

    @classmethod
    def from_dict(cls, data: dict, base: "WorldsConfig | None" = None) -> "WorldsConfig":
        """From a TOML ``[worlds]`` table (``[worlds.ranges]``: ``name = {low, high, relative, log}``)."""
        base = base or cls()
        check_keys(data, ("budget", "candidates", "count", "quorum", "ranges", "scene_step", "seed"),
                   "[worlds] key(s)")
        kw = {k: data[k] for k in ("count", "quorum", "scene_step", "candidates", "budget", "seed") if k in data}
        if "ranges" in data:
            table = data["ranges"]
            if not isinstance(table, dict) or not table:
                raise UserError("[worlds.ranges] must be a table of name = {low = .., high = ..}")
            ranges = []
            for name, spec in table.items():
                if not isinstance(spec, dict):
                    raise UserError(f"[worlds.ranges] {name} must be a table {{low = .., high = ..}}")
                check_keys(spec, ("high", "log", "low", "relative"), "key(s)", prefix=f"[worlds.ranges] {name}: ")
                if "low" not in spec or "high" not in spec:
                    raise UserError(f"[worlds.ranges] {name} needs low and high")
                ranges.append(WorldRange(name, spec["low"], spec["high"], bool(spec.get("relative", False)),
                                         bool(spec.get("log", False))))
            kw["ranges"] = tuple(ranges)
        return cls(**{**base.__dict__, **kw})


@dataclass(frozen=True)
class World:
    """One plausible world: ``sensor`` and ``scene`` overrides (world 0: none, the nominal model)."""

    index: int
    sensor: dict = field(default_factory=dict)
    scene: dict = field(default_factory=dict)

    @property
    def parameters(self) -> dict:
        return {**self.sensor, **self.scene}

    def to_dict(self) -> dict:
        return {"index": self.index, "sensor": dict(self.sensor), "scene": dict(self.scene)}


def _lhs(rng, k: int) -> np.ndarray:
    """Latin-hypercube fractions in (0, 1): one per stratum, shuffled."""
    return (rng.permutation(k) + rng.uniform(size=k)) / k


def draw_worlds(cfg: WorldsConfig, reference: SensorConfig, lights: str, seed: int,
                uncertainty: dict | None = None, model: str = "") -> list[World]:
    """World 0 (nominal) and ``cfg.count`` drawn worlds (see the module notes).

    Parameters
    ----------
    cfg : WorldsConfig
    reference : SensorConfig
        The space's reference sensor (the nominal values; relative ranges scale its fields).
    lights : str
        The run's scenes' lights (picks the default background parameter).
    seed : int
        The run's seed (the draws are reproducible from it).
    uncertainty : dict, optional
        A validated parameter uncertainty (:func:`~nlosplan.sensor_models.uncertainty.validate_uncertainty`).
    model : str
        The scenes' calibrated scene model (picks the default ranges, :func:`default_ranges`).
    """
    rng = np.random.default_rng([int(seed), 17])
    calibrated = {n: p for n, p in (uncertainty or {}).get("parameters", {}).items()
                  if n in sensor_parameters()}  # a calibrated bin width or zone count is the design's, not a world's
    ranges = [r for r in cfg.resolved_ranges(lights, model) if r.name not in calibrated]
    for r in ranges:
        r.check(reference)
    k = cfg.count
    columns: dict[str, np.ndarray] = {}
    for r in ranges:
        u = _lhs(rng, k)
        lo, hi = r.absolute(reference)
        columns[r.name] = (np.exp(np.log(lo) + u * (np.log(hi) - np.log(lo))) if r.log and lo > 0
                           else lo + u * (hi - lo))
    samples = (uncertainty or {}).get("samples") or []
    if calibrated:
        if samples:
            rows = rng.choice(len(samples), size=k, replace=len(samples) < k)
            for name in calibrated:
                columns[name] = np.array([samples[i].get(name, calibrated[name]["value"]) for i in rows], float)
        else:
            for name, p in calibrated.items():
                columns[name] = np.clip(rng.normal(p["value"], p["std"], k), p["lo"], p["hi"])
    sensor_names = set(sensor_parameters())
    worlds = [World(0)]
    for i in range(k):
        values = {n: float(round(float(col[i]), 6)) for n, col in columns.items()}
        worlds.append(World(i + 1, {n: v for n, v in values.items() if n in sensor_names},
                            {n: v for n, v in values.items() if n not in sensor_names}))
    return worlds


def world_sensor(design, reference: SensorConfig, overrides: dict | None) -> SensorConfig:
    """A design's sensor in a world: built on the overridden reference, blur added in quadrature."""
    overrides = overrides or {}
    plain = {k: v for k, v in overrides.items() if k not in BLUR_FIELDS}
    s = design.sensor(reference.replace(**plain) if plain else reference)
    blur = {k: in_quadrature(getattr(s, k), overrides[k]) for k in BLUR_FIELDS if k in overrides}
    return s.replace(**blur) if blur else s
