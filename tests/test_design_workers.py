"""Design worker processes: one thread each for numpy's BLAS and torch (the pool is the parallelism)."""

import os

import pytest
from threadpoolctl import threadpool_info

from nlosplan.planner.design.executors import PoolExecutor


class _Probe:
    def to_dict(self) -> dict:
        return {}


def _threads(job) -> dict:
    import numpy as np
    import torch

    np.ones((64, 64)) @ np.ones((64, 64))  # BLAS loaded and used
    blas = [d["num_threads"] for d in threadpool_info() if d["user_api"] == "blas"]
    return {"blas": blas, "torch": torch.get_num_threads()}


def test_each_worker_runs_one_blas_and_one_torch_thread():
    pool = PoolExecutor(2)
    try:
        results = [res for _, res in pool.map(_threads, [_Probe(), _Probe()])]
    finally:
        pool.close()
    assert len(results) == 2
    for res in results:
        assert res["blas"] and set(res["blas"]) == {1} and res["torch"] == 1, res


def _pid(job) -> int:
    import os

    return os.getpid()


def _square(job) -> int:
    return job * job


@pytest.mark.parametrize("ahead", [1, 2])
def test_a_pool_takes_the_next_job_only_when_fewer_than_ahead_are_out(ahead):
    pool = PoolExecutor(2)
    taken, yielded = [], []

    def jobs():
        for j in range(6):
            taken.append(j)
            assert len(taken) - len(yielded) <= ahead  # never more than `ahead` out at once
            yield j

    try:
        for job, res in pool.map(_square, jobs(), ahead=ahead):
            yielded.append(job)
            assert res == job * job
    finally:
        pool.close()
    assert sorted(yielded) == list(range(6)) and taken == list(range(6))


def test_recycled_workers_are_fresh_processes():
    pool = PoolExecutor(2)
    try:
        before = {res for _, res in pool.map(_pid, [_Probe()] * 6)}
        assert pool.recycle(10**12) is False  # none holds a terabyte: kept
        kept = {res for _, res in pool.map(_pid, [_Probe()] * 6)}
        assert kept <= before
        assert pool.recycle(1) is True  # every worker holds more than a byte: replaced
        after = {res for _, res in pool.map(_pid, [_Probe()] * 6)}
        assert after and before.isdisjoint(after)
        assert {res["torch"] for _, res in pool.map(_threads, [_Probe()])} == {1}  # still set up as workers
    finally:
        pool.close()


def test_a_simulation_stage_that_ran_recycles_the_workers_and_drops_compiled_programs(tmp_path, monkeypatch):
    import jax

    from nlosplan.planner.design import run, workers
    from nlosplan.planner.design.data import SceneSet
    from nlosplan.planner.design.executors import SerialExecutor
    from nlosplan.planner.design.jobs import CatalogJob, ReferenceJob
    from nlosplan.sensor_models.presets import preset

    class Recorded(SerialExecutor):
        recycled = 0

        def recycle(self, above_bytes=0):
            assert above_bytes == run.RECYCLE_ABOVE_BYTES
            self.recycled += 1
            return True

    cleared, held = [], []
    monkeypatch.setattr(jax, "clear_caches", lambda: cleared.append(1))
    monkeypatch.setattr(workers, "_held", None)

    def built(job):
        held.append((workers._held, len(cleared)))
        return {"status": "ok", "seconds": 1.0}

    monkeypatch.setattr(run, "build_reference", built)
    scenes = SceneSet(objects=("A",), positions=(0,), repeats=1, crlb_objects=(), fidelity="draft")
    sensor = preset("tmf8828-3x3-short")
    jobs = [ReferenceJob(str(tmp_path / f"w{w}_{r}x{r}.npz"), sensor.replace(zones_rows=r, zones_cols=r), scenes,
                         f"world {w}, {r}x{r}") for r in (3, 1) for w in (1, 2, 3)]
    ex = Recorded()
    assert run._simulate(ex, jobs, lambda *a: None, "references", cache=False)[0] == {j.label: 1.0 for j in jobs}
    # the worlds of one layout share the programs; they are dropped before the next layout's first world
    assert held == [("3x3", 0), ("3x3", 0), ("3x3", 0), ("1x1", 1), ("1x1", 1), ("1x1", 1)]
    assert ex.recycled == 1  # once per stage that ran
    # nothing to simulate: the workers are kept
    assert run._simulate(ex, [], lambda *a: None, "references", cache=False) == ({}, None)
    assert ex.recycled == 1
    # the catalog runs in a process of its own: what this one holds stays; recycling drops it
    monkeypatch.setattr(run, "run_catalog", lambda job: held.append((workers._held, len(cleared))) or {})
    run._prepare(CatalogJob())
    assert held[-1] == ("1x1", 1)
    SerialExecutor().recycle()
    assert len(cleared) == 2 and workers._held is None
    # a failing job leaves its programs held until the next layout's job drops them
    def boom(job):
        raise RuntimeError("boom")

    monkeypatch.setattr(run, "build_reference", boom)
    with pytest.raises(RuntimeError, match="boom"):
        run._prepare(jobs[0])
    assert workers._held == "3x3"
    monkeypatch.setattr(run, "build_reference", built)
    run._prepare(jobs[-1])
    assert held[-1] == ("1x1", 3)


