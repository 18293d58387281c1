"""Sim-to-real calibration of the sensor model (``nlosplan calibrate``).

- :mod:`.model`: parameters (normalized, bounded), DENALI's three steps, the forward model.
- :mod:`.fit`: nlopt fit with stacked steps, Fisher uncertainties, robustness checks.
- :mod:`.plane`: captures of a plane at known distances (``tmf882x_distance``), held-out scores,
  the calibrated :class:`~nlosplan.sensor_models.config.SensorConfig`.
"""

from nlosplan.sensor_models.calibration.fit import CalibrationFit, fit_calibration, predict, usable_zones
from nlosplan.sensor_models.calibration.model import PARAM_NAMES, PARAMS, STEPS, CaptureSet, make_model
from nlosplan.sensor_models.calibration.plane import (
    PlaneHoldout,
    calibrated_sensor,
    capture_set,
    fit_plane,
    holdout_scores,
    plane_holdout,
)

__all__ = ["PARAMS", "PARAM_NAMES", "STEPS", "CalibrationFit", "CaptureSet", "PlaneHoldout", "calibrated_sensor",
           "capture_set", "fit_calibration", "fit_plane", "holdout_scores", "make_model", "plane_holdout", "predict",
           "usable_zones"]
