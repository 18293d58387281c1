"""Where evaluations run: this process, a local process pool, or a Dask cluster.

Every executor takes picklable jobs (:mod:`~nlosplan.planner.design.jobs`)
and a module-level function and yields ``(job, result)`` as results arrive,
so the search does not care where they ran. A job that raises is yielded
with an ``{"status": "failed"}`` result; it never stops the others. With
``ahead=n``, ``map`` takes the next job from ``jobs`` (an iterator may be
lazy) only while fewer than ``n`` are running or waiting to be yielded, so a
job stream can look at the results so far before it offers its next job
(the optimize stage's branch and bound).

``--cluster tcp://HOST:PORT`` connects to a running Dask scheduler (its
workers must see the run's output folder, where the reference data lies);
``--cluster local:N`` starts a Dask ``LocalCluster`` with N single-threaded
worker processes on this machine.
"""

from __future__ import annotations

import multiprocessing
import os
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from typing import Any, Callable, Iterable, Iterator

from nlosplan.errors import UserError
from nlosplan.planner.design.workers import init_worker, release_programs

__all__ = ["make_executor", "init_worker", "SerialExecutor", "PoolExecutor", "DaskExecutor"]


_END = object()  # the end of a job stream


def _offer(source, ahead: int | None, out, start) -> None:
    """Start jobs taken from the iterator ``source`` while ``out()`` (jobs running or not yet yielded) is under
    ``ahead`` (None: all of them)."""
    while ahead is None or out() < ahead:
        job = next(source, _END)
        if job is _END:
            return
        start(job)


def _failed(job, exc: BaseException) -> dict:
    """The result record of a job that raised (the job's fields, ``status`` and ``reason``)."""
    return {**job.to_dict(), "status": "failed", "reason": f"{type(exc).__name__}: {exc}"}


def _resident_bytes(pid: int) -> int | None:
    """Resident memory of a process, bytes (``/proc/PID/statm``), or None where it cannot be read."""
    try:
        with open(f"/proc/{pid}/statm") as fh:
            return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):
        return None


class SerialExecutor:
    """Run jobs one after another in this process."""

    name = "serial"
    workers = 1

    def map(self, fn: Callable[[Any], dict], jobs: Iterable[Any], ahead: int | None = None
            ) -> Iterator[tuple[Any, dict]]:
        for job in jobs:  # one at a time: every job is offered after the results before it
            try:
                yield job, fn(job)
            except Exception as exc:  # noqa: BLE001 -- recorded, not fatal
                yield job, _failed(job, exc)

    def recycle(self, above_bytes: int = 0) -> bool:
        """Drop the compiled programs this process holds (the jobs ran here); True."""
        release_programs()
        return True

    def close(self) -> None:
        """Nothing to release: jobs ran in this process."""


class PoolExecutor:
    """A local process pool (``spawn``: safe with JAX and torch in the parent)."""

    name = "local pool"

    def __init__(self, workers: int):
        self.workers = int(workers)
        self._pool = ProcessPoolExecutor(self.workers, mp_context=multiprocessing.get_context("spawn"),
                                         initializer=init_worker, initargs=(os.getpid(),))

    def map(self, fn, jobs, ahead: int | None = None):
        source, futures, pending = iter(jobs), {}, set()

        def start(job) -> None:
            f = self._pool.submit(fn, job)
            futures[f] = job
            pending.add(f)

        _offer(source, ahead, lambda: len(pending), start)
        while pending:
            done, pending = wait(pending, return_when=FIRST_COMPLETED)
            for f in done:
                job = futures.pop(f)
                exc = f.exception()
                yield job, (_failed(job, exc) if exc else f.result())
            _offer(source, ahead, lambda: len(pending), start)

    def recycle(self, above_bytes: int = 0) -> bool:
        """Replace the workers by fresh ones when one of them holds more than ``above_bytes`` of memory.

        After the simulation stages: what a worker compiled and cached for a reference -- 2.5-2.9 GB for the 8x8
        one -- is not carried into the evaluations. A fresh worker imports JAX, torch,
        scikit-learn and the simulators again (2-4 s of a core each), so workers that stayed small (a round of
        1x1 and 3x3 world references: 0.6-1.3 GB) are kept. Returns whether they were replaced; where a
        worker's memory cannot be read they are.
        """
        sizes = [_resident_bytes(pid) for pid in list(self._pool._processes or {})]
        if above_bytes > 0 and sizes and all(b is not None and b <= above_bytes for b in sizes):
            return False
        # not waiting: the old workers end (freeing their gigabytes: 1-1.5 s) while the new ones start
        self._pool.shutdown(wait=False)
        self._pool = ProcessPoolExecutor(self.workers, mp_context=multiprocessing.get_context("spawn"),
                                         initializer=init_worker, initargs=(os.getpid(),))
        return True

    def close(self) -> None:
        """Stop the workers without waiting for them to end (they free their memory while the caller goes on, e.g.
        writes the report: 1.5 s of a `--quick` run); the interpreter's exit still waits for them."""
        self._pool.shutdown(wait=False, cancel_futures=True)


