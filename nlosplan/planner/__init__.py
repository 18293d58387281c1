"""Planners: the sensor-design search (:mod:`.design`) and capture planning (:mod:`.capture`).

Both speak one ask/tell protocol, :class:`~nlosplan.planner.protocol.AskTellPlanner`
(``suggest(n)`` / ``ingest(results)``); executors run what they suggest.
"""

from nlosplan.planner.protocol import AskTellPlanner

__all__ = ["AskTellPlanner"]
