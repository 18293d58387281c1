"""NLOS tasks: learning and bounds.

- Models (``models``), training (``training``, its types in
  ``training_types``, checkpoints in ``checkpoints``), splits (``splits``),
  the one scoring module with DENALI's metrics (``metrics``) and the
  benchmark runner (``benchmark``).
- Bounds: Fisher information and the localization CRLB (``fisher``,
  ``bounds``), the ideal observer (``ideal_observer``).
- ``names``: model, task and split names and training defaults, importable
  without torch or scikit-learn (the CLI's parsers use them).

The face exports only the light names: the modules that need torch or
scikit-learn are imported by their path where they are used, so that
``nlosplan --help`` does not load them. Captures and their storage are the
:mod:`nlosplan.data` room's.
"""

from nlosplan.tasks.names import (DEFAULT_EPOCHS, DEFAULT_PATIENCE, DEFAULT_WIDTH, MODEL_NAMES, PROFILES, SMALL,
                                  SPLITS, TASK_LABEL, TASKS, check_names)

__all__ = ["DEFAULT_EPOCHS", "DEFAULT_PATIENCE", "DEFAULT_WIDTH", "MODEL_NAMES", "PROFILES", "SMALL", "SPLITS",
           "TASKS", "TASK_LABEL", "check_names"]
