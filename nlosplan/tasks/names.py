"""Names and defaults of the tasks room, importable without torch or scikit-learn (the CLI's parsers use them)."""

from __future__ import annotations

from nlosplan.errors import UserError

__all__ = ["MODEL_NAMES", "LEARNER_NAMES", "MODEL_LABELS", "model_phrase",
           "TASKS", "TASK_LABEL", "SPLITS", "PROFILES", "DEFAULT_EPOCHS", "DEFAULT_PATIENCE",
           "DEFAULT_WIDTH", "SMALL", "check_names"]

#: The DENALI benchmark models.
MODEL_NAMES: tuple[str, ...] = ("mlp", "cnn1d", "cnn3d", "transformer")
#: Every learner the design planner may train: the benchmark models and k nearest neighbours on principal components
#: of square-root counts (:mod:`nlosplan.tasks.neighbours`).
LEARNER_NAMES: tuple[str, ...] = MODEL_NAMES + ("knn",)
#: How reports name them, with the article a sentence needs ("met with an MLP trained on ...").
MODEL_LABELS = {"mlp": ("an", "MLP"), "cnn1d": ("a", "1D CNN"), "cnn3d": ("a", "3D CNN"),
                "transformer": ("a", "Transformer"), "knn": ("a", "k-nearest-neighbour learner")}
#: Task names: localization, 30-way shape classification, 2-way size classification.
TASKS: tuple[str, ...] = ("loc", "shape", "size")
#: Label column each classification task predicts.
TASK_LABEL = {"shape": "object", "size": "size"}
#: Train/test splits (see :mod:`nlosplan.tasks.splits`).
SPLITS: tuple[str, ...] = ("random", "positions", "objects", "sizes", "sizes:4in", "sizes:8in")
#: Training profiles (see :mod:`nlosplan.tasks.benchmark`).
PROFILES = ("cpu", "denali")
#: Default epoch cap, early-stopping patience and width (see the measured timings in nlosplan.tasks.benchmark).
DEFAULT_EPOCHS = 30
DEFAULT_PATIENCE = 5
DEFAULT_WIDTH = 0.25
#: Settings of the "small" run CI can afford (a few minutes on 2 CPU cores at DENALI's size).
SMALL = {"epochs": 5, "width": 0.125}


def model_phrase(name: str) -> str:
    """``"an MLP"``, ``"a 1D CNN"``: a model as a sentence names it (an unknown name as it is, with "a")."""
    article, label = MODEL_LABELS.get(name, ("a", name))
    return f"{article} {label}"


def check_names(kind: str, given, allowed) -> list[str]:
    """``given`` (a name or names) checked against ``allowed``, duplicates dropped; a UserError names the bad ones."""
    given = [given] if isinstance(given, str) else list(given)
    bad = [g for g in given if g not in allowed]
    if bad or not given:
        raise UserError(f"unknown {kind} {', '.join(map(repr, bad)) or '(none given)'}; allowed: {', '.join(allowed)}")
    return list(dict.fromkeys(given))