def _in_one_worker(fn) -> dict:
    """``fn``'s result from a fresh design worker (a pool of one, closed after)."""
    pool = PoolExecutor(1)
    try:
        (_, res), = list(pool.map(fn, [_Probe()]))
    finally:
        pool.close()
    return res


def _faults_of(round_, warm: int, rounds: int) -> dict:
    """Minor page faults per call of ``round_`` (after ``warm`` calls), in this process."""
    import resource

    for _ in range(warm):
        round_()
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    for _ in range(rounds):
        round_()
    return {"faults": (resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before) / rounds}


def _faults_per_round(job) -> dict:
    """Minor page faults of allocating and freeing four 1 MiB arrays, per round (after a warm-up)."""
    import numpy as np

    def round_():
        arrays = [np.ones(1 << 18, np.float32) for _ in range(4)]  # 1 MiB each: above glibc's default mmap threshold
        return sum(float(a[-1]) for a in arrays)

    return _faults_of(round_, 5, 50)


def test_workers_reuse_freed_memory_instead_of_faulting_it_in_again():
    # glibc hands a freed 1 MiB block back to the kernel and faults 256 fresh pages in for the next one; a design
    # worker keeps it (nlosplan.resources.keep_freed_memory): the ideal observer's blocks cost no page faults again
    res = _in_one_worker(_faults_per_round)
    assert res["faults"] < 20, res


def test_without_keeping_freed_memory_the_same_loop_faults_every_page(monkeypatch):
    # the control: the measurement above can fail (NLOSPLAN_KEEP_FREED_MEMORY=0 leaves glibc's defaults)
    monkeypatch.setenv("NLOSPLAN_KEEP_FREED_MEMORY", "0")
    res = _in_one_worker(_faults_per_round)
    assert res["faults"] > 4 * 200, res  # four arrays of 256 pages each, nearly every page again


def test_keep_freed_memory_reports_whether_it_is_in_force(monkeypatch):
    import subprocess
    import sys

    # and numpy stops advising huge pages for its arrays where the allocator keeps what it frees
    code = ("import numpy as np; from nlosplan.resources import keep_freed_memory as k; "
            "print(k(), k(), np._core.multiarray._get_madvise_hugepage())")
    on = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    monkeypatch.setenv("NLOSPLAN_KEEP_FREED_MEMORY", "0")
    off = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    assert on == ["True", "True", "False"] and off == ["False", "False", "True"]


def _big_block_faults(job) -> dict:
    """Page faults of one round that allocates, fills and frees a 200 MB block (an 8x8 evaluation's array)."""
    import numpy as np

    def round_():
        a = np.empty(25_000_000)
        a.fill(1.0)
        return float(a[-1])

    return _faults_of(round_, 1, 3)


