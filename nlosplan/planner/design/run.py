"""``run_design``: references, the ask/tell search on an executor, a JSON checkpoint, the summary.

This is the executor side of the search's ``suggest``/``ingest``
(:mod:`nlosplan.planner.protocol`): it runs what the search suggests and
ingests the results. The checkpoint is ``OUT/design_checkpoint.json`` (the
configuration and the optimize stage's candidates, rewritten atomically) and
``OUT/design_evaluations.jsonl`` (every evaluation ingested so far, with its
design, evaluator, fidelity, metric, interval, run time and status; one line
appended and flushed per result). ``resume=True`` ingests everything in it,
so nothing already evaluated is computed again. The simulated references are
saved beside it and reused when their configuration matches; they, and the
worlds' references (:mod:`~nlosplan.planner.design.worlds`), are simulated
on the executor, one job per zone layout and world.
"""

from __future__ import annotations

import hashlib
import json
import os
import platform
import subprocess
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

from nlosplan.data.load import check_captures, load_dataset
from nlosplan.errors import UserError
from nlosplan.files import write_bytes, write_text, writing
from nlosplan.planner.design import reference_cache, robust
from nlosplan.planner.design.budget import (budget_statement, check_budget_memory, check_real_budget,
                                            default_captures, real_capacity, requested)
from nlosplan.planner.design.catalog import keep as stability_keep
from nlosplan.planner.design.catalog import kept_summary, run_catalog, stability_summary
from nlosplan.planner.design.cost import CostModel
from nlosplan.planner.design.data import SceneSet, build_reference, reference_from_dataset
from nlosplan.planner.design.evaluation import Evaluation, Evaluator
from nlosplan.planner.design.evaluators import evaluate
from nlosplan.planner.design.evidence import Candidate
from nlosplan.planner.design.executors import make_executor
from nlosplan.planner.design.jobs import CatalogJob, ReferenceJob
from nlosplan.planner.design.optimize import collect_candidates, optimize_choice, run_optimize
from nlosplan.planner.design.references import real_reference_path, reference_paths, world_reference_path
from nlosplan.planner.design.requirements import DEFAULT_REQUIREMENTS, Requirement
from nlosplan.planner.design.scheduling import RunTimes
from nlosplan.planner.design.search import SEED_STRIDE, DesignSearch, SearchConfig, Stage
from nlosplan.planner.design.space import Design, DesignSpace, parse_zones
from nlosplan.planner.design.summary import summarize
from nlosplan.planner.design.workers import hold_programs
from nlosplan.planner.design.worlds import WorldsConfig, draw_worlds, world_sensor
from nlosplan.sensor_models import resolve_sensor

__all__ = ["DesignConfig", "run_design", "read_evaluations", "CHECKPOINT", "EVALUATIONS"]

CHECKPOINT = "design_checkpoint.json"
EVALUATIONS = "design_evaluations.jsonl"


@dataclass(frozen=True)
class DesignConfig:
    """Everything a design run depends on (what the checkpoint must match to resume).

    Parameters
    ----------
    space : DesignSpace
    requirements : tuple of Requirement
    cost : CostModel
    search : SearchConfig
    scenes : SceneSet
        Simulated scenes of the evaluators.
    real : str, optional
        A capture store (SQLite) whose captures the trained evaluator uses
        instead of simulated ones (degraded to each design).
    real_where : dict, optional
        Filter of the real captures (e.g. ``{"lights": "off"}``).
    capture_sensor : str, optional
        Preset or sensor file of the real captures (default: the space's reference).
    label : str
        ``"full"`` or ``"quick"`` (for the report).
    worlds : WorldsConfig
        The plausible worlds the cheapest met candidates are checked in (not with ``real``).

    Notes
    -----
    ``scenes.model`` always follows the space's reference: a DENALI-calibrated reference
    (``denali-tmf8828-3x3``, the default) simulates its scenes with the scene parameters it was fitted
    with (:mod:`~nlosplan.simulators.presets.scene_model`), any other with the scene's defaults.
    """

    space: DesignSpace = field(default_factory=DesignSpace)
    requirements: tuple[Requirement, ...] = DEFAULT_REQUIREMENTS
    cost: CostModel = field(default_factory=CostModel)
    search: SearchConfig = field(default_factory=SearchConfig)
    scenes: SceneSet | None = None
    real: str | None = None
    real_where: dict | None = None
    capture_sensor: str | None = None
    label: str = "full"
    worlds: WorldsConfig = field(default_factory=WorldsConfig)

    def __post_init__(self) -> None:
        from nlosplan.simulators.presets.scene_model import scene_model

        if self.scenes is not None:
            model = scene_model(self.space.reference)
            if self.scenes.model != model:
                object.__setattr__(self, "scenes", replace(self.scenes, model=model))

    def to_dict(self) -> dict:
        return {"space": self.space.to_dict(), "requirements": [r.to_dict() for r in self.requirements],
                "cost": self.cost.to_dict(), "search": self.search.to_dict(),
                "scenes": None if self.scenes is None else self.scenes.to_dict(), "real": self.real,
                "real_where": self.real_where, "capture_sensor": self.capture_sensor, "label": self.label,
                "worlds": self.worlds.to_dict()}

    def hash(self) -> str:
        return hashlib.sha1(json.dumps(self.to_dict(), sort_keys=True, default=str).encode()).hexdigest()[:12]


