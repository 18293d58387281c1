"""The design search on typed evidence (issue 34): typed records, the read-only store and its lookups, and the seam
kept by an AST walk: no module outside ``planner/design/search.py`` reads the search's attributes beyond its ask/tell
surface, only the search writes the evidence store, and the sizes the issue set stay met."""

from __future__ import annotations

import ast
import json
import math
from pathlib import Path

import pytest

from nlosplan.planner.design.evaluation import Evaluation, Evaluator, Status, place_of
from nlosplan.planner.design.evidence import Candidate, Evidence, EvidenceStore
from nlosplan.planner.design.jobs import DesignJob
from nlosplan.planner.design.requirements import Condition, Requirement, Task
from nlosplan.planner.design.search import DesignSearch, SearchConfig, Stage
from nlosplan.planner.design.space import Design, DesignSpace

PACKAGE = Path(__file__).resolve().parents[1] / "nlosplan"
SPACE = DesignSpace(zones=((1, 1), (3, 3)), bin_factors=(1, 2), axes=("zones", "jitter_fwhm_ps", "photon_fraction"))
REFS = {"1x1": "out/reference/ref1.npz", "3x3": "out/reference/ref3.npz"}
LOC = Requirement("loc", 0.05)
SIZE = Requirement("size", 0.9)

#: What a module outside the search may use of a ``DesignSearch``: the ask/tell pair, the stage machine's hooks for
#: its driver (the optimize stage's jobs and candidates, the worlds' references) and the read-only evidence.
SURFACE = frozenset({"suggest", "ingest", "stage", "evidence", "optimize_jobs", "ingest_candidates",
                     "needed_references", "ingest_references"})
SEARCH_MODULE = "nlosplan.planner.design.search"
#: The drivers of the search: the only modules that may build one.
DRIVERS = frozenset({"nlosplan.planner.design.run", "nlosplan.planner.design.progress"})


def _record(job: DesignJob, value: float, **more) -> dict:
    return {**job.to_dict(), "metric": "loc_rmse", "value": value, "lo": 0.9 * value, "hi": 1.1 * value,
            "seconds": 0.5, "status": "ok", "reason": "", "extra": {}, **more}


# ------------------------------------------------------------------------------------------------ typed records
def test_a_logged_line_becomes_a_typed_record_and_misspelt_fields_fail_at_the_seam():
    search = DesignSearch(SPACE, [LOC, SIZE], SearchConfig(grid_points=3, seeds=1), REFS)
    job = search.job(Evaluator.TRAINED, SIZE, SPACE.reference_design().replace(jitter_fwhm_ps=100.0))
    line = json.loads(json.dumps(_record(job, 0.93)))  # as the log holds it: plain strings
    ev = Evaluation.from_record(line)
    assert (ev.evaluator, ev.task, ev.status) == (Evaluator.TRAINED, Task.SIZE, Status.OK)
    assert ev.evaluator is Evaluator.TRAINED and ev.task is Task.SIZE and ev.status is Status.OK
    assert ev.design == job.design and ev.seed == job.seed and ev.model == search.evidence.learner(Task.SIZE)
    assert ev.key == job.key and ev.place is None and ev.ok and ev.finite and (ev.lo, ev.hi) == (0.9 * 0.93, 1.1 * 0.93)
    # an executor's record of a job that raised carries only the job's fields, the status and the reason
    failed = Evaluation.from_record({**job.to_dict(), "status": "failed", "reason": "RuntimeError: boom"})
    assert failed.status is Status.FAILED and math.isnan(failed.value) and failed.seconds == 0.0 and not failed.finite
    with pytest.raises(ValueError, match="'traned' is not a valid Evaluator"):
        Evaluation.from_record({**line, "evaluator": "traned"})
    with pytest.raises(ValueError, match="'speed' is not a valid Task"):
        Evaluation.from_record({**line, "task": "speed"})
    with pytest.raises(KeyError, match="design"):
        Evaluation.from_record({k: v for k, v in line.items() if k != "design"})
    # an old log line: no world, no extra, the condition as text
    old = {k: v for k, v in line.items() if k not in ("world", "extra")}
    assert Evaluation.from_record({**old, "condition": "size=4in"}).condition == Condition("size", "4in")


def test_enums_are_their_logged_names():
    from nlosplan.planner.design.progress import STAGES
    from nlosplan.tasks.names import TASKS

    assert tuple(Task) == TASKS and [e.value for e in Evaluator] == ["bound", "trained", "trained_sim",
                                                                     "learning_curve"]
    assert json.dumps([Task.LOC, Evaluator.TRAINED_SIM, Status.UNREACHABLE]) == '["loc", "trained_sim", "unreachable"]'
    assert STAGES[1:-2] == tuple(s.value for s in Stage)[:-1] and STAGES[0] == "references"
    assert Evaluator.TRAINED_SIM.knobs == "trained" and not Evaluator.BOUND.trains
    assert Evaluator.LEARNING_CURVE.knobs == "trained" and Evaluator.LEARNING_CURVE.trains
    assert Requirement("loc", 0.05).task is Task.LOC and Requirement.from_dict(LOC.to_dict()) == LOC
    # the job's key, what resume looks up in old logs, is the one of plain strings
    plain = DesignJob("trained", "size", Design(), 3, {"model": "mlp"}, None, "r.npz", {})
    assert plain.evaluator is Evaluator.TRAINED and plain.key == DesignJob(Evaluator.TRAINED, Task.SIZE, Design(), 3,
                                                                           {"model": "mlp"}, None, "r.npz", {}).key


