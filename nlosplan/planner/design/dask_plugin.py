"""The Dask worker plugin of :class:`~nlosplan.planner.design.executors.DaskExecutor` (imported only with dask)."""

from __future__ import annotations

from distributed.diagnostics.plugin import WorkerPlugin

from nlosplan.planner.design.workers import init_worker

__all__ = ["WatchParent"]


class WatchParent(WorkerPlugin):
    """Every worker of a LocalCluster (restarts included) starts with :func:`init_worker`: it ends with ``parent``
    (and exits the ordinary way: Dask stops its workers itself).

    Parameters
    ----------
    parent : int
        Process id of the process that started the cluster (the workers' parent).
    """

    name = "nlosplan-watch-parent"

    def __init__(self, parent: int):
        self.parent = parent

    def setup(self, worker) -> None:
        init_worker(self.parent, quick_exit=False)  # Dask ends its workers itself
