"""The design search's units of work, typed and picklable: one evaluation, one optimize run.

A job is what the search suggests and an executor (this process, a local
process pool, Dask workers) hands to a module-level function
(:func:`~nlosplan.planner.design.evaluators.evaluate`,
:func:`~nlosplan.planner.design.optimize.optimize_choice`). Jobs are frozen
dataclasses of plain values, enums, a :class:`~nlosplan.planner.design.space.Design`
and a :class:`~nlosplan.planner.design.requirements.Condition`, so they
pickle to any worker; a result travels back as a plain dict (it is logged as
a JSON line and read back on resume) and is typed once, when the search
ingests it (:class:`~nlosplan.planner.design.evaluation.Evaluation`).
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path

from nlosplan.planner.design.cost import CostModel
from nlosplan.planner.design.data import SceneSet
from nlosplan.planner.design.evaluation import Evaluator
from nlosplan.planner.design.requirements import Condition, Requirement, Task
from nlosplan.planner.design.space import Design, DesignSpace
from nlosplan.sensor_models import SensorConfig

__all__ = ["DesignJob", "OptimizeJob", "ReferenceJob", "CatalogJob"]


@dataclass(frozen=True)
class DesignJob:
    """One evaluation of one design on one task.

    Parameters
    ----------
    evaluator : Evaluator or its name
        Kept as an :class:`~nlosplan.planner.design.evaluation.Evaluator`.
    task : Task or its name
        Kept as a :class:`~nlosplan.planner.design.requirements.Task`.
    design : Design
    seed : int
    fidelity : dict
        The evaluator's knobs (see :data:`~nlosplan.planner.design.evaluators.DEFAULT_FIDELITY`).
    condition : Condition or None
        The rows the metric is computed on.
    reference : str
        Path of the saved :class:`~nlosplan.planner.design.data.ReferenceData` of the design's zone layout.
    reference_sensor : dict
        The space's reference sensor (:meth:`SensorConfig.to_dict`).
    world : dict, optional
        A world's sensor overrides (:func:`~nlosplan.planner.design.worlds.world_sensor`; the reference
        file is that world's); None in the nominal model.
    """

    evaluator: Evaluator
    task: Task
    design: Design
    seed: int
    fidelity: dict
    condition: Condition | None
    reference: str
    reference_sensor: dict
    world: dict | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "evaluator", Evaluator(self.evaluator))
        object.__setattr__(self, "task", Task(self.task))

    @property
    def key(self) -> str:
        """A stable id of the evaluation (what resume looks up); the reference by file name, so a moved OUT resumes."""
        fields = {"evaluator": self.evaluator, "task": self.task, "design": self.design.to_dict(), "seed": self.seed,
                  "fidelity": self.fidelity, "condition": None if self.condition is None else str(self.condition),
                  "reference": Path(self.reference).name}  # names carry the content hash
        if self.world is not None:  # nominal jobs keep the key they always had
            fields["world"] = self.world
        return hashlib.sha1(json.dumps(fields, sort_keys=True, default=str).encode()).hexdigest()[:16]

    def to_dict(self) -> dict:
        """The job as a result record carries it: plain values, the condition as ``col=value``, and ``key``."""
        return {"evaluator": self.evaluator, "task": self.task, "design": self.design.to_dict(), "seed": self.seed,
                "fidelity": self.fidelity, "condition": None if self.condition is None else str(self.condition),
                "reference": self.reference, "reference_sensor": self.reference_sensor, "world": self.world,
                "key": self.key}


@dataclass(frozen=True)
class OptimizeJob:
    """One optimize run: the cheapest design of one discrete choice (zones, bin width) for one requirement.

    Parameters
    ----------
    requirement : Requirement
    gap : float
        The measured bound-to-trained gap of the requirement's task (score units).
    space : DesignSpace
        With its reference sensor.
    cost : CostModel
    base : Design
        The choice's costliest design (its zones and bin width fixed).
    max_evals : int
        COBYLA evaluations.
    fidelity : dict
        The bound evaluator's knobs.
    reference : str
        As :class:`DesignJob`.
    reference_sensor : dict
    """

    requirement: Requirement
    gap: float
    space: DesignSpace
    cost: CostModel
    base: Design
    max_evals: int
    fidelity: dict
    reference: str
    reference_sensor: dict

    def to_dict(self) -> dict:
        """The job as plain data (what a failed run's record carries)."""
        return {"requirement": self.requirement.to_dict(), "gap": self.gap, "space": self.space.to_dict(),
                "space_reference": self.space.sensor.to_dict(), "cost": self.cost.to_dict(),
                "base": self.base.to_dict(), "max_evals": self.max_evals, "fidelity": self.fidelity,
                "reference": self.reference, "reference_sensor": self.reference_sensor}

    def bound_job(self, design: Design) -> DesignJob:
        """The bound evaluation of ``design`` under this run's requirement (seed 0)."""
        return DesignJob(Evaluator.BOUND, self.requirement.task, design, 0, self.fidelity, self.requirement.condition,
                         self.reference, self.reference_sensor)


@dataclass(frozen=True)
class ReferenceJob:
    """One reference to simulate and save (a zone layout, in the nominal model or in a world).

    Parameters
    ----------
    path : str
        Where to save it (nothing is simulated when the file exists).
    sensor : SensorConfig
        The layout's reference sensor (in the world, for a world's reference).
    scenes : SceneSet
        Its scenes (with the world's ``scene_kwargs``).
    label : str
        E.g. ``"3x3"`` or ``"world 2, 1x1"`` (for progress and the report).
    min_support_sigma_ps : float
        The fast simulator plans the impulse response for at least this Gaussian sigma, ps (a design run's
        references, nominal and worlds': the largest world's, so a layout's references all run one compiled
        program); 0: the sensor's own.
    pad_scenes : SceneSet, optional
        A world's reference: the layout's nominal scenes, whose plan the fast simulator pads to (so the world runs
        the nominal references' compiled program); None: its own plan.
    """

    path: str
    sensor: SensorConfig
    scenes: SceneSet
    label: str
    min_support_sigma_ps: float = 0.0
    pad_scenes: SceneSet | None = None

    def to_dict(self) -> dict:
        return {"path": self.path, "sensor": self.sensor.to_dict(), "scenes": self.scenes.to_dict(),
                "label": self.label, "min_support_sigma_ps": self.min_support_sigma_ps,
                "pad_scenes": None if self.pad_scenes is None else self.pad_scenes.to_dict()}


@dataclass(frozen=True)
class CatalogJob:
    """The stability catalog (:func:`~nlosplan.planner.design.catalog.run_catalog`), run beside the references.

    It has no inputs: the job only names it for progress and for a failure's record.
    """

    label: str = "stability catalog"

    def to_dict(self) -> dict:
        return {"label": self.label}
