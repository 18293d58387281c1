"""The sensor terms of issue 16: per-zone offsets, scales, gains, overlap; pulse tail; dead time of multi-SPAD zones."""

import math

import numpy as np
import pytest

from nlosplan.constants import C_M_PER_PS
from nlosplan.errors import UserError
from nlosplan.sensor_models import SensorConfig, expected_histogram, load_sensor_file, preset
from nlosplan.sensor_models.counts import deadtime_expected, pileup_expected
from nlosplan.sensor_models.pipeline import pulse_boxes
from nlosplan.sensor_models.zone_terms import apply_zone_terms, move_nodes, overlap_factor

PULSE = (0.1, 0.6, 0.2, 0.1)


def _sensor(**kw):
    base = dict(zones_rows=1, zones_cols=2, n_bins=64, bin_width_ps=100.0, start_offset_ps=0.0, iterations=1000,
                photon_scale=1.0, saturation=False, pulse_shape=PULSE, pulse_shape_step_ps=100.0,
                pulse_shape_t0_ps=0.0)
    return SensorConfig(**{**base, **kw})


def test_zone_offsets_move_the_return_by_exactly_the_offset():
    t = np.full((2, 1), 1000.0)
    w = np.ones((2, 1))
    plain = np.asarray(expected_histogram(_sensor(), t, w))
    moved = np.asarray(expected_histogram(_sensor(zone_time_offsets_ps=(300.0, -200.0)), t, w))
    np.testing.assert_allclose(moved[0], np.roll(plain[0], 3), atol=1e-12)
    np.testing.assert_allclose(moved[1], np.roll(plain[1], -2), atol=1e-12)
    # a fractional offset moves the mean arrival by exactly the offset (box pulse, exact binning)
    frac = np.asarray(expected_histogram(_sensor(zone_time_offsets_ps=(37.0, 0.0)), t, w))
    centre = np.arange(64) + 0.5
    assert (frac[0] @ centre - plain[0] @ centre) / frac[0].sum() == pytest.approx(0.37, abs=1e-9)


def test_zone_time_scales_record_t_at_s_times_t():
    t = np.full((2, 1), 2000.0)
    w = np.ones((2, 1))
    plain = np.asarray(expected_histogram(_sensor(), t, w))
    scaled = np.asarray(expected_histogram(_sensor(zone_time_scales=(1.1, 1.0)), t, w))
    np.testing.assert_allclose(scaled[0], np.roll(plain[0], 2), atol=1e-12)  # 2000 ps -> 2200 ps
    np.testing.assert_allclose(scaled[1], plain[1], atol=1e-12)


def test_zone_gains_multiply_the_light_of_their_zone():
    t, w = np.full((2, 3), 1500.0), np.ones((2, 3))
    plain = np.asarray(expected_histogram(_sensor(), t, w))
    gained = np.asarray(expected_histogram(_sensor(zone_gains=(2.5, 0.0)), t, w))
    np.testing.assert_allclose(gained[0], 2.5 * plain[0], rtol=1e-12)
    assert np.all(gained[1] == 0)


def test_overlap_factor_limits_and_its_effect_on_a_plane_return():
    d0 = 0.05
    t_at = lambda r: 2 * r / C_M_PER_PS  # noqa: E731
    assert float(overlap_factor(t_at(d0), d0)) == pytest.approx(0.5, rel=1e-12)
    assert float(overlap_factor(t_at(10.0), d0)) == pytest.approx(1 - (d0 / 10.0) ** 2, rel=1e-6)
    assert float(overlap_factor(0.0, d0)) == 0.0 and float(overlap_factor(-5.0, d0)) == 0.0
    assert float(overlap_factor(t_at(0.01), 0.0)) == 1.0
    t = np.full((2, 1), t_at(0.08))
    plain = np.asarray(expected_histogram(_sensor(), t, np.ones((2, 1))))
    over = np.asarray(expected_histogram(_sensor(zone_overlap_m=(0.08, 0.0)), t, np.ones((2, 1))))
    assert over[0].sum() == pytest.approx(0.5 * plain[0].sum(), rel=1e-9)
    np.testing.assert_allclose(over[1], plain[1], rtol=1e-12)


def test_pulse_tail_carries_its_share_with_an_exponential_decay():
    s = _sensor(pulse_tail_fraction=0.01, pulse_tail_decay_ps=250.0)
    offsets, width, masses = pulse_boxes(s)
    assert masses.sum() == pytest.approx(1.0, abs=1e-12)
    assert masses[:4].sum() == pytest.approx(0.99, abs=1e-12)  # the measured samples keep 1 - fraction
    tail = masses[4:]
    assert tail.sum() == pytest.approx(0.01, abs=1e-12)
    np.testing.assert_allclose(tail[1:6] / tail[:5], math.exp(-100.0 / 250.0), rtol=1e-9)
    assert offsets[4] == pytest.approx(offsets[3] + width)  # starts after the last sample
    # counts after the pulse fall by exp(-bin / decay) per bin
    h = np.asarray(expected_histogram(s, np.full((2, 1), 1000.0), np.ones((2, 1))))[0]
    assert h[20] / h[19] == pytest.approx(math.exp(-100.0 / 250.0), rel=1e-9)
    with pytest.raises(UserError, match="pulse_tail_fraction > 0 needs a pulse_shape"):
        SensorConfig(pulse_tail_fraction=0.1)


