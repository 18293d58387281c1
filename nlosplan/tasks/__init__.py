"""NLOS tasks: datasets and their storage, models, metrics, and fast evaluators.

- :class:`Dataset` (``dataset``): histograms with labels, in memory.
"""

from nlosplan.tasks.dataset import LABEL_COLUMNS, SCENE_KEYS, Dataset

__all__ = ["Dataset", "LABEL_COLUMNS", "SCENE_KEYS"]
