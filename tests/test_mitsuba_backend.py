"""The Mitsuba twin (llvm_ad_rgb on the CPU): small renders checked against closed forms and the fast backend."""

import numpy as np
import pytest

from nlosplan.constants import C_M_PER_PS
from nlosplan.errors import UserError
from nlosplan.sensor_models import preset
from nlosplan.simulators import FastSimulator, NLOSWarning, denali_scene, expected_histogram
from nlosplan.simulators.mitsuba import TwinSimulator, spot_point
from nlosplan.simulators.mitsuba.env import check_versions, resolve_variant

SMALL = {"spp": 32, "zone_sub": 4, "flash_resolution": 128}


@pytest.fixture(scope="module")
def sensor():
    return preset("tmf8828-3x3-short")


@pytest.fixture(scope="module")
def lambertian():
    return denali_scene("A", "8in", position=19, reflectance="lambertian")


def test_direct_wall_return_matches_fast_backend(sensor, lambertian):
    """Projector flash, zone sub-pixel meter and time axis: the wall's first bounce equals the fast one."""
    twin = TwinSimulator(lambertian.without_objects(), sensor, fidelity={**SMALL, "zone_sub": 8}).expected(parts=True)
    fast = FastSimulator(lambertian.without_objects(), sensor, fidelity="high", dtype="float64").expected(parts=True)
    a, b = twin["direct"], fast["direct"]
    assert a.shape == (3, 3, 128)
    assert np.abs(a - b).sum() / b.sum() < 0.02
    np.testing.assert_allclose(a.sum(-1), b.sum(-1), rtol=0.02)
    assert np.array_equal(a.argmax(-1), b.argmax(-1))
    assert np.all(twin["object"] == 0)


def test_three_bounce_small_render_is_seeded_and_near_the_fast_backend(sensor, lambertian):
    zones = [(1, 1), (1, 2)]
    fid = {**SMALL, "spp": 512}
    a = TwinSimulator(lambertian, sensor, fidelity=fid, zones=zones, seed=3)
    b = TwinSimulator(lambertian, sensor, fidelity=fid, zones=zones, seed=3)
    c = TwinSimulator(lambertian, sensor, fidelity=fid, zones=zones, seed=4)
    oa, ob, oc = (s.expected(parts=True)["object"] for s in (a, b, c))
    assert oa.shape == (2, 128)
    assert np.array_equal(oa, ob)  # same seed, same result
    assert not np.array_equal(oa, oc)
    fast = FastSimulator(lambertian, sensor, fidelity="default", zones=zones, dtype="float64").expected(parts=True)
    ratio = oa.sum(-1) / fast["object"].sum(-1)
    assert np.all((ratio > 0.75) & (ratio < 1.25))  # 8,192 paths per zone: ~5 % Monte-Carlo noise
    assert np.all(np.abs(oa.argmax(-1) - fast["object"].argmax(-1)) <= 2)
    assert set(a.seconds) == {"direct", "object", "total"}
    assert a.describe()["fidelity"]["spp"] == 512