def _git_revision() -> str:
    try:
        out = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, timeout=5,
                             cwd=Path(__file__).resolve().parent)
        return out.stdout.strip() or "unknown"
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def provenance(cfg: DesignConfig, seconds: float, executor_name: str) -> dict:
    """What made a run: configuration, seeds, versions, revision, wall time, machine."""
    import importlib.metadata as md

    versions = {}
    for pkg in ("nlosplan", "numpy", "jax", "torch", "nlopt", "pandas", "dask", "matplotlib"):
        try:
            versions[pkg] = md.version(pkg)
        except md.PackageNotFoundError:
            versions[pkg] = "not installed"
    return {"config": cfg.to_dict(), "config_hash": cfg.hash(), "seed": cfg.search.seed,
            "seeds": f"evaluation seeds {cfg.search.seed} x {SEED_STRIDE} + i (i: a design's i-th run)",
            "versions": versions, "git_revision": _git_revision(), "wall_seconds": seconds,
            "executor": executor_name, "python": platform.python_version(), "machine": platform.machine(),
            "cpus": os.cpu_count()}


def read_evaluations(path) -> list[dict]:
    """The results in a ``design_evaluations.jsonl`` log, in order (a torn last line, a killed run's, is left out).

    Raises
    ------
    UserError
        A line before the last does not hold an evaluation (see :func:`check_log`).
    """
    return check_log(path).results


def _evaluation(line: str) -> dict | None:
    """The evaluation record of a log line, or None when the line is not one."""
    try:
        r = json.loads(line)
    except json.JSONDecodeError:
        return None
    return r if isinstance(r, dict) and {"evaluator", "task", "design"} <= set(r) else None


@dataclass
class LogCheck:
    """What a ``design_evaluations.jsonl`` holds: its results, damaged lines (1-based) and a torn tail."""

    results: list[dict]
    damaged: list[int]
    torn_tail: bool
    lines: list[str]


def check_log(path, *, repair: bool = False) -> LogCheck:
    """Read an evaluation log; damaged lines stop it unless ``repair``.

    The last line without its newline is the evaluation a killed run was
    writing: it is left out (and cut from the file when the run resumes).
    Any other line that is not a JSON evaluation is damage: a UserError
    names the lines, unless ``repair`` (then they are left out and reported
    in ``damaged``).
    """
    path = Path(path)
    if not path.exists():
        return LogCheck([], [], False, [])
    data = path.read_bytes()
    torn = bool(data) and not data.endswith(b"\n")
    lines = data.decode("utf-8", errors="replace").split("\n")
    if lines and lines[-1] == "":
        lines.pop()
    results, damaged = [], []
    for i, line in enumerate(lines, 1):
        r = _evaluation(line)
        if r is None:
            if not (torn and i == len(lines)):  # the line a killed run was writing is not damage
                damaged.append(i)
            continue
        results.append(r)
    body = lines[:-1] if torn and _evaluation(lines[-1]) is None else lines
    if damaged and not repair:
        shown = ", ".join(map(str, damaged[:10])) + (f" and {len(damaged) - 10} more" if len(damaged) > 10 else "")
        raise UserError(f"{path}: line(s) {shown} of {len(body)} are damaged (not an evaluation); rerun with --resume "
                        "--repair to drop them (their evaluations run again), or restore the file")
    return LogCheck(results, damaged, torn, body)


