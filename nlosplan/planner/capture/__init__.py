"""Capture planning: which gantry positions to capture next (ask/tell), in closed loop with the rig.

- :mod:`.keepout` — candidate positions, gantry limits, the direct-view ray test;
- :mod:`.space` — the nominal counts model and its derivatives at every candidate;
- :mod:`.motion`, :mod:`.route` — gantry time and route ordering (nearest neighbour + 2-opt);
- :mod:`.doptimal`, :mod:`.batch` — D-optimal designs (IPOPT) and joint batches per second of travel;
- :mod:`.ensemble`, :mod:`.calibration` — the localization model with uncertainty, the calibration fit;
- :mod:`.planner` — :class:`CapturePlanner` (suggest / ingest / best, checkpoints);
- :mod:`.simrig` — a simulated rig (simulator captures + the motion model) for studies and tests.
"""

from nlosplan.planner.capture.batch import batch_information, select_batch
from nlosplan.planner.capture.calibration import calibration_error, fit_counts_model
from nlosplan.planner.capture.doptimal import relaxed_doptimal, round_design
from nlosplan.planner.capture.ensemble import EnsembleLocalizer
from nlosplan.planner.capture.keepout import (Candidates, direct_view_zones, grid_points, region_points,
                                              screen_candidates)
from nlosplan.planner.capture.motion import MotionModel
from nlosplan.planner.capture.planner import CapturePlanner, PlannerConfig
from nlosplan.planner.capture.route import order_batch
from nlosplan.planner.capture.space import CALIBRATION_PARAMETERS, CandidateSpace, build_space, denali_scene_fn
from nlosplan.planner.capture.strategies import STRATEGIES

__all__ = ["CALIBRATION_PARAMETERS", "STRATEGIES", "Candidates", "CandidateSpace", "CapturePlanner",
           "EnsembleLocalizer", "MotionModel", "PlannerConfig", "batch_information", "build_space",
           "calibration_error", "denali_scene_fn", "direct_view_zones", "fit_counts_model", "grid_points",
           "order_batch", "region_points", "relaxed_doptimal", "round_design", "screen_candidates",
           "select_batch"]
