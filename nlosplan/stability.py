"""The stability catalog: stiff and extreme cases every room must survive.

Each room contributes an explicit list of :class:`~nlosplan.cases.Case`
objects (no registration by import side effect); :func:`all_cases` gathers
them and :func:`~nlosplan.cases.run_cases` runs them, timing each and turning
exceptions into failures with their message. This module sits above the
rooms it lists (sensor_models, simulators); the entry type and the runner
live below every room, in :mod:`nlosplan.cases`.

:func:`run_apart` runs cases in a process of their own whose XLA compiles cheaply
(:data:`CATALOG_XLA_FLAGS`): ``nlosplan check`` and a design run's catalog run them that way.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from dataclasses import asdict
from typing import Callable

from nlosplan.cases import Case, CaseResult, run_cases
from nlosplan.resources import end_with_parent
from nlosplan.sensor_models.stability_cases import CASES as sensor_cases
from nlosplan.simulators.fast.stability_cases import CASES as transport_cases
from nlosplan.simulators.stability_cases import CASES as simulator_cases

__all__ = ["CATALOG_XLA_FLAGS", "Case", "CaseResult", "all_cases", "run_apart", "run_cases"]

#: XLA options of the catalog's own process (:func:`run_apart`): LLVM without optimisation, and XLA's CPU backend
#: without its fusion emitters. The catalog's ~900 programs each run a few times, so compiling them is most of its
#: time (59 of 80 s on a 2-core machine with the defaults); compiled this way the catalog took 54-56 s (96 -> 58-60
#: CPU-seconds), every case passing either way. Only rounding differs (the cases' tolerances are far wider); the
#: simulations of a design run and of ``nlosplan simulate`` keep the defaults.
CATALOG_XLA_FLAGS = ("--xla_backend_optimization_level=0", "--xla_cpu_use_fusion_emitters=false")

#: What the catalog's process writes before each result line (anything else it prints goes to standard error).
_MARK = "nlosplan-case "
#: Environment variable carrying the pid of the process that starts the catalog's (:func:`catalog_env`).
PARENT_ENV = "NLOSPLAN_CATALOG_PARENT"


def all_cases() -> list[Case]:
    """Every case of every room that has one, sensor models first."""
    return list(sensor_cases) + list(simulator_cases) + list(transport_cases)


def catalog_env(environ=None) -> dict:
    """The environment of the catalog's process: ``environ`` (default: this one's) with
    :data:`CATALOG_XLA_FLAGS` after any ``XLA_FLAGS`` already set (the later of two equal options counts), and this
    process's pid in :data:`PARENT_ENV`, so the catalog's process ends with it even when it dies before the
    catalog's imports are done (the process would be re-parented by then and could not tell its parent was gone)."""
    env = dict(os.environ if environ is None else environ)
    env["XLA_FLAGS"] = " ".join(filter(None, (env.get("XLA_FLAGS", "").strip(), *CATALOG_XLA_FLAGS)))
    env[PARENT_ENV] = str(os.getpid())
    return env


def run_apart(cases: list[Case], progress: Callable[[CaseResult], None] | None = None) -> list[CaseResult]:
    """Run ``cases`` (by name, from :func:`all_cases`) in a new process of this Python with :func:`catalog_env`.

    XLA reads its options once per process, when it starts, so a process that already computed (a design run's
    worker, which simulates references after the catalog) cannot take them: the cases run in one of their own.
    ``progress(result)`` after each case, as :func:`~nlosplan.cases.run_cases`.

    Raises
    ------
    RuntimeError
        The process stopped before every case had its result (its last line of standard error is in the message).
    """
    names = [c.name for c in cases]
    code = "from nlosplan.stability import _child; _child()"
    with tempfile.TemporaryFile("w+") as err:
        proc = subprocess.Popen([sys.executable, "-c", code, *names], stdout=subprocess.PIPE, stderr=err,
                                env=catalog_env(), text=True)
        results = []
        try:
            for line in proc.stdout:
                if line.startswith(_MARK):
                    results.append(CaseResult(**json.loads(line[len(_MARK):])))
                    if progress is not None:
                        progress(results[-1])
        except BaseException:  # interrupted here (Ctrl-C, a failing progress callback): the cases stop with it
            proc.kill()
            proc.wait()
            raise
        rc = proc.wait()
        if rc != 0 or len(results) != len(names):
            err.seek(0)
            last = [s.strip() for s in err.read().splitlines() if s.strip()][-1:] or ["nothing on standard error"]
            raise RuntimeError(f"the stability catalog's process stopped (exit {rc}) after {len(results)} of "
                               f"{len(names)} cases: {last[0]}")
    return results


def _child() -> None:
    """The catalog's process (:func:`run_apart`): run the cases named in ``sys.argv[1:]``, one result line each."""
    end_with_parent(int(os.environ.get(PARENT_ENV, os.getppid())))
    out = os.fdopen(os.dup(1), "w")
    os.dup2(2, 1)  # what the cases print goes to standard error; standard output carries the results only
    known = {c.name: c for c in all_cases()}
    unknown = [n for n in sys.argv[1:] if n not in known]
    if unknown:
        print(f"no such stability case: {', '.join(unknown)}", file=sys.stderr)
        sys.exit(2)

    def say(res: CaseResult) -> None:
        out.write(_MARK + json.dumps(asdict(res)) + "\n")
        out.flush()

    run_cases([known[n] for n in sys.argv[1:]], say)
    out.close()
    sys.stderr.flush()
    os._exit(0)  # every result is out: no teardown of JAX and every module (~1 s)
