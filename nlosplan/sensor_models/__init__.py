"""Sensor models: configuration, presets, zone geometry, histogram formation.

Examples
--------
>>> from nlosplan import sensor_models as sm
>>> sensor = sm.preset("tmf8828-3x3-short").replace(jitter_fwhm_ps=100.0)
>>> sensor.zones_rows, sensor.n_bins
(3, 128)
"""

from nlosplan.sensor_models.binning import bin_boxes, bin_impulses
from nlosplan.sensor_models.config import MAX_BINS, SensorConfig
from nlosplan.sensor_models.counts import coates_correction, pileup_expected, sample_poisson, saturate
from nlosplan.sensor_models.degrade import Degradation, degrade_counts, degrade_expected, degrade_linear, reach
from nlosplan.sensor_models.impulse import impulse_fwhm_ps, impulse_sigma_ps
from nlosplan.sensor_models.pipeline import (
    apply_jitter,
    background_per_bin,
    bin_arrivals,
    counts_from_rates,
    expected_counts,
    expected_histogram,
    pulse_boxes,
    sample_counts,
    sample_histogram,
)
from nlosplan.sensor_models.presets import (PRESET_NAMES, load_sensor_file, preset, resolve_sensor, sensor_base,
                                            uncertainty)
from nlosplan.sensor_models.transient import (TimeGrid, bin_nodes_without_irf, deposit, deposit_at, irf_extent_ps,
                                              irf_matrix)
from nlosplan.sensor_models.zones import flash_intensity, solid_angle_rect, zone_edges_tan, zone_rays, zone_solid_angles

__all__ = [
    "MAX_BINS", "PRESET_NAMES", "Degradation", "SensorConfig", "TimeGrid", "apply_jitter", "background_per_bin",
    "bin_arrivals", "bin_boxes", "bin_impulses", "bin_nodes_without_irf", "coates_correction", "counts_from_rates",
    "degrade_counts", "degrade_expected", "degrade_linear", "deposit", "deposit_at", "expected_counts",
    "expected_histogram", "flash_intensity", "impulse_fwhm_ps", "impulse_sigma_ps", "irf_extent_ps", "irf_matrix",
    "load_sensor_file", "pileup_expected", "preset", "pulse_boxes", "reach", "resolve_sensor", "sample_counts",
    "sample_histogram", "sample_poisson", "saturate", "sensor_base", "solid_angle_rect", "uncertainty", "zone_edges_tan",
    "zone_rays", "zone_solid_angles",
]