class _Checkpoint:
    """``design_checkpoint.json`` (configuration, candidates) + ``design_evaluations.jsonl`` (one result per line).

    Results are appended and flushed one line at a time, so a killed run
    loses at most the evaluation in flight. Starting over where a run's
    files exist needs ``overwrite`` (they move to ``.bak``); resuming needs
    a checkpoint; a damaged log needs ``repair`` (see :func:`check_log`).
    """

    def __init__(self, path: Path, cfg: DesignConfig, resume: bool, *, overwrite: bool = False, repair: bool = False,
                 say=None):
        self.path = path
        self.log = path.with_name(EVALUATIONS)
        self.data = {"config_hash": cfg.hash(), "config": cfg.to_dict(), "candidates": None, "optimize_log": []}
        self.results: list[dict] = []
        say = say or (lambda text: None)
        if resume:
            if not path.exists():
                raise UserError(f"--resume: there is no run to resume in {path.parent} (no {path.name}); "
                                "run without --resume to start one")
            try:
                old = json.loads(path.read_text())
            except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
                raise UserError(f"cannot read the checkpoint {path}: {exc}") from None
            if not isinstance(old, dict) or old.get("config_hash") != cfg.hash():
                raise UserError(f"{path} is from a run with another configuration; use another --out, "
                                "or run with --overwrite to start over (the old files move to .bak)")
            self.data = old
            check = check_log(self.log, repair=repair)
            self.results = check.results
            if check.damaged or check.torn_tail:  # rewrite the log without them, keeping the damaged one aside
                if check.damaged:
                    kept = write_bytes(self.log.with_name(self.log.name + ".damaged"), self.log.read_bytes())
                    say(f"--repair: dropped damaged line(s) {', '.join(map(str, check.damaged))} of {self.log.name} "
                        f"(their evaluations run again; the damaged file is kept as {kept.name})")
                write_text(self.log, "".join(json.dumps(r, default=_json_default) + "\n" for r in self.results))
        else:
            if repair:
                raise UserError("--repair applies only with --resume")
            old = [p for p in (path, self.log) if p.exists()]
            if old and not overwrite:
                n = len(check_log(self.log, repair=True).results) if self.log.exists() else 0
                raise UserError(f"{path.parent} holds a previous run ({n} evaluations); pass --resume to continue it, "
                                "--overwrite to start over (its files move to .bak), or choose another --out")
            for p in old:
                p.replace(p.with_name(p.name + ".bak"))
            if old:
                say(f"--overwrite: the previous run's {', '.join(p.name for p in old)} moved to .bak")
            self.save()
        self._fh = open(self.log, "a")

    def add(self, result: dict) -> None:
        self.results.append(result)
        self._fh.write(json.dumps(result, default=_json_default) + "\n")
        self._fh.flush()

    def save(self) -> None:
        write_text(self.path, json.dumps(self.data, default=_json_default))

    def close(self) -> None:
        self._fh.close()


def _json_default(o):
    if isinstance(o, (Design, Candidate)):
        return o.to_dict()
    if hasattr(o, "item"):
        return o.item()
    raise TypeError(f"not JSON serializable: {type(o).__name__}")


def _programs(job) -> str:
    """What a reference job compiles: its zone layout's simulator."""
    return f"{job.sensor.zones_rows}x{job.sensor.zones_cols}"


def _prepare(job) -> dict:
    """One job of the preparation stages, on any executor: a reference to simulate, or the stability catalog.

    A process keeps the programs its last job compiled while the next job compiles the same (the worlds'
    references of one zone layout: tracing them and loading them again from the on-disk cache cost 3 of a 3x3
    world reference's 8 s) and drops them before a job of another layout
    (:func:`~nlosplan.planner.design.workers.hold_programs`); a stage that ran drops the rest
    (:func:`_recycle`). The catalog runs in a process of its own (:func:`~nlosplan.stability.run_apart`).
    """
    if isinstance(job, CatalogJob):  # in a process of its own: what this one holds stays for its next reference
        return run_catalog(job)
    hold_programs(_programs(job))
    return build_reference(job)


