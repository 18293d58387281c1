"""The planner protocol: decisions as ask/tell, in one pair of words, ``suggest(n)`` and ``ingest(results)``.

Every planner of this room proposes work and learns from its results
without running anything itself (bluesky-adaptive's ask/tell, blop's
``Optimizer``):

- :class:`~nlosplan.planner.design.search.DesignSearch`: ``suggest()``
  returns evaluation jobs, ``ingest`` takes evaluation results (dicts);
- :class:`~nlosplan.planner.capture.planner.CapturePlanner`: ``suggest(n)``
  returns proposed positions (dicts with an ``id``), ``ingest`` takes capture
  results by ``id``;
- :class:`~nlosplan.planner.capture.closed_loop.ClosedLoop` (the capture
  planner on a rig): ``suggest(n)`` returns (x_mm, y_mm) in route order,
  ``ingest`` takes ``[((x_mm, y_mm), [CaptureResult, ...]), ...]``.

An empty suggestion means the planner has nothing more to propose. Failed
work is ingested like any result (with its status), so it is recorded and
not proposed again. The *executor side* runs the suggestions and feeds the
results back: :func:`nlosplan.planner.design.run.run_design` (on a process
pool or Dask), :func:`nlosplan.hardware.plans.ask_tell_plan` (on the rig, as
a plan of moves and captures; it takes the two methods as callables, so the
hardware room needs no planner type) and the studies' loops.
"""

from __future__ import annotations

from typing import Any, Protocol, Sequence, runtime_checkable

__all__ = ["AskTellPlanner"]


@runtime_checkable
class AskTellPlanner(Protocol):
    """A planner: :meth:`suggest` what to do next, :meth:`ingest` what came of it."""

    def suggest(self, n: int | None = None) -> Sequence[Any]:
        """Up to ``n`` proposals (empty: nothing more to propose)."""

    def ingest(self, results: Sequence[Any]) -> None:
        """Results of earlier proposals (failures included)."""
