"""Captures and their storage (a room above the simulators, below calibration and learning).

- :class:`Dataset` (``dataset``): histograms with labels, in memory.
- :class:`CaptureStore` (``store``, rows in ``records``): SQLite in WAL mode,
  one transaction per capture, histograms with full metadata; read-only mode.
- :func:`load_dataset` (``load``): the one loader of stored captures the
  design planner and the studies use.
- :func:`import_denali`, :func:`export_denali` (``denali_io``): DENALI's
  folder layout in and out.
- :func:`build_dataset` (``build``): a simulated dataset of the DENALI rig.

This room stores and loads; it trains nothing (that is :mod:`nlosplan.tasks`).
"""

from nlosplan.data.build import build_dataset
from nlosplan.data.dataset import LABEL_COLUMNS, SCENE_KEYS, Dataset, scene_keys
from nlosplan.data.denali_io import OBJECT_ALIASES, export_denali, import_denali, load_positions
from nlosplan.data.load import load_dataset
from nlosplan.data.records import capture_key, describe
from nlosplan.data.store import CaptureStore

__all__ = ["CaptureStore", "Dataset", "LABEL_COLUMNS", "OBJECT_ALIASES", "SCENE_KEYS", "build_dataset", "capture_key",
           "describe", "export_denali", "import_denali", "load_dataset", "load_positions", "scene_keys"]