#: After a simulation stage, a local pool's workers are replaced when one holds more than this (bytes of resident
#: memory): the 8x8 reference leaves 2.5-2.9 GB, a round of small world references 0.6-1.3 GB.
RECYCLE_ABOVE_BYTES = 1_500_000_000


def _recycle(executor) -> None:
    """After a simulation stage: fresh workers for the evaluations where one grew large, or the programs dropped
    where there are no workers (:meth:`PoolExecutor.recycle` and the others')."""
    executor.recycle(RECYCLE_ABOVE_BYTES)


def _simulate(executor, jobs: list[ReferenceJob], say, what: str, cache: bool = True,
              catalog: bool = False) -> tuple[dict, dict | None]:
    """Run reference jobs on the executor (in parallel); ``label -> seconds`` and the catalog's summary.

    A failure stops the run. With ``cache``, a reference an earlier run left in :mod:`.reference_cache` is
    copied instead of simulated, and a simulated one is put there. The largest layouts start first (the
    executors start jobs in order, so the longest does not run alone at the end). With ``catalog``, the
    stability catalog runs as one more job, after the largest reference, when any reference is simulated;
    its summary is returned (None when it did not run: the caller runs it). (In two parts, the larger first, the
    references and the catalog took 80 s on a fresh cache against 81 s: not kept.) When anything ran, a local pool's
    workers are replaced by fresh ones if one grew past :data:`RECYCLE_ABOVE_BYTES`
    (:meth:`PoolExecutor.recycle`): the evaluations do not carry the memory of the large simulations (the cold
    main job peaked at 4.6 GB without it), and do not import everything again after small ones.
    """
    if cache:
        jobs = [j for j in jobs if Path(j.path).exists() or not reference_cache.restore(j.path, j.sensor, j.scenes, say)]
    jobs = sorted(jobs, key=lambda j: -j.sensor.zones_rows * j.sensor.zones_cols)
    if catalog and jobs:
        jobs.insert(1, CatalogJob())
    out, summary = {}, None
    for i, (job, res) in enumerate(executor.map(_prepare, jobs)):
        if isinstance(job, CatalogJob):
            if res.get("status") == "ok":
                summary = stability_keep(res, cache)
            else:
                say(f"{what}: the stability catalog stopped on its worker ({res.get('reason')}); it runs again at "
                    "the end")
            say(f"{what}: {job.label}", i + 1, len(jobs))
            continue
        if res.get("status") != "ok":
            raise RuntimeError(f"simulating the {job.label} reference failed: {res.get('reason')}")
        out[job.label] = res["seconds"]
        say(f"{what}: {job.label}", i + 1, len(jobs))
        if cache:
            reference_cache.store(job.path, job.sensor, job.scenes)
    if jobs:
        _recycle(executor)
    return out, summary


def _references(cfg: DesignConfig, out: Path, say, executor, cache: bool = True,
                catalog: bool = False, worlds: robust.WorldPlan | None = None) -> tuple[dict, dict, dict, dict | None]:
    """Simulated reference per zone layout (reused when saved with the same key); real ones if asked.

    With ``catalog``, the stability catalog runs beside the references it simulates; its summary is the last
    item (None when it did not run). With ``worlds``, the fast simulator plans them for the worlds' largest
    jitter (:func:`_support_sigma`), so the worlds' references later run the programs compiled here.
    """
    from nlosplan.planner.design.data import load_reference

    real, info = {}, {}
    space, scenes = cfg.space, cfg.scenes
    sims = reference_paths(out, space, scenes)
    support = _support_sigma(cfg, worlds, scenes.backend)
    jobs = [ReferenceJob(str(path), space.layout_sensor(parse_zones(layout)), scenes, layout, support)
            for layout, path in sims.items() if not path.exists()]
    stability = None
    if jobs:
        beside = " and the stability catalog" if catalog else ""
        say(f"references: simulating {len(jobs)} ({scenes.n_scenes} scenes each){beside}")
        stability = _simulate(executor, jobs, say, "references", cache, catalog)[1]
    for layout, path in sims.items():
        ref = load_reference(path)
        info[layout] = {"scenes": int(len(ref.labels)), "bound_scenes": int(len(ref.crlb_labels)),
                        "seconds": ref.seconds, "source": f"{scenes.backend} simulator", "fidelity": scenes.fidelity}
    if cfg.real:
        captured = resolve_sensor(cfg.capture_sensor or space.reference)
        ds = load_dataset(cfg.real, {**(cfg.real_where or {}), "zones": f"{captured.zones_rows}x{captured.zones_cols}"},
                          drop_backgrounds=True, zones_hint="the real captures must have the capture sensor's zones "
                                                            "(give the matching --capture-sensor)")
        ref = reference_from_dataset(ds, captured, str(cfg.real))
        path = real_reference_path(out, cfg.real)
        ref.save(path)
        real = {layout: path for layout in sims}  # unreachable layouts are reported per evaluation
        info["real"] = {"captures": int(len(ds)), "source": str(cfg.real), "sensor": captured.name,
                        "training_captures": real_capacity(ds.labels).captures}
    return sims, real, info, stability


