"""Sensor models: configuration, presets, zone geometry, histogram formation.

Examples
--------
>>> from nlosplan import sensor_models as sm
>>> sensor = sm.preset("tmf8828-3x3-short").replace(jitter_fwhm_ps=100.0)
>>> sensor.zones_rows, sensor.n_bins
(3, 128)
"""

from nlosplan.sensor_models.binning import bin_boxes, bin_impulses
from nlosplan.sensor_models.config import SensorConfig
from nlosplan.sensor_models.counts import coates_correction, pileup_expected, sample_poisson, saturate
from nlosplan.sensor_models.pipeline import (
    apply_jitter,
    bin_arrivals,
    expected_counts,
    expected_histogram,
    sample_counts,
    sample_histogram,
)
from nlosplan.sensor_models.presets import PRESET_NAMES, preset, resolve_sensor
from nlosplan.sensor_models.zones import flash_intensity, zone_rays, zone_solid_angles

__all__ = [
    "PRESET_NAMES",
    "SensorConfig",
    "apply_jitter",
    "bin_arrivals",
    "bin_boxes",
    "bin_impulses",
    "coates_correction",
    "expected_counts",
    "expected_histogram",
    "flash_intensity",
    "pileup_expected",
    "preset",
    "resolve_sensor",
    "sample_counts",
    "sample_histogram",
    "sample_poisson",
    "saturate",
    "zone_rays",
    "zone_solid_angles",
]
