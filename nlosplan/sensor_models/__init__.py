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
from nlosplan.sensor_models.counts import coates_correction, pileup_expected
from nlosplan.sensor_models.degrade import Degradation, degrade_counts, degrade_expected, degrade_linear, reach
from nlosplan.sensor_models.impulse import impulse_fwhm_ps, impulse_sigma_ps, in_quadrature, sigma_of_fwhm
from nlosplan.sensor_models.noise import (CaptureNoise, floor_counts, floor_per_bin, floor_rate_hz, per_bin, rate_hz,
                                         sample_poisson)
from nlosplan.sensor_models.pipeline import (
    apply_jitter,
    bin_arrivals,
    counts_from_rates,
    expected_counts,
    expected_histogram,
    pulse_boxes,
    sample_histogram,
)
from nlosplan.sensor_models.presets import (PRESET_NAMES, load_sensor_file, preset, resolve_sensor, sensor_base,
                                            preset_uncertainty)
from nlosplan.sensor_models.transient import (TimeGrid, bin_nodes_without_irf, deposit, deposit_at, irf_extent_ps,
                                              irf_matrix)
from nlosplan.sensor_models.zones import flash_intensity, solid_angle_rect, zone_edges_tan, zone_rays, zone_solid_angles

__all__ = [
    "MAX_BINS", "PRESET_NAMES", "CaptureNoise", "Degradation", "SensorConfig", "TimeGrid", "apply_jitter",
    "bin_arrivals", "bin_boxes", "bin_impulses", "bin_nodes_without_irf", "coates_correction", "counts_from_rates",
    "degrade_counts", "degrade_expected", "degrade_linear", "deposit", "deposit_at", "expected_counts",
    "expected_histogram", "flash_intensity", "floor_counts", "floor_per_bin", "floor_rate_hz", "impulse_fwhm_ps",
    "impulse_sigma_ps", "in_quadrature", "irf_extent_ps", "irf_matrix", "load_sensor_file", "per_bin",
    "pileup_expected", "preset", "pulse_boxes", "rate_hz", "reach", "resolve_sensor", "sample_histogram",
    "sample_poisson", "sensor_base", "sigma_of_fwhm", "solid_angle_rect", "preset_uncertainty", "zone_edges_tan",
    "zone_rays", "zone_solid_angles",
]
