"""Run configurations: the full default, ``--quick``, and TOML files.

A TOML file may hold any of these tables (all optional; what is missing
keeps the default of the chosen mode)::

    [space]                      # DesignSpace fields
    reference = "denali-tmf8828-3x3"   # the default; DENALI presets bring their fitted scene
    zones = ["1x1", "3x3", "8x8"]
    jitter_fwhm_ps = [0, 800]

    [[requirements]]
    task = "loc"
    threshold = 0.05
    condition = "size=4in"       # optional: size=, lights=, quadrant=

    [cost]                       # CostModel weights per doubling
    zones = 0.3

    [search]                     # SearchConfig (fidelity as a table of tables)
    seeds = 3
    seed = 0                     # the run's seed (--seed): noise, splits and training seeds
    models = ["mlp", "cnn1d"]    # candidate learners (--models); the best per task is used
    max_seeds = 8                # most seeds of an undecided candidate
    budget = 30                  # extra evaluations to decide undecided candidates and rows
    curve_seeds = 2              # seeds of each learning-curve point at the reference design (0: none)
    [search.fidelity.trained]
    train_captures = 25200       # training captures of each learner (--train-captures; default one per
                                 # training scene: 2,100 here, 700 with --quick)

    [scenes]                     # SceneSet: simulated scenes of the evaluators
    positions_stride = 2
    session_floor_sd = 0         # capture sessions' floor spread (fraction; default the scene model's,
                                 # 0.0173 for DENALI's unit; 0 = one floor for every session)

    [worlds]                     # WorldsConfig: plausible worlds the answer must hold in
    count = 8                    # --worlds
    quorum = 0.9                 # a minimum design must be met in this fraction of them
    scene_step = 2               # worlds simulate every 2nd position of the run's scenes
    candidates = 4               # most candidates examined per requirement until one holds
    budget = 48                  # extra world evaluations to decide undecided worlds (apart from [search]'s)
    seed = 0                     # the worlds' draw (the same for every --seed)
    [worlds.ranges]              # what no data pins down (replaces the defaults when given)
    albedo = {low = 0.3, high = 0.7}
    photon_scale = {low = 0.5, high = 2.0, relative = true, log = true}
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from nlosplan.errors import UserError, check_keys
from nlosplan.schema import (NUMBER, STRING, Spec, check_types, int_in, list_of, load_table, number_in, one_of,
                             pair_of, predicate, quantity, table_of)
from nlosplan.planner.design.budget import MAX_TRAIN_CAPTURES, TRAIN_CAPTURES
from nlosplan.planner.design.cost import CostModel
from nlosplan.planner.design.data import SceneSet
from nlosplan.planner.design.evaluators import DEFAULT_FIDELITY
from nlosplan.planner.design.requirements import DEFAULT_REQUIREMENTS, Requirement
from nlosplan.planner.design.run import DesignConfig
from nlosplan.planner.design.search import SearchConfig
from nlosplan.planner.design.space import DesignSpace, parse_zones
from nlosplan.planner.design.worlds import WorldsConfig

__all__ = ["full_config", "quick_config", "load_config", "QUICK_OBJECTS"]

#: Ten DENALI objects across the three class groups (the quick run's shape classes).
QUICK_OBJECTS = ("A", "S", "O", "V", "3", "7", "circle", "plus", "triangle", "minus")


def full_config() -> DesignConfig:
    """The main job: all 30 objects, both sizes, 50 positions; the whole default space."""
    from nlosplan.denali import DENALI_OBJECTS

    return DesignConfig(search=SearchConfig(curve_seeds=2), scenes=SceneSet(objects=DENALI_OBJECTS), label="full")


def quick_config() -> DesignConfig:
    """``--quick``: 10 objects, 50 positions, zones 1x1 and 3x3, four axes, coarse grids (CI, README)."""
    fid = {k: dict(v) for k, v in DEFAULT_FIDELITY.items()}
    fid["bound"]["draws"] = 200
    fid["trained"]["epochs"] = 20
    space = DesignSpace(zones=((1, 1), (3, 3)), bin_factors=(1, 2, 4),
                        axes=("zones", "bin_factor", "jitter_fwhm_ps", "photon_fraction"))
    search = SearchConfig(grid_points=4, refine_steps=1, seeds=3, candidates=1, optimize_evals=8, fidelity=fid,
                          max_seeds=4, budget=16, curve_seeds=1)
    scenes = SceneSet(objects=QUICK_OBJECTS, positions=tuple(range(0, 100, 2)), crlb_objects=("A", "S"),
                      crlb_stride=10)
    worlds = WorldsConfig(count=4, scene_step=2, candidates=3, budget=24)
    return DesignConfig(space=space, search=search, scenes=scenes, label="quick", worlds=worlds)


def _schema() -> dict:
    """What each key of a design TOML must hold (checked when the file is read, before any work)."""
    from nlosplan.denali import DENALI_OBJECTS, SIZES
    from nlosplan.simulators import BACKENDS, FIDELITY_LEVELS

    zone = Spec('a zone grid such as "3x3"', parse_zones)  # a UserError of parse_zones marks a bad value
    objects = list_of(predicate('a DENALI object such as "A" or "circle"', lambda v: v in DENALI_OBJECTS), min_len=1)
    count = int_in(1)
    return {
        "space": {"reference": STRING, "zones": list_of(zone, min_len=1), "bin_factors": list_of(int_in(1, 64), min_len=1),
                  "n_bins": pair_of(int_in(1, 4096)), "jitter_fwhm_ps": pair_of(quantity("jitter_fwhm_ps")),
                  "pulse_fwhm_ps": pair_of(quantity("pulse_fwhm_ps")), "photon_fraction": pair_of(number_in(0, 1)),
                  "axes": list_of(STRING, min_len=1)},
        "requirement": {"task": one_of("loc", "shape", "size"), "threshold": NUMBER, "condition": STRING},
        "cost": {k: number_in(0, 1000) for k in CostModel().to_dict()},   # relative weights (defaults 0.1-0.3)
        "search": {"grid_points": int_in(1, 100), "refine_steps": int_in(0, 20), "seeds": int_in(1, 20),
                   "candidates": int_in(1, 100), "optimize_evals": int_in(1, 10_000), "curve_seeds": int_in(0, 8),
                   "fidelity": table_of()},
        "bound": {"draws": count, "looks": count, "crlb_repeats": count},
        "trained": {"model": STRING, "epochs": count, "width": number_in(0, lo_open=True), "repeats": count,
                    "bootstrap": int_in(0), TRAIN_CAPTURES: int_in(2, MAX_TRAIN_CAPTURES)},
        "scenes": {"objects": objects, "sizes": list_of(one_of(*SIZES), min_len=1),
                   "positions": list_of(int_in(0, 99), min_len=1), "positions_stride": int_in(1, 99),
                   "lights": one_of("off", "on"), "repeats": count, "crlb_objects": objects, "crlb_stride": count,
                   "fidelity": one_of(*FIDELITY_LEVELS), "backend": one_of(*BACKENDS),
                   "session_floor_sd": number_in(0, 0.5)},
    }


def _table(data: dict, name: str, where: str) -> dict:
    t = data.get(name, {})
    if not isinstance(t, dict):
        raise UserError(f"{where}: [{name}] must be a table, not {type(t).__name__} {t!r}")
    return t


def load_config(path, base: DesignConfig) -> DesignConfig:
    """``base`` with the tables of a TOML file applied (see the module notes).

    Every table and key is type- and range-checked when the file is read,
    before any evaluation: a wrong type is one line naming the file, the
    table, the key and what it must hold.
    """
    p = Path(path)
    data = load_table(p, "configuration file", suffixes=(".toml",))
    check_keys(data, ("space", "requirements", "cost", "search", "scenes", "worlds"), "table(s)", prefix=f"{p}: ")
    types = _schema()
    cfg = base
    if "space" in data:
        space = check_types(_table(data, "space", str(p)), types["space"], f"{p}: [space]")
        cfg = replace(cfg, space=DesignSpace.from_dict({**base.space.to_dict(), **space}))
    if "requirements" in data:
        reqs = data["requirements"]
        if not isinstance(reqs, list) or not reqs or not all(isinstance(r, dict) for r in reqs):
            raise UserError(f"{p}: [[requirements]] must be a non-empty array of tables")
        reqs = [check_types(r, types["requirement"], f"{p}: [[requirements]] #{i + 1}") for i, r in enumerate(reqs)]
        try:
            cfg = replace(cfg, requirements=tuple(Requirement.from_dict(r) for r in reqs))
        except (KeyError, TypeError) as exc:
            raise UserError(f"{p}: each requirement needs task and threshold ({exc})") from None
    if "cost" in data:
        cost = check_types(_table(data, "cost", str(p)), types["cost"], f"{p}: [cost]")
        cfg = replace(cfg, cost=CostModel.from_dict({**base.cost.to_dict(), **cost}))
    if "search" in data:
        s = dict(check_types(_table(data, "search", str(p)), types["search"], f"{p}: [search]"))
        given = s.pop("fidelity", {})
        check_keys(given, tuple(base.search.fidelity), "evaluator(s)", prefix=f"{p}: ", suffix=" in [search.fidelity]")
        for name, knobs in given.items():
            if not isinstance(knobs, dict):
                raise UserError(f"{p}: [search.fidelity] {name} = {knobs!r} must be a table of knobs, e.g. "
                                f"[search.fidelity.{name}]")
            check_types(knobs, types.get(name, {}), f"{p}: [search.fidelity.{name}]")
        fid = {k: {**v, **given.get(k, {})} for k, v in base.search.fidelity.items()}
        try:
            cfg = replace(cfg, search=replace(base.search, fidelity=fid, **s))
        except TypeError as exc:
            raise UserError(f"{p}: [search]: {exc}") from None
        except UserError as exc:
            raise UserError(f"{p}: {exc}") from None
    if "scenes" in data:
        s = dict(check_types(_table(data, "scenes", str(p)), types["scenes"], f"{p}: [scenes]"))
        stride = s.pop("positions_stride", None)
        if stride is not None:
            s["positions"] = tuple(range(0, 100, stride))
        try:
            cfg = replace(cfg, scenes=replace(base.scenes, **s))
        except TypeError as exc:
            raise UserError(f"{p}: [scenes]: {exc}") from None
    if "worlds" in data:
        try:
            cfg = replace(cfg, worlds=WorldsConfig.from_dict(_table(data, "worlds", str(p)), base.worlds))
        except UserError as exc:
            raise UserError(f"{p}: {exc}") from None
        for r in cfg.worlds.ranges or ():
            try:
                r.check(cfg.space.sensor)
            except UserError as exc:
                raise UserError(f"{p}: {exc}") from None
    return cfg


__all__ += ["DEFAULT_REQUIREMENTS"]