def test_expected_histogram_dispatch_and_pipeline(sensor, lambertian):
    """``backend="mitsuba"`` is a drop-in: same shape, the sensor's background floor and crosstalk peak."""
    s = sensor.replace(crosstalk=0.5, dark_rate_hz=1e5)
    with pytest.warns(NLOSWarning, match="measures the relay wall only .* table 14, table 15 are not in its histograms"):
        h = expected_histogram(lambertian, s, backend="mitsuba", fidelity=SMALL, zones=[(0, 0)])
    assert h.shape == (1, 128) and np.all(np.isfinite(h)) and np.all(h >= 0)
    floor = s.iterations * s.dark_rate_hz * s.bin_width_ps * 1e-12
    assert h[0, -1] == pytest.approx(floor, rel=1e-3)  # only the pulse tails' last 1e-4 reach the last bin
    zero_bin = int(-s.start_offset_ps // s.bin_width_ps)
    assert h[0, zero_bin - 2 : zero_bin + 4].max() > 0.3 * s.iterations * s.crosstalk


def test_retroreflective_three_bounce_lands_at_the_fast_backends_bins(sensor):
    scene = denali_scene("S", "8in", position=45)
    twin = TwinSimulator(scene, sensor, fidelity=SMALL, zones=[(1, 1)]).expected(parts=True)["object"]
    fast = FastSimulator(scene, sensor, zones=[(1, 1)], dtype="float64").expected(parts=True)["object"]
    assert abs(int(twin.argmax()) - int(fast.argmax())) <= 1
    assert 0.7 < twin.sum() / fast.sum() < 1.3


def test_spot_mode_direct_closed_form_and_three_bounce_time(sensor, lambertian):
    """DENALI's single centre spot: direct return in closed form; the object's return at its path length."""
    sim = TwinSimulator(lambertian, sensor, fidelity=SMALL, zones=[(1, 1)], illumination="spot")
    tr = sim.transient()
    spot = spot_point(lambertian)
    q = spot - lambertian.lidar.position
    r = np.linalg.norm(q)
    expected = lambertian.wall.albedo / np.pi * abs(q @ lambertian.wall.normal) / r**3
    assert tr["direct"].sum() == pytest.approx(expected, rel=1e-6)
    t_direct = (tr["direct"][0] * tr["times_ps"]).sum() / tr["direct"].sum()
    assert t_direct == pytest.approx(2 * r / C_M_PER_PS, abs=1e-3)
    # the object's return: LiDAR -> spot -> object -> centre zone's wall -> LiDAR, between the shortest and longest
    from nlosplan.simulators.mitsuba.geometry import detection

    det = detection(lambertian, sensor, 4, [4])
    x2 = det.points[det.weight > 0]
    x = lambertian.objects[0].world_vertices()
    legs = (r + np.linalg.norm(x - spot, axis=1)[:, None] + np.linalg.norm(x[:, None] - x2[None], axis=2)
            + np.linalg.norm(x2 - lambertian.lidar.position, axis=1)[None])
    t_obj = (tr["object"][0] * tr["times_ps"]).sum() / tr["object"].sum()
    assert legs.min() / C_M_PER_PS < t_obj < legs.max() / C_M_PER_PS
    assert tr["object"][0, tr["times_ps"] < legs.min() / C_M_PER_PS - 50].sum() == 0


def test_errors_are_one_line(sensor, lambertian):
    with pytest.raises(UserError, match="illumination='laser' is unknown; allowed: flash, spot"):
        TwinSimulator(lambertian, sensor, illumination="laser")
    with pytest.raises(UserError, match="unknown twin fidelity 'best'"):
        TwinSimulator(lambertian, sensor, fidelity="best")
    with pytest.raises(UserError, match="spp=0 must be an integer >= 1"):
        TwinSimulator(lambertian, sensor, fidelity={"spp": 0})
    with pytest.raises(UserError, match=r"zone \(3, 0\) is outside the 3x3 grid"):
        TwinSimulator(lambertian, sensor, zones=[(3, 0)])
    with pytest.raises(UserError, match="unknown Mitsuba variant 'scalar_rgb'"):
        resolve_variant("scalar_rgb")
    with pytest.raises(UserError, match=r"mitsuba 3\.5\.2 is not supported by the installed mitransient \(needs >= 3\.6\.0"):
        check_versions("3.5.2", ("3.6.0", "3.10.0"))
    check_versions("3.9.1", ("3.6.0", "3.10.0"))
    with pytest.raises(UserError, match="unknown backend 'blender'; available: fast, mitsuba"):
        expected_histogram(lambertian, sensor, backend="blender")


def test_missing_libllvm_names_the_package(monkeypatch):
    from nlosplan.simulators.mitsuba import env as mitsuba_env

    monkeypatch.setattr(mitsuba_env, "find_libllvm", lambda *a, **k: None)
    with pytest.raises(UserError, match="needs libLLVM >= 16, none found; install it .*apt-get install libllvm19"):
        mitsuba_env.load_mitsuba("llvm_ad_rgb")
