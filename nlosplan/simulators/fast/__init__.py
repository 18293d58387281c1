"""The fast, differentiable JAX backend: plan, transport, simulator."""

from nlosplan.simulators.fast.fidelity import FIDELITY_LEVELS, Fidelity, resolve_fidelity
from nlosplan.simulators.fast.geometry import direct_returns
from nlosplan.simulators.fast.plan import SimPlan, build_plan
from nlosplan.simulators.fast.simulator import FastSimulator, scene_params, sensor_params, to_jax
from nlosplan.simulators.fast.transport import forward

__all__ = [
    "FIDELITY_LEVELS",
    "FastSimulator",
    "Fidelity",
    "SimPlan",
    "build_plan",
    "direct_returns",
    "forward",
    "resolve_fidelity",
    "scene_params",
    "sensor_params",
    "to_jax",
]
