"""The shipped realism scores: how the calibrated presets predict real data (package data ``data/realism.json``).

Made by ``nlosplan bench real`` (its ``table2`` part on ``denali-tmf8828-3x3``;
the ``plane`` part's held-out summary on ``tmf8828-3x3-plane-unit``; its
``checkpoints`` part at the full budget) and ``nlosplan bench denali --budget
full`` (DENALI's recipe on the simulated world, one entry per seed), and
shipped so that reports can show them without rerunning a calibration or a
1.5-hour training. The layout is ``bench real``'s JSON: ``{"plane": {"sensor",
"data", "summary", "targets"}, "table2": {"sensor", "rows", "ratios", "levels",
"meets", "targets", ...}, "table1": {"sensor", "made_by", "targets", "rows":
[{"task", "model", "metric", "seeds", "predicted", "best_epoch", "real"}]},
"checkpoints": {"sensor", "made_by", "targets", "rows": [{"name", "task",
"metric", "simulated", "real", "chance"}]}, "made_by"}``; each part says how it
was made.
"""

from __future__ import annotations

import json
from importlib import resources


def shipped_realism() -> dict:
    """The shipped scores (see the module notes)."""
    return json.loads((resources.files("nlosplan.calibration") / "data" / "realism.json").read_text())
