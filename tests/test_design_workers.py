"""Design worker processes: one thread each for numpy's BLAS and torch (the pool is the parallelism)."""

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


def test_recycled_workers_are_fresh_processes():
    pool = PoolExecutor(2)
    try:
        before = {res for _, res in pool.map(_pid, [_Probe()] * 6)}
        pool.recycle()
        after = {res for _, res in pool.map(_pid, [_Probe()] * 6)}
        assert after and before.isdisjoint(after)
        assert {res["torch"] for _, res in pool.map(_threads, [_Probe()])} == {1}  # still set up as workers
    finally:
        pool.close()


def test_a_simulation_stage_that_ran_recycles_the_workers_and_drops_compiled_programs(tmp_path, monkeypatch):
    import jax

    from nlosplan.planner.design import run
    from nlosplan.planner.design.data import SceneSet
    from nlosplan.planner.design.executors import SerialExecutor
    from nlosplan.planner.design.jobs import ReferenceJob
    from nlosplan.sensor_models.presets import preset

    class Recorded(SerialExecutor):
        recycled = 0

        def recycle(self):
            self.recycled += 1

    cleared = []
    monkeypatch.setattr(jax, "clear_caches", lambda: cleared.append(1))
    monkeypatch.setattr(run, "build_reference", lambda job: {"status": "ok", "seconds": 1.0})
    scenes = SceneSet(objects=("A",), positions=(0,), repeats=1, crlb_objects=(), fidelity="draft")
    jobs = [ReferenceJob(str(tmp_path / f"{r}x{r}.npz"), preset("tmf8828-3x3-short").replace(zones_rows=r, zones_cols=r),
                         scenes, f"{r}x{r}") for r in (1, 3)]
    ex = Recorded()
    assert run._simulate(ex, jobs, lambda *a: None, "references", cache=False)[0] == {"3x3": 1.0, "1x1": 1.0}
    assert ex.recycled == 1 and len(cleared) == 2  # once per stage; every job's programs dropped after it
    # nothing to simulate: the workers are kept
    assert run._simulate(ex, [], lambda *a: None, "references", cache=False) == ({}, None)
    assert ex.recycled == 1
    # a failing job drops its programs too
    def boom(job):
        raise RuntimeError("boom")

    monkeypatch.setattr(run, "build_reference", boom)
    with pytest.raises(RuntimeError, match="boom"):
        run._prepare(jobs[0])
    assert len(cleared) == 3
