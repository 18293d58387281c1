"""Design worker processes: one thread each for numpy's BLAS and torch (the pool is the parallelism)."""

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
