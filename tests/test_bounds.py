"""Cramér–Rao bound on localization: Jacobian, analytic cases, scaling, nuisances, unidentifiable flags."""

import dataclasses
import math

import numpy as np
import pytest

from nlosplan._jax import jax, jnp
from nlosplan.errors import UserError
from nlosplan.sensor_models import preset
from nlosplan.simulators import FastSimulator, corner_scene, denali_scene
from nlosplan.simulators.fast import jacobian
from nlosplan.simulators.fast.jacobian import _slopes
from nlosplan.simulators.fast.simulator import to_jax
from nlosplan.simulators.fast.transport import forward
from nlosplan.tasks.bounds import (
    analyse_fisher,
    counts_and_jacobian,
    localization_crlb,
    localization_crlb_batch,
    poisson_fisher,
)

SENSOR = preset("tmf8828-3x3-short")
SCENE = denali_scene("A", "8in", 19)
FID = "draft"
#: One nuisance set for the lights-off scene (ambient is left out there), so most tests share one compilation.
NUIS = ("photon_scale", "ambient")


# ----------------------------------------------------------------------------- analytic cases
def test_single_bin_bound_is_lam_over_slope_squared():
    lam, slope = 7.0, 0.8  # one bin, lam(theta) = 7 + 0.8 theta
    fisher = poisson_fisher([lam], [[slope]])
    out = analyse_fisher(fisher, ("x",), n_position=1)
    assert out["covariance"][0, 0] == pytest.approx(lam / slope**2, rel=1e-12)
    assert poisson_fisher([lam], [[slope]], repeats=5)[0, 0] == pytest.approx(5 * slope**2 / lam, rel=1e-12)


def test_two_bins_with_unknown_scale_double_the_variance():
    # lam_1 = s (1 + theta), lam_2 = s; parameters (theta, log s) at theta = 0: I = s [[1, 1], [1, 2]]
    s = 40.0
    fisher = poisson_fisher([s, s], [[s, s], [0.0, s]])
    np.testing.assert_allclose(fisher, s * np.array([[1.0, 1.0], [1.0, 2.0]]), rtol=1e-12)
    est = analyse_fisher(fisher, ("x", "log_photon_scale"), n_position=1)
    known = analyse_fisher(fisher[:1, :1], ("x",), n_position=1)
    assert est["covariance"][0, 0] == pytest.approx(2.0 / s, rel=1e-10)
    assert known["covariance"][0, 0] == pytest.approx(1.0 / s, rel=1e-12)
    assert est["identifiable"] and est["reason"] == ""


def test_gaussian_peak_location_bound_is_sigma_squared_over_photons():
    # a Gaussian pulse of A photons on fine bins, no background: Fisher for its location -> A / sigma^2
    amp, sigma, width = 500.0, 3.0, 0.05
    t = np.arange(-40.0, 40.0, width)
    lam = amp * width * np.exp(-0.5 * (t / sigma) ** 2) / (sigma * math.sqrt(2 * math.pi))
    out = analyse_fisher(poisson_fisher(lam, (lam * t / sigma**2)[:, None]), ("x",), n_position=1)
    assert out["covariance"][0, 0] == pytest.approx(sigma**2 / amp, rel=1e-6)


def test_zero_mean_bins_are_ignored_without_nan():
    fisher = poisson_fisher([0.0, 4.0], [[3.0], [2.0]])
    assert fisher[0, 0] == pytest.approx(1.0)


def test_estimating_nuisances_never_lowers_the_bound_for_random_fisher_matrices():
    rng = np.random.default_rng(3)
    for _ in range(200):
        p = int(rng.integers(3, 7))
        jac = rng.normal(size=(20, p)) * rng.uniform(0.01, 100.0, size=p)
        f = poisson_fisher(rng.uniform(0.5, 50.0, 20), jac)
        est = analyse_fisher(f, tuple(f"p{i}" for i in range(p)))["covariance"]
        known = analyse_fisher(f[:2, :2], ("p0", "p1"))["covariance"]
        assert np.all(np.diag(est) >= np.diag(known) * (1 - 1e-9))


# ----------------------------------------------------------------------------- the simulator's Jacobian
@pytest.fixture(scope="module")
def lights_on():
    return denali_scene("A", "8in", 19, lights="on")


ALL = ("photon_scale", "ambient", "dark", "albedo")


