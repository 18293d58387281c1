"""The design search's knobs (:class:`SearchConfig`) and the constants of its seeds and learners."""

from __future__ import annotations

from dataclasses import dataclass, field

from nlosplan.errors import UserError
from nlosplan.planner.design.budget import TRAIN_CAPTURES, check_captures_value
from nlosplan.planner.design.evaluation import Evaluator
from nlosplan.planner.design.evaluators import DEFAULT_FIDELITY
from nlosplan.resources import MAX_DESIGN_SEED as MAX_SEED

__all__ = ["SearchConfig", "MAX_SEED", "SEED_STRIDE", "DEFAULT_MODELS"]

#: Evaluation seeds are ``seed * SEED_STRIDE + i`` (``i < SEED_STRIDE // 10``); the run's seed is at most
#: ``MAX_SEED`` (:data:`nlosplan.resources.MAX_DESIGN_SEED`, defined once there), so they stay below 2**32.
SEED_STRIDE = 1000
#: Candidate learners of the trained evaluator (the best per task is used): DENALI's MLP and 1D CNN cells as the
#: benchmark trains them, and k nearest neighbours on principal components of square-root counts
#: (:mod:`nlosplan.tasks.neighbours`).
DEFAULT_MODELS = ("mlp", "cnn1d", "knn")


@dataclass(frozen=True)
class SearchConfig:
    """Knobs of the search.

    Parameters
    ----------
    grid_points : int
        Points of each continuous axis grid (and of the bins grid).
    refine_steps : int
        Bisection steps after the grid.
    seeds : int
        Seeds of the verification (and of the learners on the reference design).
    candidates : int
        Cheapest candidates verified per task (optimized, and as many scanned).
    optimize_evals : int
        COBYLA evaluations per discrete choice.
    fidelity : dict
        Knobs per evaluator (see :data:`~nlosplan.planner.design.evaluators.DEFAULT_FIDELITY`).
    seed : int
        The run's seed, 0 to :data:`MAX_SEED` (``--seed``).
    models : tuple of str
        Candidate learners (:data:`~nlosplan.tasks.names.LEARNER_NAMES`); the best on the reference design
        is used per task.
    max_seeds : int
        Most seeds of one design (and of one design in one world) while it is undecided.
    budget : int
        Extra evaluations the run may spend deciding undecided candidates (decide and worlds stages).
    curve_seeds : int
        Seeds of each point of the learner's learning curve at the reference design, up to DENALI's 25,200
        training captures (:mod:`~nlosplan.planner.design.learning_curve`); 0: no curve (the main job 2,
        ``--quick`` 1).
    """

    grid_points: int = 6
    refine_steps: int = 2
    seeds: int = 3
    candidates: int = 2
    optimize_evals: int = 15
    fidelity: dict = field(default_factory=lambda: {k: dict(v) for k, v in DEFAULT_FIDELITY.items()})
    seed: int = 0
    models: tuple = DEFAULT_MODELS
    max_seeds: int = 8
    budget: int = 30
    curve_seeds: int = 0

    def __post_init__(self) -> None:
        from nlosplan.tasks.names import LEARNER_NAMES, check_names

        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or not 0 <= self.seed <= MAX_SEED:
            raise UserError(f"seed={self.seed!r} must be a whole number from 0 to {MAX_SEED}")
        for name, lo in (("grid_points", 2), ("refine_steps", 0), ("seeds", 1), ("candidates", 1),
                         ("optimize_evals", 1), ("budget", 0), ("curve_seeds", 0)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < lo:
                raise UserError(f"[search] {name}={v!r} must be a whole number >= {lo}")
        if isinstance(self.max_seeds, bool) or not isinstance(self.max_seeds, int) or not \
                self.seeds <= self.max_seeds <= SEED_STRIDE // 10:
            raise UserError(f"[search] max_seeds={self.max_seeds!r} must be a whole number from seeds "
                            f"({self.seeds}) to {SEED_STRIDE // 10}")
        budget = self.fidelity.get(Evaluator.TRAINED.knobs, {}).get(TRAIN_CAPTURES)
        if budget is not None:
            check_captures_value(budget, f"[search.fidelity.trained] {TRAIN_CAPTURES}")
        models = (self.models,) if isinstance(self.models, str) else tuple(self.models)
        object.__setattr__(self, "models", tuple(check_names("model(s)", models, LEARNER_NAMES)))

    def seed_of(self, i: int) -> int:
        """The evaluation seed of a design's ``i``-th run."""
        return self.seed * SEED_STRIDE + int(i)

    def to_dict(self) -> dict:
        return {k: list(v) if isinstance(v, tuple) else v for k, v in self.__dict__.items()}