class DaskExecutor:
    """A Dask distributed cluster: an existing scheduler or a LocalCluster started here."""

    def __init__(self, address: str):
        try:
            from dask.distributed import Client, LocalCluster
        except ImportError as exc:  # pragma: no cover - dask is a dependency
            raise UserError(f"--cluster needs dask[distributed]: {exc}") from None
        self._cluster = None
        if address.startswith("local:"):
            try:
                n = int(address.split(":", 1)[1])
            except ValueError:
                raise UserError(f"--cluster {address}: give local:N with N workers, e.g. local:2") from None
            if n < 1:
                raise UserError(f"--cluster {address}: N must be >= 1")
            self._cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                         dashboard_address=None, host="127.0.0.1")
            self._client = Client(self._cluster)
            from nlosplan.planner.design.dask_plugin import WatchParent

            # the workers are this process's children: they end with it, even on kill -9
            self._client.register_plugin(WatchParent(os.getpid()))
            self.workers = n
            self.name = f"dask LocalCluster ({n} workers)"
        elif address.startswith("tcp://"):
            try:
                self._client = Client(address, timeout="5s")
            except (OSError, TimeoutError) as exc:
                raise UserError(f"cannot reach the Dask scheduler at {address}: {exc}") from None
            self.workers = max(1, len(self._client.scheduler_info().get("workers", {})))
            self.name = f"dask {address} ({self.workers} workers)"
        else:
            raise UserError(f"--cluster {address!r}: give tcp://HOST:PORT or local:N")
        self._client.run(init_worker)

    def map(self, fn, jobs, ahead: int | None = None):
        from dask.distributed import as_completed

        source, index, queue = iter(jobs), {}, as_completed([])

        def start(job) -> None:
            f = self._client.submit(fn, job, pure=False)
            index[f.key] = job
            queue.add(f)

        _offer(source, ahead, queue.count, start)
        for f in queue:
            job = index.pop(f.key)
            try:
                yield job, f.result()
            except Exception as exc:  # noqa: BLE001 -- recorded, not fatal
                yield job, _failed(job, exc)
            _offer(source, ahead, queue.count, start)

    def recycle(self, above_bytes: int = 0) -> bool:
        """Every worker drops the compiled programs it holds; True."""
        self._client.run(release_programs)
        return True

    def close(self) -> None:
        self._client.close()
        if self._cluster is not None:
            self._cluster.close()


def make_executor(workers: int | None = None, cluster: str | None = None):
    """The executor for ``--workers`` / ``--cluster`` (default: a pool of the CPU count, serial for 1)."""
    if cluster:
        return DaskExecutor(cluster)
    n = (os.cpu_count() or 1) if workers is None else int(workers)
    if n < 1:
        raise UserError(f"--workers {n} must be >= 1")
    return SerialExecutor() if n == 1 else PoolExecutor(n)