# ---------------------------------------------------------------------------------------------- the store
def test_the_store_finds_runs_by_what_a_query_asks_without_rebuilding_jobs():
    search = DesignSearch(SPACE, [LOC], SearchConfig(grid_points=3, seeds=1, max_seeds=4, models=("mlp",)), REFS)
    d = SPACE.reference_design()
    jobs = [search.job(Evaluator.TRAINED, LOC, d, i) for i in (0, 2)]
    jobs.append(search.job(Evaluator.TRAINED, LOC, d, 0, reference="world/world3_3x3_k.npz", world={"albedo": 0.3}))
    jobs.append(search.job(Evaluator.BOUND, LOC, d))
    search.ingest([_record(j, 0.04 + 0.001 * k) for k, j in enumerate(jobs)])
    ev = search.evidence
    assert len(ev) == 4 and [r.key for r in ev.records()] == [j.key for j in jobs]
    # runs in seed order, nominal model only (the world's run has its own place)
    assert [r.seed for r in ev.runs(LOC, d)] == [jobs[0].seed, jobs[1].seed]
    assert ev.run(Evaluator.TRAINED, LOC, d, 1) is None
    world = ev.run(Evaluator.TRAINED, LOC, d, 0, place=place_of("elsewhere/world3_3x3_k.npz", {"albedo": 0.3}))
    assert world is not None and world.key == jobs[2].key and world.place == ("world3_3x3_k.npz", '{"albedo": 0.3}')
    assert ev.bound(LOC, d).key == jobs[3].key and ev.bound_meets(LOC, d)  # lo 0.9 * 0.043 <= 0.05
    # a condition is another cell: a requirement on 4-inch objects has no runs yet
    assert ev.runs(Requirement("loc", 0.05, ("size", "4in")), d) == []
    tv = ev.trained_value(LOC, d)
    assert tv.seeds == 2 and tv.value == pytest.approx(0.0405) and tv.verdict == "met"
    # the same key ingested again replaces the first, and is not counted twice
    search.ingest([_record(jobs[0], 0.06)])
    assert len(ev) == 4 and ev.runs(LOC, d)[0].value == 0.06
    assert isinstance(ev, Evidence) and not hasattr(ev, "add") and not hasattr(ev, "ingest")  # only the search writes


def test_candidates_keep_the_checkpoint_format():
    row = {"requirement": LOC.name, "design": Design().to_dict(), "cost": 1.5, "predicted": 0.04, "bound": 0.02,
           "status": "feasible", "reason": "", "choice": "3x3, bin x1", "evaluations": 3, "seconds": 0.1}
    c = Candidate.from_dict({**row, "source": "optimized"})
    assert c.design == Design() and c.cost == 1.5 and c.source == "optimized" and c.trained is None
    assert c.to_dict() == {**row, "source": "optimized"} and list(c.to_dict()) == [*row, "source"]
    assert Candidate.from_dict(c.to_dict()) == c
    scan = Candidate(Design(zones=(1, 1)), 0.5)
    assert scan.to_dict() == {"design": Design(zones=(1, 1)).to_dict(), "cost": 0.5, "source": "scans"}


def test_a_resumed_search_jumps_to_the_optimize_stage_it_had_reached():
    search = DesignSearch(SPACE, [LOC], SearchConfig(grid_points=3, seeds=1, models=("mlp",)), REFS)
    assert search.stage is Stage.SCREEN and search.suggest()
    search.ingest_candidates({LOC.name: [Candidate(SPACE.reference_design(), 1.0, "optimized")]}, [])
    assert search.stage is Stage.OPTIMIZE
    jobs = search.suggest()  # past optimize: the verify stage trains the candidate over the seeds
    assert search.stage is Stage.VERIFY and [(j.evaluator, j.design) for j in jobs] == [
        (Evaluator.TRAINED, SPACE.reference_design())]
    assert search.evidence.stage == "verify"


# ------------------------------------------------------------------------- the seam, kept by an AST walk
def _modules(root: Path) -> dict[str, Path]:
    out = {}
    for path in sorted(root.rglob("*.py")):
        parts = list(path.relative_to(root.parent).with_suffix("").parts)
        out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return out


def _imports_of(tree: ast.AST, name: str) -> set[str]:
    """Local names a module binds to ``name`` imported from anywhere in nlosplan."""
    return {a.asname or a.name for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)
            and (node.module or "").startswith("nlosplan") for a in node.names if a.name == name}


