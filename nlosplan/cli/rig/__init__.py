"""``nlosplan rig``: drive the capture rig (or its pty emulators).

- :mod:`.capture`: ``rig capture``, ``rig dry-run``, ``rig status`` (and the
  port, plan, motion and mode options they share);
- :mod:`.run`: ``rig run``, the capture planner in closed loop with the rig.
"""

from __future__ import annotations

from nlosplan.cli.rig import capture, run

__all__ = ["add"]


def add(sub) -> None:
    """The ``rig`` subcommand: ``capture``, ``dry-run``, ``status``, ``run``."""
    rsub = capture.add(sub)
    run.add_rig(rsub)
