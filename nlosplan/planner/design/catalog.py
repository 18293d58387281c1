"""The stability catalog's verdict in a design run, kept between runs of the same code.

The catalog (:mod:`nlosplan.stability`: stiff and extreme cases of the sensor models and simulators) checks the
code, not the run's inputs: its result depends only on the source of the rooms it covers and on the numerical
libraries. The full main job runs it once (about a minute on this 2-core machine, in a process of its own:
:func:`~nlosplan.stability.run_apart`), as one more job on its executor beside the references it simulates
(:func:`run_catalog`; from this process at the end when no reference is simulated), and keeps the summary in
``$NLOSPLAN_CACHE/stability/KEY.json`` (or ``~/.cache/nlosplan/stability``), KEY the SHA-256 of
:func:`~nlosplan.planner.design.reference_cache.code_version`, the source of the catalog and runner, and the
versions of JAX, jaxlib and NumPy; a later run with the same key reports that summary, marked ``cached``.
``--no-cache`` runs it regardless. An unreadable entry is run again and replaced.
"""

from __future__ import annotations

import hashlib
import json
import time
from pathlib import Path

from nlosplan.errors import UserError
from nlosplan.files import write_json
from nlosplan.planner.design import reference_cache

__all__ = ["stability_summary", "kept_summary", "run_catalog", "keep", "catalog_key"]


def catalog_key() -> str:
    """The content key of the catalog's result (code and library versions)."""
    import jax
    import jaxlib
    import numpy

    pkg = Path(__file__).resolve().parents[2]
    h = hashlib.sha256(reference_cache.code_version().encode())
    for rel in ("stability.py", "cases.py"):
        h.update((pkg / rel).read_bytes())
    h.update(f"{jax.__version__} {jaxlib.__version__} {numpy.__version__}".encode())
    return h.hexdigest()[:32]


def _path() -> Path:
    return reference_cache.cache_dir().parent / "stability" / f"{catalog_key()}.json"


def kept_summary(quick: bool, cache: bool = True) -> dict | None:
    """The summary a run reports without running the catalog, or None when it must run.

    ``--quick`` runs do not run it (they say so); with ``cache``, an earlier run's entry for this
    :func:`catalog_key` is taken (marked ``cached``). An unreadable entry counts as none.
    """
    if quick:
        return {"ran": False, "note": "not run with --quick; run `nlosplan check`"}
    path = _path() if cache else None
    if path is not None and path.is_file():
        try:
            kept = json.loads(path.read_text())
            if {"passed", "total", "failed", "seconds"} <= set(kept):
                return {**kept, "ran": True, "cached": True}
        except (OSError, ValueError):
            pass  # unreadable: run it again and replace the entry
    return None


def run_catalog(job=None) -> dict:
    """Run the whole catalog (in a process of its own: :func:`~nlosplan.stability.run_apart`); its summary
    (module-level, so a design run's executor can run it as a job).

    Parameters
    ----------
    job : CatalogJob, optional
        Only names the work (:class:`~nlosplan.planner.design.jobs.CatalogJob`); the catalog has no inputs.

    Returns
    -------
    dict
        ``status`` (``"ok"``), ``ran``, ``passed``, ``total``, ``failed`` (case names), ``seconds``.
    """
    from nlosplan.stability import all_cases, run_apart

    t0 = time.perf_counter()
    results = run_apart(all_cases())
    return {"status": "ok", "ran": True, "passed": sum(r.passed for r in results), "total": len(results),
            "failed": [r.name for r in results if not r.passed], "seconds": time.perf_counter() - t0}


def keep(summary: dict, cache: bool = True) -> dict:
    """Put a fresh summary in the cache (with ``cache``); the report's form of it (``cached`` False)."""
    out = {k: summary[k] for k in ("ran", "passed", "total", "failed", "seconds")}
    if cache:
        try:
            write_json(_path(), out)
        except (OSError, UserError):
            pass  # a cache that cannot be written is only a lost speed-up; the summary is in this run's report
    return {**out, "cached": False}


def stability_summary(quick: bool, cache: bool = True, say=None) -> dict:
    """The catalog's summary for a design run's report (run here when no earlier one is kept).

    Parameters
    ----------
    quick : bool
        ``--quick`` runs do not run it (they say so).
    cache : bool
        Take the summary of an earlier run with the same :func:`catalog_key`, and keep a new one.
    say : callable, optional
        ``say(text)`` before the catalog runs.

    Returns
    -------
    dict
        ``ran``, ``passed``, ``total``, ``failed`` (case names), ``seconds`` (of the run that computed it) and
        ``cached`` (True when taken from an earlier run); or ``ran`` False and a ``note`` when the catalog's
        process stopped before its end (nothing is kept then: the next run tries again).
    """
    kept = kept_summary(quick, cache)
    if kept is not None:
        return kept
    if say:
        say("stability: the catalog")
    try:
        return keep(run_catalog(), cache)
    except RuntimeError as exc:  # its process died (memory, a signal): the run's results stand without it
        return {"ran": False, "note": f"did not finish: {exc}; run `nlosplan check`"}