def _search_names(func: ast.AST, classes: set[str]) -> set[str]:
    """Names in one scope that hold a DesignSearch: built by it, annotated with it, unpacked first from
    ``search_from_files``, or called ``search`` (the convention every driver follows)."""
    names = {"search"}
    args = getattr(func, "args", None)
    if args is not None:
        for a in args.args + args.kwonlyargs + args.posonlyargs:
            if a.annotation is not None and any(c in ast.unparse(a.annotation) for c in classes):
                names.add(a.arg)
    for node in ast.walk(func):
        if isinstance(node, ast.Assign) and isinstance(node.value, ast.Call):
            called = ast.unparse(node.value.func)
            for t in node.targets:
                if isinstance(t, ast.Name) and called in classes:
                    names.add(t.id)
                if isinstance(t, ast.Tuple) and called.endswith("search_from_files") and isinstance(t.elts[0], ast.Name):
                    names.add(t.elts[0].id)
    return names


def search_reads(root: Path) -> list[str]:
    """Every read of a DesignSearch attribute outside its module that is not in :data:`SURFACE`, and every module
    outside the drivers that imports the class or the evidence store's writable class."""
    found = []
    for mod, path in _modules(root).items():
        if mod == SEARCH_MODULE:
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"))
        classes = _imports_of(tree, "DesignSearch")
        if classes and mod not in DRIVERS:
            found.append(f"{mod}: imports DesignSearch (only its drivers, {', '.join(sorted(DRIVERS))}, may)")
        if _imports_of(tree, "EvidenceStore") and mod != "nlosplan.planner.design.evidence":
            found.append(f"{mod}: imports EvidenceStore (only the search writes the evidence)")
        scopes = [tree] + [n for n in ast.walk(tree) if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))]
        for scope in scopes:
            names = _search_names(scope, classes | {"DesignSearch"})
            for node in ast.walk(scope):
                if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id in names
                        and node.attr not in SURFACE):
                    found.append(f"{mod}:{node.lineno}: reads {node.value.id}.{node.attr}")
    return sorted(set(found))


def test_no_module_outside_the_search_reads_its_attributes():
    assert search_reads(PACKAGE) == []


def test_the_search_seam_checker_catches_planted_reads(tmp_path):
    pkg = tmp_path / "nlosplan"
    (pkg / "planner" / "design").mkdir(parents=True)
    (pkg / "reports").mkdir()
    for rel, text in {
        "planner/design/search.py": "class DesignSearch:\n    results = {}\n",
        "planner/design/run.py": ("from nlosplan.planner.design.search import DesignSearch as DS\n"
                                  "def go():\n    s = DS()\n    s.suggest()\n    return s.results\n"),
        "planner/design/progress.py": ("from nlosplan.planner.design.search import DesignSearch\n"
                                       "def rebuilt(out):\n    search, ckpt, refs = search_from_files(out)\n"
                                       "    return search.evidence, search._store\n"),
        "planner/design/summary.py": ("from nlosplan.planner.design.evidence import EvidenceStore\n"
                                      "def summarize(search: 'DesignSearch'):\n    return search.candidates\n"),
        "reports/page.py": "from nlosplan.planner.design.search import DesignSearch\n",
    }.items():
        (pkg / rel).write_text(text)
    found = search_reads(pkg)
    assert found == sorted([
        "nlosplan.planner.design.progress:4: reads search._store",
        "nlosplan.planner.design.run:5: reads s.results",
        "nlosplan.planner.design.summary:3: reads search.candidates",
        "nlosplan.planner.design.summary: imports EvidenceStore (only the search writes the evidence)",
        "nlosplan.reports.page: imports DesignSearch (only its drivers, nlosplan.planner.design.progress, "
        "nlosplan.planner.design.run, may)"]), found


def string_keyed_lookups(folder: Path) -> dict[str, int]:
    """``x["k"]`` and ``x.get("k")`` per module of a folder (the issue's count of loose-dict reads)."""
    out = {}
    for path in sorted(folder.glob("*.py")):
        n = 0
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Subscript) and isinstance(node.slice, ast.Constant) \
                    and isinstance(node.slice.value, str):
                n += 1
            elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "get"
                  and node.args and isinstance(node.args[0], ast.Constant) and isinstance(node.args[0].value, str)):
                n += 1
        out[path.name] = n
    return out


def test_the_search_stays_small_and_the_planner_reads_typed_records(tmp_path):
    assert len((PACKAGE / "planner/design/search.py").read_text().splitlines()) <= 300
    counts = string_keyed_lookups(PACKAGE / "planner/design")
    assert sum(counts.values()) <= 160, counts
    assert counts["search.py"] <= 5 and counts["robust.py"] == 0 and counts["lines.py"] == 0, counts
    (tmp_path / "probe.py").write_text('x["a"]\nx.get("b")\nx[0]\nx.get(k)\ny["c"] = 1\nf"{x}"\n')
    assert string_keyed_lookups(tmp_path) == {"probe.py": 3}
