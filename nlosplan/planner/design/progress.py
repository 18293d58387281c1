"""Where a design run stands, read back from the files it writes (a live or finished ``OUT``).

:func:`design_progress` rebuilds the run's :class:`~nlosplan.planner.design.search.DesignSearch`
from ``design_checkpoint.json`` (the configuration, the optimize stage's
candidates) and ingests ``design_evaluations.jsonl``, exactly as a resumed run
does (:func:`~nlosplan.planner.design.run.run_design`), then asks it what it
would suggest next: the stage, the evaluations left in that stage, and the
answer so far (:func:`~nlosplan.planner.design.summary.summarize` of what has
landed). It computes nothing new and writes nothing: the run's files are the
only source. The live view (``nlosplan serve``, ``design --live``) shows it.
"""

from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path

from nlosplan.errors import UserError
from nlosplan.planner.design.cost import CostModel
from nlosplan.planner.design.data import SceneSet
from nlosplan.planner.design.requirements import Requirement
from nlosplan.planner.design.run import CHECKPOINT, EVALUATIONS, check_log
from nlosplan.planner.design.search import DesignSearch, SearchConfig
from nlosplan.planner.design.space import Design, DesignSpace
from nlosplan.planner.design.summary import summarize

__all__ = ["STAGES", "design_progress", "search_from_files"]

#: The stages in run order: ``references`` (simulating, before any evaluation), the search's own
#: (:attr:`DesignSearch.STAGES`, ``screen`` ... ``worlds``; ``optimize`` runs COBYLA and evaluates nothing),
#: ``finishing`` (nothing left to evaluate: the stability catalog and the report), ``done`` (``result.json``
#: written).
STAGES = ("references",) + tuple(s for s in DesignSearch.STAGES if s != "done") + ("finishing", "done")


def _reference_paths(out: Path, space: DesignSpace, scenes: SceneSet, cfg: dict) -> tuple[dict, dict]:
    """The reference files a run of this configuration uses (the names its evaluation keys carry)."""
    sims = {}
    for z in space.zones:
        ref_design = Design(z, 1, space.sensor.n_bins, space.jitter_fwhm_ps[0], space.pulse_fwhm_ps[0], 1.0)
        sensor = ref_design.sensor(space.sensor).replace(name=f"reference {z[0]}x{z[1]}")
        sims[f"{z[0]}x{z[1]}"] = out / "reference" / f"{z[0]}x{z[1]}_{scenes.key(sensor)}.npz"
    real = {}
    if cfg.get("real"):
        path = out / "reference" / f"real_{hashlib.sha1(str(cfg['real']).encode()).hexdigest()[:8]}.npz"
        real = {k: path for k in sims}
    return sims, real


def search_from_files(out, results: list[dict] | None = None) -> tuple[DesignSearch, dict]:
    """The run's search rebuilt from ``OUT``'s checkpoint, with its logged results ingested.

    Parameters
    ----------
    out : str or Path
        A design output folder.
    results : list of dict, optional
        The evaluation log, when already read (default: read ``design_evaluations.jsonl``).

    Returns
    -------
    (DesignSearch, dict)
        The search (its stage advanced as far as the results allow) and the checkpoint.

    Raises
    ------
    UserError
        No readable checkpoint, or one this code cannot rebuild a search from.
    """
    out = Path(out)
    try:
        ckpt = json.loads((out / CHECKPOINT).read_text())
        cfg = ckpt["config"]
        space = DesignSpace.from_dict(cfg["space"])
        reqs = [Requirement.from_dict(r) for r in cfg["requirements"]]
        search_cfg = SearchConfig(**cfg["search"])
        scenes = SceneSet.from_dict(cfg["scenes"])
        cost = CostModel.from_dict(cfg["cost"])
    except (OSError, json.JSONDecodeError) as exc:
        raise UserError(f"cannot read the design checkpoint {out / CHECKPOINT}: {exc}") from None
    except (KeyError, TypeError, ValueError) as exc:
        raise UserError(f"{out / CHECKPOINT} holds a configuration this nlosplan cannot read ({exc!r})") from None
    sims, real = _reference_paths(out, space, scenes, cfg)
    search = DesignSearch(space, reqs, search_cfg, sims, cost, real or None)
    search.ingest(_logged(out) if results is None else results)
    if ckpt.get("candidates") is not None:
        cands = {k: [{**c, "design": Design.from_dict(c["design"])} for c in v] for k, v in ckpt["candidates"].items()}
        search.stage = "optimize"
        search.set_candidates(cands, ckpt.get("optimize_log") or [])
    return search, ckpt


def _logged(out: Path) -> list[dict]:
    """The evaluations a run logged so far, for a reader that watches it: damaged lines are left out, never fatal
    (the run itself stops on them when it resumes; see :func:`~nlosplan.planner.design.run.check_log`)."""
    return check_log(out / EVALUATIONS, repair=True).results


def design_progress(out, results: list[dict] | None = None) -> dict:
    """Stage, evaluations done and left, and the answer so far of a design run (live or finished).

    Parameters
    ----------
    out : str or Path
        The run's output folder.
    results : list of dict, optional
        The evaluation log, when already read.

    Returns
    -------
    dict
        ``stage`` (one of :data:`STAGES`), ``done`` (evaluations logged), ``left``
        (evaluations the search would still run in this stage; later stages are
        not known before this one ends), ``left_by_evaluator`` (``{"bound": n,
        ...}``), ``failed``, ``costs`` (design key -> cost, for every design
        logged), ``summary`` (the answer so far, as ``result.json`` will hold it
        at the end) and ``finished`` (``result.json`` is there, newer than the checkpoint: the run ended).
    """
    out = Path(out)
    results = _logged(out) if results is None else results
    search, ckpt = search_from_files(out, results)
    jobs = search.suggest()
    if jobs:
        stage = search.stage
    elif search.stage == "optimize" and ckpt.get("candidates") is None:
        stage = "optimize"
    else:
        stage = "finishing"
    if not results and stage == "screen":
        refs = list(search.references.values())
        if not all(Path(p).exists() for p in refs):
            stage = "references"
    result = out / "result.json"   # written by the command after the run, so newer than the run's checkpoint
    finished = result.exists() and result.stat().st_mtime_ns >= (out / CHECKPOINT).stat().st_mtime_ns
    if finished:
        stage = "done"
    left_by = {}
    for j in jobs:
        left_by[j.evaluator] = left_by.get(j.evaluator, 0) + 1
    costs = {}
    for r in results:
        d = Design.from_dict(r["design"])
        if d.key() not in costs:
            c = search.cost(d, search.space)
            costs[d.key()] = c if math.isfinite(c) else None
    return {"stage": stage, "done": len(results), "left": len(jobs), "left_by_evaluator": left_by,
            "failed": sum(r.get("status") == "failed" for r in results), "costs": costs,
            "summary": summarize(search), "finished": finished}
