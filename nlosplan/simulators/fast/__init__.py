"""The fast, differentiable JAX backend: plan, transport, simulator."""

from nlosplan.simulators.fast.fidelity import FIDELITY_LEVELS, Fidelity, resolve_fidelity
from nlosplan.simulators.fast.plan import SimPlan, build_plan
from nlosplan.simulators.fast.simulator import FastSimulator, scene_params, sensor_params

__all__ = [
    "FIDELITY_LEVELS",
    "FastSimulator",
    "Fidelity",
    "SimPlan",
    "build_plan",
    "resolve_fidelity",
    "scene_params",
    "sensor_params",
]