def test_dead_time_matches_the_non_paralyzable_formula_and_coates_in_its_limits():
    n_bins, rate = 4000, 2e-3  # photons per bin per iteration, constant
    lam = np.full(n_bins, rate)
    dead = 50.0  # bins
    d = np.asarray(deadtime_expected(lam, 1.0, 1, dead))
    steady = d[-1000:].mean()  # detections per bin, far from the window start
    n = -math.expm1(-rate)  # detection probability per bin of a live detector
    assert steady == pytest.approx(n / (1 + n * dead), rel=2e-3)  # non-paralyzable: m = n / (1 + n tau)
    # a dead time longer than the window is Coates' first-photon model; M detectors share the light
    lam = np.abs(np.sin(np.arange(128) / 7.0)) * 0.05
    np.testing.assert_allclose(np.asarray(deadtime_expected(lam, 550.0, 1, 500.0)),
                               np.asarray(pileup_expected(lam, 550.0)), rtol=1e-10)
    np.testing.assert_allclose(np.asarray(deadtime_expected(lam, 550.0, 4, None)),
                               4 * np.asarray(pileup_expected(lam / 4, 550.0)), rtol=1e-12)
    many = np.asarray(deadtime_expected(lam, 550.0, 10**6, None))
    np.testing.assert_allclose(many, 550.0 * lam, rtol=1e-5)  # many detectors: no pile-up


def test_node_moves_preserve_mass_and_mean_and_are_exact_on_whole_nodes():
    rng = np.random.default_rng(0)
    x = np.zeros((2, 60))
    x[:, 20:30] = rng.random((2, 10))
    times = 10.0 * np.arange(60)
    whole = np.asarray(move_nodes(x, times, 10.0, offsets_ps=np.array([30.0, -20.0])))
    np.testing.assert_allclose(whole[0], np.roll(x[0], 3), atol=1e-15)
    np.testing.assert_allclose(whole[1], np.roll(x[1], -2), atol=1e-15)
    frac = np.asarray(move_nodes(x, times, 10.0, scales=np.array([1.05, 1.0]), offsets_ps=np.array([3.7, 0.0])))
    np.testing.assert_allclose(frac.sum(1), x.sum(1), rtol=1e-12)
    mean = lambda a: (a * times).sum(1) / a.sum(1)  # noqa: E731
    assert mean(frac)[0] == pytest.approx(1.05 * mean(x)[0] + 3.7, rel=1e-12)
    g = np.asarray(apply_zone_terms(x, times, 10.0, gains=np.array([2.0, 1.0])))
    np.testing.assert_allclose(g[0], 2 * x[0])


def test_per_zone_fields_validate_and_round_trip(tmp_path):
    s = preset("tmf8828-3x3-short").replace(zone_gains=[1.0] * 8 + [2.0], zone_time_offsets_ps=[5.0] * 9,
                                            zone_time_scales=[1.01] * 9, zone_overlap_m=[0.05] * 9)
    for ext in ("toml", "json"):
        s.save(tmp_path / f"s.{ext}")
        assert load_sensor_file(tmp_path / f"s.{ext}") == s
    with pytest.raises(UserError, match="zone_gains has 4 values but the sensor has 9 zones"):
        s.replace(zone_gains=[1.0] * 4)
    with pytest.raises(UserError, match=r"zone_time_offsets_ps\[1\]='x' must be a number"):
        s.replace(zone_time_offsets_ps=[0.0, "x"] + [0.0] * 7)
    with pytest.raises(UserError, match="zone_overlap_m must be >= 0"):
        s.replace(zone_overlap_m=[-0.1] + [0.0] * 8)
    with pytest.raises(UserError, match="zone_time_scales must be between 0.5 and 2"):
        s.replace(zone_time_scales=[3.0] * 9)
    with pytest.raises(UserError, match="dead_time_ps=-1.0 must be > 0"):
        s.replace(dead_time_ps=-1.0)
    with pytest.raises(UserError, match="spads_per_zone=0 is out of range"):
        s.replace(spads_per_zone=0)
    # another zone layout starts neutral: one unit's per-zone values do not carry over
    s8 = s.replace(zones_rows=8, zones_cols=8)
    assert s8.zone_gains is None and s8.zone_overlap_m is None and s8.zone_time_offsets_ps is None
    with pytest.raises(UserError, match="give arrivals per zone"):
        expected_histogram(s, np.array([3000.0]), np.array([1.0]))


