"""Sensor-design search: the least hardware that does each NLOS task.

Public surface: :class:`DesignSpace`, :class:`Design`, :class:`Requirement`,
:class:`CostModel`, :class:`DesignConfig`, :func:`run_design`,
:func:`full_config`, :func:`quick_config`, :func:`load_config`.
"""

from nlosplan.planner.design.config import full_config, load_config, quick_config
from nlosplan.planner.design.cost import CostModel
from nlosplan.planner.design.requirements import DEFAULT_REQUIREMENTS, Requirement, parse_requirement
from nlosplan.planner.design.run import DesignConfig, run_design
from nlosplan.planner.design.space import Design, DesignSpace

__all__ = ["CostModel", "DEFAULT_REQUIREMENTS", "Design", "DesignConfig", "DesignSpace", "Requirement",
           "full_config", "load_config", "parse_requirement", "quick_config", "run_design"]
