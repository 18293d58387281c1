"""Sim-to-real calibration of the sensor model (``nlosplan calibrate``).

- :mod:`.model`: parameters (normalized, bounded), DENALI's three steps, the forward model.
- :mod:`.fit`: nlopt fit with stacked steps, Fisher uncertainties, robustness checks.
- :mod:`.bootstrap`: uncertainties from refits on captures resampled with replacement.
- :mod:`.plane`: captures of a plane at known distances (``tmf882x_distance``), held-out scores,
  the calibrated :class:`~nlosplan.sensor_models.config.SensorConfig`.
- :mod:`.denali_data`: DENALI-layout captures (a folder or a capture store) with the arrivals of their
  matching simulated DENALI scenes.
- :mod:`.denali`: the fit on DENALI captures, a holdout split by gantry position, the calibrated sensor.
"""

from nlosplan.sensor_models.calibration.bootstrap import BootstrapErrors, bootstrap_errors
from nlosplan.sensor_models.calibration.denali import (
    DenaliHoldout,
    calibrated_denali_sensor,
    denali_holdout,
    fit_denali,
)
from nlosplan.sensor_models.calibration.denali_data import (
    DenaliCaptures,
    denali_capture_set,
    load_denali_captures,
    scene_arrivals,
)
from nlosplan.sensor_models.calibration.fit import (
    CalibrationFit,
    ZoneScores,
    fit_calibration,
    predict,
    usable_zones,
    zone_scores,
)
from nlosplan.sensor_models.calibration.model import PARAM_NAMES, PARAMS, STEPS, CaptureSet, make_model
from nlosplan.sensor_models.calibration.plane import (
    PlaneHoldout,
    calibrated_sensor,
    capture_set,
    fit_plane,
    holdout_scores,
    plane_holdout,
)

__all__ = ["PARAMS", "PARAM_NAMES", "STEPS", "BootstrapErrors", "CalibrationFit", "CaptureSet", "DenaliCaptures", "DenaliHoldout",
           "PlaneHoldout", "ZoneScores", "bootstrap_errors", "calibrated_denali_sensor", "calibrated_sensor", "capture_set",
           "denali_capture_set", "denali_holdout", "fit_calibration", "fit_denali", "fit_plane", "holdout_scores",
           "load_denali_captures", "make_model", "plane_holdout", "predict", "scene_arrivals", "usable_zones",
           "zone_scores"]
