"""Sim-to-real calibration of the sensor model (``nlosplan calibrate``): a room above simulators and data.

- :mod:`.workflow`: the plane and DENALI workflows the command runs (load, fit, calibrated sensor).
- :mod:`.tmf882x_fit`, :mod:`.tmf882x_report`: the TMF882x time base and pulse shape from plane captures
  (``nlosplan sensor fit-timebase``).
- :mod:`.model`: parameters (normalized, bounded), DENALI's three steps, the forward model.
- :mod:`.fit`: nlopt fit with stacked steps, Fisher uncertainties, robustness checks.
- :mod:`.bootstrap`: uncertainties from refits on captures resampled with replacement.
- :mod:`.plane`: captures of a plane at known distances (``tmf882x_distance``), held-out scores,
  the calibrated :class:`~nlosplan.sensor_models.config.SensorConfig`.
- :mod:`.denali_data`: DENALI-layout captures (a folder or a capture store) with the arrivals of their
  matching simulated DENALI scenes.
- :mod:`.denali`: the fit on DENALI captures, a holdout split by gantry position, the calibrated sensor.
"""

from nlosplan.calibration.bootstrap import BootstrapErrors, bootstrap_errors
from nlosplan.calibration.denali import (
    DenaliHoldout,
    calibrated_denali_sensor,
    denali_holdout,
    fit_denali,
)
from nlosplan.calibration.denali_data import (
    DenaliCaptures,
    denali_capture_set,
    load_denali_captures,
    scene_arrivals,
)
from nlosplan.calibration.fit import (
    CalibrationFit,
    ZoneScores,
    fit_sensor_model,
    predict,
    usable_zones,
    zone_scores,
)
from nlosplan.calibration.model import PARAM_NAMES, PARAMS, STEPS, CaptureSet, make_model
from nlosplan.calibration.plane import (
    PlaneHoldout,
    calibrated_sensor,
    capture_set,
    fit_plane,
    holdout_scores,
    plane_holdout,
)
from nlosplan.calibration.tmf882x_fit import DistanceCaptures, fit_pulse_shape, fit_timebase, load_distance_captures
from nlosplan.calibration.workflow import Calibration, calibrate_denali, calibrate_plane, load_denali, load_plane

__all__ = ["PARAMS", "PARAM_NAMES", "STEPS", "BootstrapErrors", "Calibration", "CalibrationFit", "CaptureSet",
           "DenaliCaptures", "DenaliHoldout", "DistanceCaptures", "PlaneHoldout", "ZoneScores", "bootstrap_errors",
           "calibrate_denali", "calibrate_plane", "calibrated_denali_sensor", "calibrated_sensor", "capture_set",
           "denali_capture_set", "denali_holdout", "fit_sensor_model", "fit_denali", "fit_plane", "fit_pulse_shape",
           "fit_timebase", "holdout_scores", "load_denali", "load_denali_captures", "load_distance_captures",
           "load_plane", "make_model", "plane_holdout", "predict", "scene_arrivals", "usable_zones", "zone_scores"]
