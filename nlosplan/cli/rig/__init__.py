"""``nlosplan rig``: drive the capture rig (or its pty emulators).

- :mod:`.capture`: ``rig capture`` (and the port, plan, motion and mode
  options the rig commands share);
- :mod:`.dry_run`: ``rig dry-run``; :mod:`.status`: ``rig status``;
- :mod:`.run`: ``rig run``, the capture planner in closed loop with the rig;
- :mod:`.origin`: the origin check before a session moves (``--origin-confirmed``).
"""

from __future__ import annotations

from nlosplan.cli.rig import capture, dry_run, run, status

__all__ = ["add"]


def add(sub) -> None:
    """The ``rig`` subcommand: ``capture``, ``dry-run``, ``status``, ``run``."""
    rsub = capture.add(sub)
    dry_run.add_rig(rsub)
    status.add_rig(rsub)
    run.add_rig(rsub)
