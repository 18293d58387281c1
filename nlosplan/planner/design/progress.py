"""Where a design run stands, read back from the files it writes (a live or finished ``OUT``).

:func:`design_progress` rebuilds the run's :class:`~nlosplan.planner.design.search.DesignSearch`
from ``design_checkpoint.json`` (the configuration, the optimize stage's
candidates) and ingests ``design_evaluations.jsonl``, exactly as a resumed run
does (:func:`~nlosplan.planner.design.run.run_design`), then asks it what it
would suggest next: the stage, the evaluations left in that stage, and the
answer so far (:func:`~nlosplan.planner.design.summary.summarize` of its
evidence). It computes nothing new and writes nothing: the run's files are the
only source. The live view (``nlosplan serve``, ``design --live``) shows it.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import NamedTuple

from nlosplan.errors import UserError
from nlosplan.planner.design.cost import CostModel
from nlosplan.planner.design.data import SceneSet
from nlosplan.planner.design.evaluation import Status
from nlosplan.planner.design.evidence import Candidate
from nlosplan.planner.design.references import real_reference_path, reference_paths
from nlosplan.planner.design.requirements import Requirement
from nlosplan.planner.design.run import CHECKPOINT, EVALUATIONS, check_log
from nlosplan.planner.design.search import DesignSearch, SearchConfig, Stage
from nlosplan.planner.design.space import DesignSpace
from nlosplan.planner.design.summary import summarize

__all__ = ["STAGES", "RunFiles", "design_progress", "search_from_files"]

#: The stages in run order: ``references`` (simulating, before any evaluation), the search's own
#: (:class:`~nlosplan.planner.design.search.Stage`, ``screen`` ... ``worlds``; ``optimize`` runs COBYLA and
#: evaluates nothing), ``finishing`` (nothing left to evaluate: the stability catalog and the report), ``done``
#: (``result.json`` written).
STAGES = ("references",) + tuple(s.value for s in Stage if s is not Stage.DONE) + ("finishing", "done")


class RunFiles(NamedTuple):
    """A run rebuilt from its files: the search, the checkpoint as read, and the simulated references it names."""

    search: DesignSearch
    checkpoint: dict
    references: dict[str, Path]


def search_from_files(out, results: list[dict] | None = None) -> RunFiles:
    """The run's search rebuilt from ``OUT``'s checkpoint, with its logged results ingested.

    Parameters
    ----------
    out : str or Path
        A design output folder.
    results : list of dict, optional
        The evaluation log, when already read (default: read ``design_evaluations.jsonl``).

    Returns
    -------
    RunFiles
        The search (its stage advanced as far as the results allow), the checkpoint and the reference files
        (layout -> path; the run may not have simulated them yet).

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
        real = cfg.get("real")
    except (OSError, json.JSONDecodeError) as exc:
        raise UserError(f"cannot read the design checkpoint {out / CHECKPOINT}: {exc}") from None
    except (KeyError, TypeError, ValueError) as exc:
        raise UserError(f"{out / CHECKPOINT} holds a configuration this nlosplan cannot read ({exc!r})") from None
    sims = reference_paths(out, space, scenes)
    real_refs = {k: real_reference_path(out, real) for k in sims} if real else None
    search = DesignSearch(space, reqs, search_cfg, sims, cost, real_refs)
    search.ingest(_logged(out) if results is None else results)
    candidates = ckpt.get("candidates")
    if candidates is not None:
        search.ingest_candidates({k: [Candidate.from_dict(c) for c in v] for k, v in candidates.items()},
                                 ckpt.get("optimize_log") or [])
    return RunFiles(search, ckpt, sims)


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
    search, ckpt, references = search_from_files(out, results)
    jobs = search.suggest()
    if jobs:
        stage = search.stage.value
    elif search.stage is Stage.OPTIMIZE and ckpt.get("candidates") is None:
        stage = "optimize"
    else:
        stage = "finishing"
    if not results and stage == "screen" and not all(p.exists() for p in references.values()):
        stage = "references"
    result = out / "result.json"   # written by the command after the run, so newer than the run's checkpoint
    finished = result.exists() and result.stat().st_mtime_ns >= (out / CHECKPOINT).stat().st_mtime_ns
    if finished:
        stage = "done"
    left_by: dict[str, int] = {}
    for j in jobs:
        left_by[j.evaluator.value] = left_by.get(j.evaluator.value, 0) + 1
    evidence, costs = search.evidence, {}
    for r in evidence.records():
        key = r.design.key()
        if key not in costs:
            c = evidence.cost(r.design)
            costs[key] = c if math.isfinite(c) else None
    return {"stage": stage, "done": len(results), "left": len(jobs), "left_by_evaluator": left_by,
            "failed": sum(r.get("status") == Status.FAILED for r in results), "costs": costs,
            "summary": summarize(evidence), "finished": finished}
