"""Start-up of a design worker process: one thread per worker, and an end with the process that started it; the
compiled programs a process holds between preparation jobs."""

from __future__ import annotations

import contextlib
import os
import sys

from nlosplan.resources import THREADS_ENV, end_with_parent, keep_freed_memory

__all__ = ["init_worker", "hold_programs", "release_programs"]


#: The zone layout the compiled programs this process holds were compiled for (the catalog runs apart), or None.
_held: str | None = None


def release_programs() -> None:
    """Drop the compiled programs this process holds (they stay in the on-disk compilation cache)."""
    import gc

    import jax

    global _held
    jax.clear_caches()
    gc.collect()
    _held = None


def hold_programs(key: str) -> None:
    """Before a job that compiles the programs ``key`` names: keep the programs held when they are those, else
    drop them (a worker holds one layout's programs at a time: the 8x8 reference's are 2.5-2.9 GB)."""
    global _held
    if _held not in (None, key):
        release_programs()
    _held = key


def _leave() -> None:
    """A worker's last act once its pool stopped it: flush and end without the interpreter's teardown."""
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(OSError, ValueError, AttributeError):  # closed or replaced: nothing to flush
            stream.flush()
    os._exit(0)


def init_worker(parent: int | None = None, quick_exit: bool = True) -> None:
    """Worker start-up: one thread per worker (the pool provides the parallelism); end with ``parent``.

    Also keeps freed memory for reuse (:func:`~nlosplan.resources.keep_freed_memory`): half the page
    faults, and 9-18 % less time in the ideal observer's evaluations. A worker its pool stops ends at once
    (:func:`_leave`, the last of multiprocessing's exit finalizers, before JAX's and torch's exit handlers and
    the teardown of every module: 0.9-2 s of a core a worker, each time a pool is recycled or closed); every
    result it made was sent before, and what it wrote was written atomically. ``quick_exit=False`` (a Dask
    worker, which ends on its own terms) keeps the ordinary exit.
    """
    if parent is not None:
        end_with_parent(parent)
    if quick_exit:
        from multiprocessing import util

        util.Finalize(None, _leave, exitpriority=-(2**30))
    keep_freed_memory()
    # torch takes its thread count from this when it is imported: a worker that only simulates (the
    # references) never imports it (1-2 s and ~200 MB a process), one that trains gets one thread
    os.environ["OMP_NUM_THREADS"] = "1"
    os.environ.setdefault(THREADS_ENV, "1")  # the fast simulator's chunks one after the other
    # numpy's BLAS started its threads (one per core) when numpy was imported, before this runs: the variable
    # above comes too late for it, and two workers' matrix products (the ideal observer's) ran four threads
    # on two cores
    from threadpoolctl import threadpool_limits

    threadpool_limits(1)
    torch = sys.modules.get("torch")
    if torch is not None:  # imported before this ran (a Dask worker): its pool is already sized
        torch.set_num_threads(1)