def check_inputs(cfg: DesignConfig, workers: int | None = None) -> None:
    """What a run needs from outside, checked before any work: the real captures' store and sensor, that they hold
    the training captures asked for, and memory for the learners' training sets (one line each)."""
    budget = requested(cfg.search.fidelity[Evaluator.TRAINED.knobs])
    cells = max(r * c for r, c in cfg.space.zones) * cfg.space.sensor.n_bins
    check_budget_memory(budget, cells, workers or os.cpu_count() or 1)
    if cfg.real:
        captured = resolve_sensor(cfg.capture_sensor or cfg.space.reference)
        zones = f"{captured.zones_rows}x{captured.zones_cols}"
        where = check_captures(cfg.real, {**(cfg.real_where or {}), "zones": zones}, drop_backgrounds=True,
                               zones_hint="the real captures must have the capture sensor's zones (give the matching "
                                          "--capture-sensor)")
        check_real_budget(budget, cfg.real, where)


def run_design(cfg: DesignConfig, out, *, resume: bool = False, workers: int | None = None,
               cluster: str | None = None, progress=None, overwrite: bool = False, repair: bool = False,
               cache: bool = True) -> dict:
    """Run the design search and summarize it.

    Parameters
    ----------
    cfg : DesignConfig
    out : str or Path
        Output folder (checkpoint, references, report).
    resume : bool
        Continue from ``OUT/design_checkpoint.json`` (same configuration); an error when there is none.
    workers : int, optional
        Local worker processes (default: the CPU count; 1 runs in this process).
    cluster : str, optional
        ``tcp://HOST:PORT`` or ``local:N`` (Dask) instead of the local pool.
    progress : callable, optional
        ``progress(text, done, total)`` after each step; ``text`` starts with the stage (``references``,
        ``grid``, ``refine``, ``optimize``, ``verify``, ...) and a colon; ``done``/``total`` count the
        evaluations done and planned so far (None where not counted).
    overwrite : bool
        Start over where a previous run's files are (they move to ``.bak``); without it that is an error.
    repair : bool
        With ``resume``: drop damaged lines of the evaluation log (else they stop the run with their numbers).
    cache : bool
        Take simulated references from the content cache of earlier runs and put new ones there
        (:mod:`~nlosplan.planner.design.reference_cache`); False simulates them (``--no-cache``).

    Returns
    -------
    dict
        :func:`~nlosplan.planner.design.summary.summarize`'s result plus
        ``provenance``, ``references``, ``stability`` and ``checkpoint``.

    Raises
    ------
    UserError
        Before any work: nothing to resume, a previous run without ``overwrite``, a damaged log without
        ``repair``, unusable real captures or capture sensor, an unreachable cluster.
    """
    t0 = time.perf_counter()
    out = Path(out)
    say = (lambda text, done=None, total=None: progress(text, done, total)) if progress else (lambda *a, **k: None)
    check_inputs(cfg, workers)
    worlds = None if cfg.real else _world_plan(cfg)  # a bad calibration uncertainty stops the run before any work
    out.mkdir(parents=True, exist_ok=True)
    ckpt = _Checkpoint(out / CHECKPOINT, cfg, resume, overwrite=overwrite, repair=repair,
                       say=lambda text: say(f"checkpoint: {text}"))
    try:
        executor = make_executor(workers, cluster)
    except BaseException:
        ckpt.close()
        raise
    try:
        with writing(kept=f"every evaluation finished so far is kept in {ckpt.log}",
                     cont="free some space and rerun with --resume"):
            result, stability = _search(cfg, out, ckpt, executor, say, worlds, cache)
        executor_name = executor.name
    finally:
        executor.close()
        ckpt.close()
    from nlosplan.simulators.presets.scene_model import describe_scene_options

    result.update(provenance=provenance(cfg, time.perf_counter() - t0, executor_name), references=result.pop("_refs"),
                  stability=stability, checkpoint=str(out / CHECKPOINT),
                  world_model=_world_model(cfg, describe_scene_options))
    return result