def test_jacobian_matches_finite_differences(lights_on):
    lam, jac, names, _ = counts_and_jacobian(lights_on, SENSOR, fidelity=FID, nuisance=ALL)
    assert names == ("x", "y", "log_photon_scale", "log_ambient", "log_dark", "log_albedo")
    assert np.all(lam > 0) and np.all(np.isfinite(jac))
    for i, h in enumerate((1e-5, 1e-5, 1e-5, 1e-5, 1e-5, 1e-5)):
        e = np.eye(len(names))[i] * h
        up, *_ = counts_and_jacobian(lights_on, SENSOR, fidelity=FID, nuisance=ALL, theta=e)
        down, *_ = counts_and_jacobian(lights_on, SENSOR, fidelity=FID, nuisance=ALL, theta=-e)
        fd = (up - down)[0] / (2 * h)
        # the transport deposits on a time grid (piecewise linear): central differences see its kinks
        np.testing.assert_allclose(jac[0, ..., i], fd, rtol=2e-3, atol=2e-4 * np.abs(fd).max(), err_msg=names[i])


def test_jacobian_matches_forward_mode_differentiation(lights_on):
    """The central differences (10 nm, 1e-8 in log units) against jax.jacfwd of the forward model (float64)."""
    lam, jac, names, _ = counts_and_jacobian(lights_on, SENSOR, fidelity=FID, nuisance=ALL)
    sim = FastSimulator([lights_on], SENSOR, fidelity=FID, dtype="float64")
    scene_p, sensor_p = sim.params()
    sc = jax.tree_util.tree_map(lambda a: a[0], to_jax(scene_p, jnp.float64))
    sp = jax.tree_util.tree_map(lambda a: a[0], to_jax(sensor_p, jnp.float64))
    arrays = to_jax(sim.plan.arrays, jnp.float64)
    axes = jnp.asarray(np.eye(3)[:2])
    static = sim.plan.static
    field = {"photon_scale": "photon_scale", "ambient": "ambient_rate_hz", "dark": "dark_rate_hz"}

    def counts(t):  # the whole forward model with the objects moved and the sensor's fields scaled
        shift = t[0] * axes[0] + t[1] * axes[1]
        objects = [dict(o, to_world=o["to_world"].at[:3, 3].add(shift)) for o in sc["objects"]]
        objects[0]["albedo"] = objects[0]["albedo"] * jnp.exp(t[2 + ALL.index("albedo")])
        scaled = dict(sp)
        for name, key in field.items():
            scaled[key] = sp[key] * jnp.exp(t[2 + ALL.index(name)])
        return forward(static, arrays, {**sc, "objects": objects}, scaled)

    ad = np.asarray(jax.jacfwd(counts)(jnp.zeros(len(names))))
    assert np.all(np.abs(ad).max(axis=(0, 1)) > 0)  # every parameter moves the counts of this lights-on scene
    # a difference of counts lam over a step h carries float64 rounding ~ eps lam / h: far below the Poisson
    # noise sqrt(lam) per unit of the parameter's information
    rounding = 1e3 * np.finfo(float).eps * lam[0] / jacobian.POSITION_STEP_M
    assert jacobian.LOG_STEP == jacobian.POSITION_STEP_M
    for i, name in enumerate(names):
        err = np.abs(jac[0, ..., i] - ad[..., i])
        tol = 1e-4 * np.abs(ad[..., i]) + 1e-7 * np.abs(ad[..., i]).max() + rounding
        assert np.all(err <= tol), (name, float((err / tol).max()))


@pytest.mark.slow  # 28 s; the simulator's mount sharing stays fast (tests/test_fast_share.py), CI runs this
def test_mount_shared_across_objects_gives_the_unshared_jacobian(monkeypatch):
    """The mount's light at the five displacements, computed once per position, equals each scene's own."""
    scenes = [denali_scene(o, "8in", p, mount=True, mount_in_background=False, albedo=0.4, diffuse_albedo=0.2)
              for o in ("A", "S") for p in (0, 47)]
    nuis = ("photon_scale", "albedo")
    theta = [0.001, -0.002, 0.05, 0.1]
    lam, jac, *_ = counts_and_jacobian(scenes, SENSOR, fidelity=FID, nuisance=nuis, theta=theta)
    # the mount and its plate: 2 poses under 4 scenes
    assert FastSimulator(scenes, SENSOR, fidelity=FID).shared_terms() is not None
    monkeypatch.setattr(FastSimulator, "shared_terms", lambda self: None)
    own, own_jac, *_ = counts_and_jacobian(scenes, SENSOR, fidelity=FID, nuisance=nuis, theta=theta)
    np.testing.assert_allclose(lam, own, rtol=1e-12, atol=1e-9)
    scale = np.abs(own_jac).max(axis=(0, 1, 2))
    assert np.all(scale > 0)
    np.testing.assert_allclose(jac, own_jac, rtol=1e-6, atol=1e-6 * scale.max())