def test_workers_reuse_a_freed_200_mb_block_too():
    # above glibc's largest automatic mmap threshold (32 MiB): without the design workers' limits every round maps
    # and faults in 48,828 fresh 4 KiB pages (or at least ~95 huge pages, each zeroed and maybe compacted first)
    assert _in_one_worker(_big_block_faults)["faults"] < 20


def _torch_state(job) -> dict:
    import sys

    imported = "torch" in sys.modules
    import torch

    return {"imported_at_start": imported, "torch": torch.get_num_threads()}


def test_workers_import_torch_only_when_a_job_does_and_then_with_one_thread(monkeypatch):
    # a worker that only simulates (the references) does not pay torch's import; one that trains gets one
    # thread even when the parent's environment asks for more
    monkeypatch.setenv("OMP_NUM_THREADS", "4")
    res = _in_one_worker(_torch_state)
    assert res == {"imported_at_start": False, "torch": 1}


def test_resident_memory_of_a_process_is_read_from_proc():
    # a fresh process that holds 200 MB it touched, beside one that holds nearly nothing (this process's own heap
    # reuses what it freed, so its size says little)
    import subprocess
    import sys

    from nlosplan.planner.design.executors import _resident_bytes

    code = "import sys; b = b'x' * 200_000_000; print('ready', flush=True); sys.stdin.read()"  # every byte written
    big = subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    small = subprocess.Popen([sys.executable, "-c", code.replace("200_000_000", "1")], stdin=subprocess.PIPE,
                             stdout=subprocess.PIPE, text=True)
    try:
        assert big.stdout.readline().strip() == "ready" and small.stdout.readline().strip() == "ready"
        held, bare = _resident_bytes(big.pid), _resident_bytes(small.pid)
        assert bare is not None and held >= bare + 190_000_000
    finally:
        for proc in (big, small):
            proc.communicate("")
    assert _resident_bytes(2**22 + 12345) is None  # no such process


def test_without_keeping_freed_memory_a_200_mb_block_faults_in_again(monkeypatch):
    # the control of the test above (284 faults a round here with transparent huge pages on request, ~48,800 with none)
    monkeypatch.setenv("NLOSPLAN_KEEP_FREED_MEMORY", "0")
    assert _in_one_worker(_big_block_faults)["faults"] > 50  # at least ~95 huge pages


def _ended(pid: int) -> bool:
    """Whether process ``pid`` has ended (gone, or a zombie not yet reaped)."""
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().rsplit(")", 1)[1].split()[0] in ("Z", "X")
    except FileNotFoundError:
        return True


def test_closed_and_recycled_pools_end_their_workers_without_being_waited_for():
    import time

    pool = PoolExecutor(2)
    first = {res for _, res in pool.map(_pid, [_Probe()] * 4)}
    assert pool.recycle(1) is True
    second = {res for _, res in pool.map(_pid, [_Probe()] * 4)}
    pool.close()
    deadline = time.monotonic() + 20
    while not all(_ended(p) for p in first | second) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert all(_ended(p) for p in first | second), "workers still running 20 s after close"


def _nap(job) -> int:
    import os
    import time

    time.sleep(job)
    return os.getpid()


def test_close_does_not_wait_for_a_worker_still_busy():
    import time

    pool = PoolExecutor(2)
    results = pool.map(_nap, [0.0, 3.0], ahead=2)
    next(results)  # the short job's; the long one is running
    t0 = time.perf_counter()
    pool.close()
    assert time.perf_counter() - t0 < 1.5  # waiting would take the long job's remaining ~3 s


def _slow_teardown(job) -> int:
    import atexit
    import os
    import time

    atexit.register(time.sleep, 5.0)  # as a library's exit handler or the modules' teardown could take
    return os.getpid()


def test_a_stopped_worker_ends_without_the_interpreters_teardown():
    import time

    pool = PoolExecutor(1)
    (_, pid), = list(pool.map(_slow_teardown, [_Probe()]))
    t0 = time.perf_counter()
    pool.close()
    while not _ended(pid) and time.perf_counter() - t0 < 10:
        time.sleep(0.02)
    assert _ended(pid) and time.perf_counter() - t0 < 3.0  # the 5 s exit handler never ran