def _world_model(cfg: DesignConfig, describe) -> dict:
    """``result.json``'s ``world_model``: the reference sensor, its scene model and options, the capture sessions'
    floor spread (a fraction of the floor; 0: one floor for every session) and one line saying all of it."""
    sd = cfg.scenes.session_sd()
    sessions = (f"capture sessions' floor spread {100 * sd:.2f} %" if sd else "one floor for every capture session")
    return {"sensor": cfg.space.reference, "scene_model": cfg.scenes.model or None,
            "scene_options": cfg.scenes.options(), "session_floor_sd": sd,
            "scene": f"{describe(cfg.scenes.options())}; {sessions}"}


def _search(cfg: DesignConfig, out: Path, ckpt: _Checkpoint, executor, say,
            worlds: robust.WorldPlan | None, cache: bool = True) -> tuple[dict, dict | None]:
    """References, then the ask/tell loop on ``executor`` until the search has nothing left; the summary."""
    quick = cfg.label.startswith("quick")
    stability = kept_summary(quick, cache)  # None: the catalog runs beside the references, or at the end
    sims, real, ref_info, ran = _references(cfg, out, say, executor, cache, catalog=stability is None, worlds=worlds)
    stability = stability or ran
    if worlds is not None and cfg.worlds.scene_step == 1:  # the worlds' scenes are the run's: world 0 is its own
        worlds.references.update({(0, layout): str(path) for layout, path in sims.items()})
    search = DesignSearch(cfg.space, cfg.requirements, cfg.search, sims, cfg.cost, real or None, worlds)
    search.ingest(ckpt.results)
    saved = ckpt.data.get("candidates")
    if saved is not None:  # the optimize stage ran: the search continues after it
        search.ingest_candidates({k: [Candidate.from_dict(c) for c in v] for k, v in saved.items()},
                                 ckpt.data.get("optimize_log") or [])
    done = len(ckpt.results)
    times = RunTimes(Evaluation.from_record(r) for r in ckpt.results)
    while True:
        jobs = times.longest_first(search.suggest())
        if not jobs and search.stage is Stage.OPTIMIZE:
            say("optimize: nlopt COBYLA per discrete choice on the corrected bound", done, done)
            log = run_optimize(search.optimize_jobs(), cfg.search.candidates,
                               lambda jobs: executor.map(optimize_choice, jobs, ahead=executor.workers))
            cands = collect_candidates(search.evidence, log, cfg.search.candidates)
            ckpt.data.update(candidates=cands, optimize_log=log)
            ckpt.save()
            search.ingest_candidates(cands, log)
            continue
        need = search.needed_references() if not jobs and search.stage is Stage.WORLDS else []
        if need:
            search.ingest_references(_world_references(cfg, out, worlds, need, executor, say, cache))
            continue
        if not jobs:
            break
        total = done + len(jobs)
        say(f"{search.stage}: {len(jobs)} evaluations", done, total)
        for _, result in executor.map(evaluate, jobs):
            ev = Evaluation.from_record(result)
            search.ingest([ev])
            ckpt.add(result)
            times.add(ev)
            done += 1
            say(f"{search.stage}: {ev.evaluator} {ev.task} {ev.design.key()}", done, total)
    if stability is None:
        stability = stability_summary(quick, cache, say)
    say("summary: writing")
    result = summarize(search.evidence)
    result.update(_refs=ref_info, train_captures=_budget(cfg, search.evidence, ref_info))
    return result, stability