def test_slopes_take_the_side_without_a_jump_and_average_a_smooth_pair():
    h = 1e-8
    lam0 = np.array([100.0, 100.0, 100.0, 100.0])
    # smooth (slope 3, curvature), jump of 0.5 between 0 and +h, jump between -h and 0, a kink (slope 3 | 5)
    up = lam0 + np.array([3 * h + 1e-14, 3 * h + 0.5, 3 * h, 5 * h])
    down = lam0 - np.array([3 * h - 1e-14, 3 * h, 3 * h + 0.5, 3 * h])
    got = np.asarray(_slopes(lam0, up, down, h))
    np.testing.assert_allclose(got, [3.0, 3.0, 3.0, 3.0], rtol=1e-5)
    # a jump's central difference would be 0.5 / 2e-8 = 2.5e7 counts per metre
    assert np.all(np.abs(got) < 10)


def test_position_parameters_translate_the_object_pose():
    shift = np.array([0.005, -0.003, 0.0])
    lam, *_ = counts_and_jacobian(SCENE, SENSOR, fidelity=FID, nuisance=NUIS, theta=[shift[0], shift[1], 0.0, 0.0])
    obj = SCENE.objects[0]
    pose = np.array(obj.to_world)
    pose[:3, 3] += shift
    moved = SCENE.replace(objects=(dataclasses.replace(obj, to_world=pose),))
    direct = FastSimulator(moved, SENSOR, fidelity=FID, dtype="float64").expected().reshape(lam.shape[1:])
    np.testing.assert_allclose(lam[0], direct, rtol=1e-9, atol=1e-9)


# ----------------------------------------------------------------------------- the bound on a DENALI scene
def test_bound_scales_as_one_over_sqrt_photons():
    base = localization_crlb(SCENE, SENSOR, fidelity=FID, nuisance=NUIS)
    more = localization_crlb(SCENE, SENSOR.replace(iterations=SENSOR.iterations * 100), fidelity=FID, nuisance=NUIS)
    assert base.position_identifiable and base.identifiable
    # ambient light does not change a lights-off capture: left out with a note
    assert base.parameters == ("x", "y", "log_photon_scale")
    assert any("ambient" in n and "lights off" in n for n in base.notes)
    # every mean (signal, dark) scales with the iterations: the information is exactly proportional
    assert more.rmse_bound_known_m == pytest.approx(base.rmse_bound_known_m / 10, rel=0.01)
    assert more.rmse_bound_m == pytest.approx(base.rmse_bound_m / 10, rel=0.01)
    # the photon scale scales only the signal: exact with no background and the nuisance known
    dark0 = SENSOR.replace(dark_rate_hz=0.0)
    one = localization_crlb(SCENE, dark0, fidelity=FID, nuisance=NUIS)
    four = localization_crlb(SCENE, dark0.replace(photon_scale=4 * dark0.photon_scale), fidelity=FID, nuisance=NUIS)
    assert four.rmse_bound_known_m == pytest.approx(one.rmse_bound_known_m / 2, rel=0.01)
    rep = localization_crlb(SCENE, SENSOR, fidelity=FID, nuisance=NUIS, repeats=9)
    assert rep.rmse_bound_m == pytest.approx(base.rmse_bound_m / 3, rel=1e-9)


def test_estimated_nuisance_bound_is_at_least_the_known_one(lights_on):
    full = localization_crlb(lights_on, SENSOR, fidelity=FID, nuisance=ALL)
    assert full.parameters == ("x", "y", "log_photon_scale", "log_ambient", "log_dark", "log_albedo")
    # ambient and dark both add a flat floor: flagged as a pair, the position bound stays finite
    assert not full.identifiable and "ambient" in full.reason and "dark" in full.reason
    assert full.position_identifiable and full.rmse_bound_m >= full.rmse_bound_known_m
    # the bound with fewer unknowns is the sub-block's: more unknowns never help
    prev = None
    for keep in ([0, 1], [0, 1, 2], [0, 1, 2, 3], [0, 1, 2, 3, 5]):
        names = tuple(full.parameters[k] for k in keep)
        est = analyse_fisher(full.fisher[np.ix_(keep, keep)], names)
        assert est["identifiable"], est["reason"]
        var = np.diag(est["covariance"])
        assert np.all(var >= np.diag(full.covariance_known_m2) * (1 - 1e-9))
        if prev is not None:
            assert np.all(var >= prev * (1 - 1e-9))
        prev = var
    r = localization_crlb(lights_on, SENSOR, fidelity=FID, nuisance=ALL[:2])
    assert r.identifiable and r.rmse_bound_m >= r.rmse_bound_known_m * (1 - 1e-9)
    assert np.all(r.std_m >= r.std_known_m * (1 - 1e-9)) and r.nuisance_price >= 1 - 1e-9
    np.testing.assert_allclose(r.fisher, full.fisher[:4, :4], rtol=1e-9)
    assert r.seconds > 0 and r.fidelity == "draft" and r.knobs["object_samples"] == 64


