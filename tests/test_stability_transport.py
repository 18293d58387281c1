"""The transport cases of the stability catalog: every case passes, and the catalog can fail."""

import numpy as np
import pytest

from nlosplan._jax import jnp
from nlosplan.simulators.fast import plan_object
from nlosplan.simulators.fast import stability_cases as sc
from nlosplan.stability import all_cases, run_cases

@pytest.fixture
def fresh_cache():
    """Empty the case module's simulator caches before and after (monkeypatched code must be re-planned)."""
    sc.clear_caches()
    yield
    sc.clear_caches()


@pytest.mark.parametrize("case", [pytest.param(c, marks=pytest.mark.slow) if c.name == "gradients-transport" else c
                                  for c in sc.CASES], ids=[c.name for c in sc.CASES])   # that one 76 s; CI runs it
def test_case_passes(case):
    (res,) = run_cases([case])
    assert res.passed, f"{res.name}: {res.detail}"
    assert res.detail and "\n" not in res.detail


def test_catalog_includes_the_transport_cases():
    names = [c.name for c in all_cases()]
    assert all(c.name in names for c in sc.CASES)
    assert len(set(names)) == len(names), "case names must be unique"


# ------------------------------------------------------------ the catalog can fail
def _fake_near_wall(growth):
    """Object parts shaped like the near-wall batch: (lateral, height, zones, bins)."""
    nx, nh = len(sc.LATERAL), len(sc.HEIGHTS)
    obj = np.zeros((nx, nh, 9, 4))
    for j, h in enumerate(sc.HEIGHTS):
        obj[:, j, :, 0] = growth(h)
    direct = np.full_like(obj, 1e9)
    return {"object": obj, "direct": direct, "counts": obj + direct, "floor": np.zeros_like(obj),
            "crosstalk": np.zeros_like(obj)}


def _in_view_bounded(fake):
    fake["object"][0] = 1.0  # in view: a bounded limit
    return fake


def test_near_wall_check_accepts_the_physical_laws():
    ok, detail = sc.near_wall_check(_in_view_bounded(_fake_near_wall(lambda h: h**2)), "lambertian")
    assert ok, detail
    assert "(h^2.0)" in detail
    ok, detail = sc.near_wall_check(_in_view_bounded(_fake_near_wall(lambda h: h**3)), "retroreflective")
    assert ok, detail


@pytest.mark.parametrize("law", [lambda h: h**-4, lambda h: h**4, lambda h: h**0.5], ids=["1/h^4", "h^4", "h^0.5"])
def test_near_wall_check_rejects_wrong_laws_out_of_view(law):
    ok, detail = sc.near_wall_check(_in_view_bounded(_fake_near_wall(law)), "lambertian")
    assert not ok and "FAIL" in detail


def test_near_wall_check_rejects_an_unbounded_in_view_return():
    # in view the return must tend to a bounded limit: growing 4x from 5 to 2 mm is out of band
    fake = _fake_near_wall(lambda h: h**2)
    fake["object"][0] = (1 / np.array(sc.HEIGHTS) ** 2)[:, None, None]
    ok, detail = sc.near_wall_check(fake, "lambertian")
    assert not ok and "FAIL" in detail.split(";")[0]


def test_near_wall_check_rejects_nan():
    fake = _in_view_bounded(_fake_near_wall(lambda h: h**2))
    fake["counts"][1, 0, 0, 0] = np.nan
    ok, _ = sc.near_wall_check(fake, "lambertian")
    assert not ok


def test_dynamic_range_check_rejects_a_float32_error():
    rng = np.random.default_rng(1)
    obj = rng.uniform(1.0, 10.0, (9, 128))
    zero = np.zeros_like(obj)
    o64 = {"object": obj, "counts": obj + 1e6, "direct": np.full_like(obj, 1e6), "floor": zero}
    assert sc.dynamic_range_check(o64, dict(o64))[0]
    ok, detail = sc.dynamic_range_check(o64, {**o64, "object": obj * (1 + 1e-2)})
    assert not ok and "object 1.0e-02" in detail
    # a 2-count error in the counts under a 1e6-count tail: 2e-6 relative, but 2e-3 of the Poisson noise
    ok, detail = sc.dynamic_range_check(o64, {**o64, "counts": o64["counts"] + 2.0})
    assert not ok and "signal 2.0e-03" in detail


def test_coupling_case_fails_when_the_exact_kernel_is_wrong(monkeypatch):
    monkeypatch.setattr(sc, "polygon_coupling", lambda x, n, k: jnp.full((x.shape[0], k.shape[0]), jnp.nan))
    passed, detail = sc._coupling_singularity()
    assert not passed and "nan" in detail


def test_near_wall_case_fails_without_the_exact_form_factor(monkeypatch, fresh_cache):
    """With the midpoint kernel everywhere (no near-field cells) the in-view return grows ~4x from 5 to 2 mm
    and an out-of-view one falls as h^4 (the wall under the patch no longer lights it with a bounded pi L;
    which lateral offset shows it first depends on how finely the flash cells tile the wall there)."""
    monkeypatch.setattr(plan_object, "NEAR_CELLS", 0.0)
    passed, detail = sc._near_wall("lambertian")()
    assert not passed
    by_x = {part.split(":")[0]: part for part in detail.split("mm: ", 1)[1].split("; ") if part.startswith("x=")}
    assert "FAIL" in by_x["x=0 m (in view)"], detail
    assert any("FAIL" in part for x, part in by_x.items() if x != "x=0 m (in view)"), detail


def test_gradient_case_fails_on_nan(monkeypatch, fresh_cache):
    monkeypatch.setattr(sc, "GRADIENT_SCENARIOS", ("zero-area",))
    forward = sc.forward
    monkeypatch.setattr(sc, "forward", lambda *a, **k: forward(*a, **k) * jnp.sqrt(-1.0))
    passed, detail = sc._gradients()
    assert not passed and "NON-FINITE zero-area" in detail