def _budget(cfg: DesignConfig, evidence, ref_info: dict) -> dict:
    """The run's training budget and learner family (:func:`~nlosplan.planner.design.budget.budget_statement`)."""
    fid = cfg.search.fidelity[Evaluator.TRAINED.knobs]
    real = ref_info.get("real")
    default = real["training_captures"] if real else default_captures(cfg.scenes.n_scenes)
    learners = {str(r.task): evidence.learner(r.task) for r in evidence.task_requirements()}
    return budget_statement(requested(fid), default=default, learners=learners, models=cfg.search.models,
                            epochs=int(fid["epochs"]), repeats=int(fid["repeats"]), real=bool(cfg.real))


def _support_sigma(cfg: DesignConfig, worlds: robust.WorldPlan | None, backend: str) -> float:
    """The Gaussian sigma (ps) every simulated reference of the run is planned for: its worlds' largest.

    The nominal references and every world's then share one plan structure, so one compiled program, per zone
    layout (a zero-jitter sensor in a plan sized for a Gaussian gives the same histograms within float32
    rounding). 0 without worlds and for the Mitsuba twin (no plan).
    """
    if worlds is None or backend != "fast":
        return 0.0
    design = cfg.space.layout_design(cfg.space.zones[0])  # a world's blur is the same in every layout
    return max((world_sensor(design, cfg.space.sensor, w.sensor).impulse_sigma_ps for w in worlds.worlds),
               default=0.0)


def _world_plan(cfg: DesignConfig) -> robust.WorldPlan:
    """The run's worlds (drawn from its seed) and their scenes."""
    from nlosplan.sensor_models.uncertainty import uncertainty_for

    space, wcfg = cfg.space, cfg.worlds
    unc, unc_source = uncertainty_for(space.reference)
    worlds = draw_worlds(wcfg, space.sensor, cfg.scenes.lights, wcfg.seed, unc, cfg.scenes.model)
    step = wcfg.scene_step
    scenes = replace(cfg.scenes, positions=cfg.scenes.positions[::step], crlb_objects=())
    ranges = [r for r in wcfg.resolved_ranges(cfg.scenes.lights, cfg.scenes.model)
              if r.name not in (unc or {}).get("parameters", {})]
    sources = [f"declared ranges: {', '.join(r.name for r in ranges)}" if ranges else "no declared ranges",
               f"calibrated: {', '.join(unc['parameters'])} ({unc_source})" if unc else f"no calibration ({unc_source})"]
    return robust.WorldPlan(wcfg, worlds, scenes, cfg.scenes.n_scenes / scenes.n_scenes, sources=sources)


def _world_references(cfg: DesignConfig, out: Path, plan: robust.WorldPlan, need, executor, say,
                      cache: bool = True) -> dict:
    """Simulate the references ``need`` lists (``(world, layout)``) on the executor; ``(index, layout) -> path``."""
    jobs, paths = [], {}
    for w, layout in need:
        sensor = world_sensor(cfg.space.layout_design(parse_zones(layout)), cfg.space.sensor, w.sensor)
        sensor = sensor.replace(name=f"reference {layout}, world {w.index}")
        scenes = replace(plan.scenes, scene_kwargs=w.scene)
        path = world_reference_path(out, w.index, layout, scenes, sensor)
        paths[(w.index, layout)] = str(path)
        jobs.append(ReferenceJob(str(path), sensor, scenes, f"world {w.index}, {layout}"))
    # every world planned for the largest world's Gaussian, as the nominal references were (_support_sigma): a
    # layout's worlds run the program the nominal references stage compiled and left in the compilation cache
    # (each world's own sigma would round to its own support: world references compiled the simulator once per
    # 50 ps step); the twin has no plan to size
    # a world's scenes are every scene_step-th position of the nominal ones: padded to the nominal plan (sizes that
    # a subset of positions can come out smaller in), they run its program
    pad = cfg.scenes if plan.scenes.backend == "fast" and plan.scenes != cfg.scenes else None
    jobs = [replace(j, min_support_sigma_ps=_support_sigma(cfg, plan, plan.scenes.backend), pad_scenes=pad)
            for j in jobs]
    say(f"world references: simulating {len(jobs)} ({plan.scenes.n_scenes} scenes each)")
    _simulate(executor, jobs, say, "world references", cache)
    return paths