# ----------------------------------------------------------------------------- unidentifiable configurations
def _assert_flagged(r, needle):
    assert not r.identifiable and not r.position_identifiable
    assert math.isinf(r.rmse_bound_m) and needle in r.reason
    assert "NOT IDENTIFIABLE" in r.summary() and "e+" not in r.summary().split("[")[0]


def test_object_beyond_the_time_window_is_flagged():
    scene = corner_scene(object_xy=(0.45, 10.0), wall_size=(20.0, 10.0))
    r = localization_crlb(scene, SENSOR, fidelity=FID)
    _assert_flagged(r, "x is not identifiable: zero information")
    assert "y is not identifiable" in r.reason and math.isinf(r.rmse_bound_known_m)
    assert r.null_directions[:2] == [{"x": 1.0}, {"y": 1.0}]


def test_zero_photons_are_flagged():
    r = localization_crlb(SCENE, SENSOR.replace(photon_scale=0.0), fidelity=FID, nuisance=NUIS)
    _assert_flagged(r, "zero information")
    assert any("photon_scale left out" in n for n in r.notes)


def test_photon_scale_and_albedo_are_flagged_as_a_pair_without_the_direct_return():
    # window starting after the relay wall's first bounce: the photon scale and the albedo both only scale
    # the object's return
    late = SENSOR.replace(pulse_shape=None, pulse_fwhm_ps=187.0, start_offset_ps=5000.0)
    r = localization_crlb(SCENE, late, fidelity=FID, nuisance=("photon_scale", "albedo"))
    assert not r.identifiable and "not separately identifiable" in r.reason
    assert "photon_scale" in r.reason and "albedo" in r.reason
    assert set(r.null_directions[0]) == {"log_photon_scale", "log_albedo"}
    # the null direction has no position component: the position bound stays finite and honest
    assert r.position_identifiable and math.isfinite(r.rmse_bound_m)
    only_scale = analyse_fisher(r.fisher[:3, :3], r.parameters[:3])
    assert r.covariance_m2 == pytest.approx(only_scale["covariance"], rel=1e-6)


def test_direct_return_calibrates_the_photon_scale_apart_from_the_albedo(lights_on):
    # with the relay wall's first bounce in the window, the photon scale is measured by it
    r = localization_crlb(lights_on, SENSOR, fidelity=FID, nuisance=ALL)
    keep = [0, 1, 2, 5]
    out = analyse_fisher(r.fisher[np.ix_(keep, keep)], tuple(r.parameters[k] for k in keep))
    assert out["identifiable"] and out["condition_number"] < 1e4


def test_analyse_fisher_flags_a_null_direction_that_leaks_into_the_position():
    f = np.array([[1.0, 0.0, 1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 1.0]])  # x and the nuisance are collinear
    out = analyse_fisher(f, ("x", "y", "log_albedo"))
    assert not out["position_identifiable"] and math.isinf(out["covariance"][0, 0])
    assert out["covariance"][1, 1] == pytest.approx(1.0)
    assert "x and albedo are not separately identifiable" in out["reason"]
    bad = analyse_fisher(np.full((2, 2), np.nan), ("x", "y"))
    assert not bad["position_identifiable"] and "not finite" in bad["reason"]


# ----------------------------------------------------------------------------- batch and inputs
def test_batch_equals_single_scenes_and_reports_the_rms():
    scenes = [denali_scene("A", "8in", p) for p in (3, 19, 77)]
    batch = localization_crlb_batch(scenes, SENSOR, fidelity=FID, nuisance=NUIS, chunk=2)
    singles = [localization_crlb(s, SENSOR, fidelity=FID, nuisance=NUIS) for s in scenes]
    for b, s in zip(batch.results, singles):
        # a batch's plan covers all its scenes (its pruning and near-wall cells differ by ~1e-3 at draft)
        np.testing.assert_allclose(b.fisher, s.fisher, rtol=5e-3)
        assert b.meta["position"] == s.meta["position"]
    expect = math.sqrt(np.mean([b.rmse_bound_m**2 for b in batch.results]))
    assert batch.rms_bound_m == pytest.approx(expect, rel=1e-12) and batch.unidentifiable == []
    assert batch.rms_bound_m == pytest.approx(math.sqrt(np.mean([s.rmse_bound_m**2 for s in singles])), rel=5e-3)
    assert batch.seconds > 0 and "CRLB RMS over 3 scenes" in batch.summary()


def test_bad_inputs_are_user_errors():
    with pytest.raises(UserError, match="nuisance"):
        localization_crlb(SCENE, SENSOR, nuisance=("gain",))
    with pytest.raises(UserError, match="orthogonal"):
        localization_crlb(SCENE, SENSOR, axes=[[1, 0, 0], [1, 1e-3, 0]])
    with pytest.raises(UserError, match="repeats"):
        poisson_fisher([1.0], [[1.0]], repeats=0)
