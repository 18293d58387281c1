"""Presets: valid, sourced, and their measured values reproduce the real data."""

import json

import numpy as np
import pytest

from nlosplan.sensor_models import PRESET_NAMES, expected_histogram, preset
from nlosplan.sensor_models.presets import MEASURED
from nlosplan.calibration.tmf882x_fit import fit_timebase, load_distance_captures
from nlosplan.simulators import WallScene, wall_arrivals


@pytest.mark.parametrize("name", PRESET_NAMES)
def test_presets_are_valid_and_carry_sources(name):
    s = preset(name)
    assert s.name == name
    assert s.notes and ("DS" in s.notes or "ST" in s.notes)
    h = expected_histogram(s, np.full((s.zones_rows, s.zones_cols, 1), 4000.0), np.full((s.zones_rows, s.zones_cols, 1), 1e-3))
    assert np.all(np.isfinite(np.asarray(h))) and float(np.asarray(h).sum()) > 0


def test_zone_modes_follow_the_datasheet():
    assert (preset("tmf8828-8x8-short").zones_rows, preset("tmf8828-8x8-short").fov_y_deg) == (8, 52.0)
    assert preset("tmf8828-3x3-short").fov_x_deg == 33.0
    assert preset("tmf8828-3x3-long").bin_width_ps == 260.0
    assert preset("vl53l8ch-8x8").n_bins == 32


@pytest.fixture(scope="module")
def captures():
    from conftest import SHARED

    path = SHARED / "data/tmf882x_distance/distance_data_even.json"
    if not path.is_file():
        pytest.skip(f"real TMF882x data not found at {path}")
    return load_distance_captures(path), json.loads(path.read_text())


def _meas_3x3():
    """The MEAS values (single-zone time base, pulse and photon scale) on the 3x3 geometry, as the 8x8/4x4 presets carry them."""
    return preset("tmf8828-8x8-short").replace(zones_rows=3, zones_cols=3, fov_x_deg=33.0, fov_y_deg=32.0,
                                               iterations=550_000)


def test_preset_time_base_matches_a_fresh_fit(captures):
    caps, _ = captures
    tb = fit_timebase(caps)
    s = preset("tmf8828-8x8-short")
    assert s.bin_width_ps == pytest.approx(tb.bin_width_ps, abs=0.01)
    assert s.start_offset_ps == pytest.approx(tb.start_offset_ps, abs=0.1)


def test_preset_places_the_wall_return_at_the_measured_peak(captures):
    """Preset (measured pulse + time base) through the wall model: peak bin of the centre zone."""
    caps, _ = captures
    s = preset("tmf8828-3x3-short").replace(saturation=False)
    errors = []
    for d, h in zip(caps.distance_m, caps.hists):
        if d < 0.06:
            continue
        model = np.asarray(expected_histogram(s, *wall_arrivals(WallScene(distance_m=float(d)), s)))[1, 1]
        errors.append(int(np.argmax(model)) - int(np.argmax(h[4])))
    errors = np.abs(errors)
    assert errors.max() <= 1 and errors.mean() < 0.3


def test_photon_scale_and_background_reproduce_the_data(captures):
    caps, _ = captures
    s = _meas_3x3()
    ratios, floors = [], []
    for d, h in zip(caps.distance_m, caps.hists):
        if d < 0.25:
            continue
        bg = np.median(h[4, -30:])
        _, w = wall_arrivals(WallScene(distance_m=float(d), albedo=1.0), s)
        ratios.append((h[4] - bg).clip(0).sum() / (w[1, 1].sum() * s.iterations))
        floors.append(bg / (s.iterations * s.bin_width_ps * 1e-12))
    assert np.median(ratios) == pytest.approx(s.photon_scale, rel=0.1)
    assert np.median(floors) == pytest.approx(s.ambient_rate_hz + s.dark_rate_hz, rel=0.15)
    assert MEASURED["n_captures"] == 69


def test_only_the_plane_unit_preset_carries_the_plane_units_per_zone_values():
    s = preset("tmf8828-3x3-plane-unit")
    assert s.pileup and s.zone_gains is not None and s.zone_time_offsets_ps is not None
    assert "never take them as facts" in s.notes and "4000 kilo-iterations" in s.notes
    for name in PRESET_NAMES:
        if name != "tmf8828-3x3-plane-unit":
            other = preset(name)
            assert other.zone_gains is None and other.zone_time_offsets_ps is None and other.zone_overlap_m is None
