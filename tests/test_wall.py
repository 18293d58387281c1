"""Physics of the first-bounce wall scene."""

import numpy as np
import pytest

from nlosplan.constants import C_M_PER_PS
from nlosplan.errors import UserError
from nlosplan.sensor_models import preset
from nlosplan.simulators import WallScene, simulate_wall, wall_arrivals


def ideal(**kw):
    base = dict(pulse_shape=None, pulse_fwhm_ps=0.0, saturation=False, ambient_rate_hz=0.0, dark_rate_hz=0.0)
    return preset("tmf8828-3x3-short").linear_uniform().replace(**{**base, **kw})


@pytest.mark.parametrize("d", [0.2, 0.49, 0.9])
def test_peak_time_matches_round_trip_within_one_bin(d):
    s = ideal(pulse_fwhm_ps=150.0)
    h = simulate_wall(WallScene(distance_m=d), s)
    centre = h[1, 1]
    t_peak = s.start_offset_ps + s.bin_width_ps * (np.argmax(centre) + 0.5)
    assert abs(t_peak - 2 * d / C_M_PER_PS) <= s.bin_width_ps


def test_square_on_wall_is_symmetric():
    h = simulate_wall(WallScene(distance_m=0.5), ideal(pulse_fwhm_ps=200.0))
    np.testing.assert_allclose(h, h[::-1, :, :], rtol=1e-10)
    np.testing.assert_allclose(h, h[:, ::-1, :], rtol=1e-10)


def test_signal_falls_as_inverse_square_with_distance():
    s = ideal()
    w1 = wall_arrivals(WallScene(distance_m=0.4), s)[1].sum()
    w2 = wall_arrivals(WallScene(distance_m=0.8), s)[1].sum()
    assert w1 / w2 == pytest.approx(4.0, rel=1e-9)


def test_signal_linear_in_albedo_and_tilt_delays_one_side():
    s = ideal(pulse_fwhm_ps=100.0)
    w_a = wall_arrivals(WallScene(albedo=0.4), s)[1]
    w_b = wall_arrivals(WallScene(albedo=0.8), s)[1]
    np.testing.assert_allclose(w_b, 2 * w_a)
    t, _ = wall_arrivals(WallScene(distance_m=0.5, yaw_deg=30.0), s)
    # positive yaw puts the right (+x) side of the wall farther away
    assert t[:, 2].mean() > t[:, 0].mean()


def test_sub_ray_refinement_converges():
    s = ideal(pulse_fwhm_ps=200.0)
    ref = simulate_wall(WallScene(yaw_deg=40.0), s, n_sub=32)
    errs = [np.abs(simulate_wall(WallScene(yaw_deg=40.0), s, n_sub=n) - ref).sum() / ref.sum() for n in (2, 4, 8)]
    assert errs[0] > errs[1] > errs[2]
    assert errs[2] < 1e-2


def test_sampled_counts_follow_the_expectation():
    s = preset("tmf8828-3x3-short")
    mean = simulate_wall(WallScene(), s)
    counts = simulate_wall(WallScene(), s, rng=7, repeats=50)
    assert counts.dtype == np.int64
    rel = abs(counts.mean(0).sum() - mean.sum()) / mean.sum()
    assert rel < 1e-3


@pytest.mark.parametrize("kw, word", [({"distance_m": 0.0}, "distance"), ({"yaw_deg": 95.0}, "yaw_deg"),
                                      ({"albedo": -0.1}, "albedo"), ({"distance_m": float("nan")}, "distance")])
def test_invalid_walls_rejected(kw, word):
    with pytest.raises(UserError, match=word):
        WallScene(**kw)