def test_fast_simulator_applies_the_zone_terms_on_its_node_transients():
    from nlosplan.simulators import FastSimulator, denali_scene

    scene = denali_scene().without_objects()
    base = preset("tmf8828-3x3-short").linear_uniform().replace(ambient_rate_hz=0.0, dark_rate_hz=0.0)
    plain = FastSimulator(scene, base, fidelity="draft", dtype="float64").expected()
    gains = np.linspace(0.5, 1.5, 9)
    bw = base.bin_width_ps
    s = base.replace(zone_gains=tuple(gains), zone_time_offsets_ps=(bw,) + (0.0,) * 8)
    sim = FastSimulator(scene, s, fidelity="draft", dtype="float64")
    out = sim.expected()
    np.testing.assert_allclose(out[0, 0], 0.5 * np.roll(plain[0, 0], 1), rtol=1e-9, atol=1e-9 * plain.max())
    np.testing.assert_allclose(out.reshape(9, -1)[1:], gains[1:, None] * plain.reshape(9, -1)[1:], rtol=1e-9,
                               atol=1e-9 * plain.max())
    text = sim.explain()
    assert "computed  zone gains" in text and "computed  zone time offsets" in text
    assert "left out  near-field overlap" in text and "left out  pulse tail" in text


def test_time_walk_moves_each_zone_by_its_own_light_in_the_pipeline_and_the_fast_simulator():
    t = np.full((2, 1), 1000.0)
    w = np.array([[1.0], [10.0]])
    plain = np.asarray(expected_histogram(_sensor(), t, w))
    walked = np.asarray(expected_histogram(_sensor(time_walk_ps=100.0), t, w))
    np.testing.assert_allclose(walked[0], plain[0], atol=1e-12)  # 1 photon per iteration: no shift
    np.testing.assert_allclose(walked[1], np.roll(plain[1], -1), atol=1e-9)  # 10x brighter: 100 ps earlier

    from nlosplan.simulators import FastSimulator, denali_scene

    scene = denali_scene().without_objects()
    base = preset("tmf8828-3x3-short").linear_uniform().replace(ambient_rate_hz=0.0, dark_rate_hz=0.0,
                                               saturation=False, pulse_tail_fraction=0.0)
    parts = FastSimulator(scene, base, fidelity="draft", dtype="float64").expected(parts=True)
    flux = parts["direct"].reshape(9, -1).sum(-1) / base.iterations
    walk = 80.0
    walked = FastSimulator(scene, base.replace(time_walk_ps=walk), fidelity="draft", dtype="float64")
    as_offsets = FastSimulator(scene, base.replace(zone_time_offsets_ps=tuple(-walk * np.log10(flux))),
                               fidelity="draft", dtype="float64")
    np.testing.assert_allclose(walked.expected(), as_offsets.expected(), rtol=1e-6, atol=1e-9 * parts["counts"].max())
    assert "computed  time walk" in walked.explain()


def test_time_walk_is_held_at_its_bounds_and_the_grid_holds_its_largest_shift():
    from nlosplan.sensor_models.transient import TimeGrid
    from nlosplan.sensor_models.zone_terms import WALK_DECADES, walk_reach_ps, walk_shift_ps

    shift = np.asarray(walk_shift_ps(np.array([1e-30, 10 ** -WALK_DECADES, 0.01, 1.0, 100.0, 1e12]), 50.0))
    np.testing.assert_allclose(shift, [300.0, 300.0, 100.0, 0.0, -100.0, -300.0], atol=1e-9)
    assert walk_reach_ps(-50.0) == pytest.approx(50.0 * WALK_DECADES)
    base = _sensor()
    plain = TimeGrid.for_sensor(base, 0.0, 3000.0, oversample=2)
    walked = TimeGrid.for_sensor(base.replace(time_walk_ps=50.0), 0.0, 3000.0, oversample=2)
    # arrivals end at 3000 ps: the walk can move them up to 300 ps later, 3 more bins of 100 ps (1 ps rounding)
    assert walked.first_bin + walked.n_grid_bins >= plain.first_bin + plain.n_grid_bins + 3


def test_time_walk_of_a_scene_is_unchanged_by_an_object_outside_the_window():
    # the far object is pruned but stretches the plan's node grid to the window's end; the walk moved the wall's
    # light (under 1 photon per iteration: later) off the shorter grid of the scene without it (41 % at the peak)
    from nlosplan.simulators import FastSimulator, corner_scene

    scene = corner_scene(object_xy=(0.45, 10.0), wall_size=(20.0, 10.0))
    sensor = preset("tmf8828-3x3-plane-unit")   # the preset with a fitted time walk
    assert sensor.time_walk_ps != 0
    far = FastSimulator(scene, sensor, fidelity="draft", dtype="float64")
    bg = FastSimulator(scene.without_objects(), sensor, fidelity="draft", dtype="float64")
    assert far.plan.static.grid.n_grid_bins > bg.plan.static.grid.n_grid_bins and not far.plan.static.objects
    h, h0 = np.asarray(far.expected()), np.asarray(bg.expected())
    assert h0.max() > 1e3
    np.testing.assert_allclose(h, h0, rtol=1e-9, atol=1e-9 * h0.max())
