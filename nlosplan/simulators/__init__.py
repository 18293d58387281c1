"""Scenes and light transport.

- Scenes: :class:`Scene` (LiDAR pose, relay wall, planes, hidden objects),
  presets :func:`denali_scene` (the DENALI rig) and :func:`corner_scene`.
- Transport: one :class:`Backend` protocol and the table :data:`BACKENDS`
  (``fast``: the JAX backend, :class:`FastSimulator`; ``mitsuba``: the
  Mitsuba 3 twin), behind the backend-independent :func:`expected_histogram`,
  :func:`sample`, :func:`background_histogram`, :func:`explain` and
  :func:`simulate` (results: :class:`SimulationResult`); batches of scenes through
  :func:`expected_batch` (:class:`BatchResult`) and :func:`counts_and_jacobian`
  (:class:`CountsJacobian`: derivatives in the objects' displacement and the
  :data:`NUISANCE_PARAMETERS`); :func:`direct_arrivals`. Rooms above go through
  these, never into a backend's modules.
- :func:`simulate_wall`: a sensor facing a plain wall (first bounce only),
  the scene of the time-base calibration.
"""

from nlosplan.simulators.api import (BACKENDS, background_histogram, check_backend, counts_and_jacobian, direct_arrivals,
                                     expected_batch, expected_histogram, explain, plan_batch, sample, simulate)
from nlosplan.simulators.backend import NUISANCE_PARAMETERS, Backend
from nlosplan.simulators.fast import FIDELITY_LEVELS, FastSimulator, Fidelity, resolve_fidelity
from nlosplan.simulators.meshes import load_obj, sample_surface, square_patch, surface_quadrature
from nlosplan.simulators.presets import corner_scene, denali_scene, rig, scene_at
from nlosplan.simulators.result import BatchResult, CountsJacobian, SimulationResult
from nlosplan.simulators.scene import HiddenObject, LidarPose, Mesh, NLOSWarning, Rect, Scene
from nlosplan.simulators.wall import WallScene, simulate_wall, wall_arrivals

__all__ = [
    "BACKENDS",
    "Backend",
    "BatchResult",
    "CountsJacobian",
    "FIDELITY_LEVELS",
    "FastSimulator",
    "Fidelity",
    "HiddenObject",
    "LidarPose",
    "Mesh",
    "NLOSWarning",
    "NUISANCE_PARAMETERS",
    "Rect",
    "Scene",
    "SimulationResult",
    "WallScene",
    "background_histogram",
    "check_backend",
    "corner_scene",
    "counts_and_jacobian",
    "denali_scene",
    "direct_arrivals",
    "expected_batch",
    "plan_batch",
    "expected_histogram",
    "explain",
    "load_obj",
    "resolve_fidelity",
    "rig",
    "sample",
    "sample_surface",
    "scene_at",
    "simulate",
    "simulate_wall",
    "square_patch",
    "surface_quadrature",
    "wall_arrivals",
]
