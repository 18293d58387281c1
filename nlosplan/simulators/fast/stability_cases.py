"""Stability-catalog cases for the fast three-bounce transport (see DESIGN.md).

Each case returns ``(passed, measured)``; :data:`CASES` lists them. Scenes
are small (a 5 cm patch, the DENALI rig at a cheap fidelity) so the whole
list runs in ``nlosplan check``; simulators are built once and shared with
the gradient case through :func:`_scenario`.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from nlosplan._jax import jax, jnp
from nlosplan.errors import UserError
from nlosplan.sensor_models.presets import preset
from nlosplan.simulators.fast.coupling import far_coupling, polygon_coupling
from nlosplan.simulators.fast.fidelity import Fidelity
from nlosplan.simulators.fast.simulator import FastSimulator, to_jax
from nlosplan.simulators.fast.stability_scene import mixed, mount_near_wall_check, mount_near_wall_scenes
from nlosplan.simulators.fast.transport import forward
from nlosplan.simulators.presets import corner_scene, denali_scene
from nlosplan.simulators.scene import HiddenObject, LidarPose, Mesh
from nlosplan.cases import Case

#: Cheap quadrature where accuracy is not the point (draft-like; flash_outer 3 keeps the outer flash cells
#: finer than the 5 cm patch's distance to the field of view).
FID = Fidelity(zone_sub=2, flash_sub=2, flash_outer=3, object_samples=64, time_oversample=2)
#: Object heights above the wall for the near-wall cases, metres.
HEIGHTS = (0.001, 0.002, 0.005)
#: Lateral patch positions: 0 is inside the field of view (both legs in the near field); the others are
#: outside it (0.2 m: 2.7 cm beyond the FoV edge; the wall under the patch is lit by the flash's tails and the zones
#: see the patch only at grazing angles).
LATERAL = (0.0, 0.2, 0.3, 0.45, 0.5)


def _base_sensor():
    return preset("tmf8828-3x3-short")


def _ok(a) -> bool:
    a = np.asarray(a)
    return bool(a.size > 0 and np.all(np.isfinite(a)) and np.all(a >= 0))


def _all_ok(out: dict) -> bool:
    return all(_ok(v) for v in out.values())


def _moved(scene, xyz):
    """``scene`` with its (single) object translated to ``xyz``, same mesh (so scenes batch)."""
    obj = scene.objects[0]
    m = np.array(obj.to_world)
    m[:3, 3] = xyz
    return scene.replace(objects=(obj.moved_to(m),))


def _yawed(scene, yaw_deg: float):
    """``scene`` with its (single) object turned by ``yaw_deg`` about the vertical through its centre."""
    obj = scene.objects[0]
    c, s = math.cos(math.radians(yaw_deg)), math.sin(math.radians(yaw_deg))
    m = np.array(obj.to_world)
    m[:3, :3] = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ m[:3, :3]
    return scene.replace(objects=(obj.moved_to(m),))


def _facing_wall_patch(size: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
    """Square patch vertices and faces with normal -z: under the mesh convention of
    :func:`corner_scene` (mesh -z looks at the wall) it faces the wall."""
    h = size / 2
    v = np.array([[-h, -h, 0.0], [h, -h, 0.0], [h, h, 0.0], [-h, h, 0.0]])
    f = np.array([[0, 2, 1], [0, 3, 2]])
    return v, f


# --------------------------------------------------------------- scenarios
def _near_wall_scenes(reflectance: str):
    base = corner_scene(object_xy=(0.45, HEIGHTS[0]), object_size=0.05, reflectance=reflectance)
    return [_moved(base, (x, -h, 0.0)) for x in LATERAL for h in HEIGHTS]


def _edge_on_scenes(reflectance: str):
    """A 10 cm patch 0.3 m from the wall, face-on and turned 89.9 deg (its face almost perpendicular to the wall)."""
    base = corner_scene(object_xy=(0.45, 0.3), reflectance=reflectance)
    return [base, _yawed(base, 89.9)]


def _one_mm_scenes(reflectance: str):
    return [s for s in _near_wall_scenes(reflectance) if s.objects[0].to_world[1, 3] == -HEIGHTS[0]]


def _grazing_wall_scene():
    """The LiDAR 0.5 m from the wall centre, its optical axis 85 deg from the wall normal."""
    base = corner_scene(wall_size=(8.0, 2.0), object_xy=(0.45, 0.3))
    a = math.radians(85.0)
    lidar = LidarPose.look_at((-0.5 * math.sin(a), -0.5 * math.cos(a), 0.0), (0.0, 0.0, 0.0))
    return base.replace(lidar=lidar)


def _degenerate_mesh():
    v, f = _facing_wall_patch()
    # extra vertices: the midpoint of edge 0-1 (collinear with it) and the centre, used only by degenerate faces
    v = np.concatenate([v, [0.5 * (v[0] + v[1]), [0.0, 0.0, 0.0]]])
    bad = np.array([[0, 0, 1], [0, 4, 1], [2, 2, 2], [5, 5, 3], [1, 4, 0]])  # repeated vertices, collinear
    faces = np.concatenate([bad[:2], f[:1], bad[2:4], f[1:], bad[4:]])
    return Mesh(vertices=v, faces=faces, name="patch+degenerate")


def _clean_mesh():
    v, f = _facing_wall_patch()
    return Mesh(vertices=v, faces=f, name="patch")


def _tail_scene():
    return corner_scene(object_xy=(0.2, 0.05), reflectance="retroreflective", albedo=5e-5)


def _zones_fidelity(n: int) -> Fidelity:
    """Flash cells on the same 48 x 48 tangent grid inside the FoV whatever the zone grid."""
    return Fidelity(zone_sub=2, flash_sub=48 // n, flash_outer=3, object_samples=64, time_oversample=2)


def _dynamic_range_sensor(s):
    # direct peak ~1e7 counts: ~345x the preset's photon budget; no 24-bit clip
    return s.replace(iterations=190_000_000, saturation=False)


_SCENARIOS = {
    # name: () -> (scenes, sensor, fidelity, dtype)
    "near-wall-lambertian": lambda: (_near_wall_scenes("lambertian"), _base_sensor(), "default", "float64"),
    "near-wall-retro": lambda: (_near_wall_scenes("retroreflective"), _base_sensor(), "default", "float64"),
    # the gradient check's 1 mm scenes (in view and out of view) at the cheap fidelity
    "near-wall-1mm": lambda: (_one_mm_scenes("lambertian"), _base_sensor(), FID, "float64"),
    "near-wall-1mm-retro": lambda: (_one_mm_scenes("retroreflective"), _base_sensor(), FID, "float64"),
    "near-wall-mixed": lambda: (mixed(_near_wall_scenes("retroreflective")), _base_sensor(), "default", "float64"),
    "near-wall-1mm-mixed": lambda: (mixed(_one_mm_scenes("retroreflective")), _base_sensor(), FID, "float64"),
    "edge-on-mixed": lambda: (mixed(_edge_on_scenes("retroreflective")), _base_sensor(), FID, "float64"),
    "mount-near-wall": lambda: (mount_near_wall_scenes(HEIGHTS), _base_sensor(), FID, "float64"),
    "beyond-window": lambda: (corner_scene(object_xy=(0.45, 10.0), wall_size=(20.0, 10.0)), _base_sensor(), FID,
                              "float64"),
    "beyond-window-background": lambda: (corner_scene(object_xy=(0.45, 10.0), wall_size=(20.0, 10.0))
                                         .without_objects(), _base_sensor(), FID, "float64"),
    "edge-on": lambda: (_edge_on_scenes("lambertian"), _base_sensor(), FID, "float64"),
    "grazing-wall": lambda: (_grazing_wall_scene(), _base_sensor(), FID, "float64"),
    "zero-area": lambda: (corner_scene(object=_degenerate_mesh(), object_xy=(0.45, 0.3)), _base_sensor(), FID,
                          "float64"),
    "zero-area-clean": lambda: (corner_scene(object=_clean_mesh(), object_xy=(0.45, 0.3)), _base_sensor(), FID,
                                "float64"),
    # the zone grids compare the transport's object counts summed over zones: a linear sensor alike in every zone
    # (the 3x3 preset's per-zone gains, pile-up and time walk belong to one unit's 3x3 layout)
    "zones-1x1": lambda: (denali_scene(), _base_sensor().linear_uniform().replace(zones_rows=1, zones_cols=1),
                          _zones_fidelity(1), "float64"),
    "zones-3x3": lambda: (denali_scene(), _base_sensor().linear_uniform(), _zones_fidelity(3), "float64"),
    "zones-16x16": lambda: (denali_scene(), _base_sensor().linear_uniform().replace(zones_rows=16, zones_cols=16),
                            _zones_fidelity(16), "float64"),
    "fov-1deg": lambda: (denali_scene(), _base_sensor().replace(fov_x_deg=1.0, fov_y_deg=1.0), FID, "float64"),
    "fov-33deg": lambda: (denali_scene(), _base_sensor(), FID, "float64"),
    "fov-120deg": lambda: (denali_scene(), _base_sensor().replace(fov_x_deg=120.0, fov_y_deg=120.0), FID,
                           "float64"),
    "dynamic-range-f64": lambda: (denali_scene(albedo=0.001), _dynamic_range_sensor(_base_sensor()), FID, "float64"),
    "dynamic-range-f32": lambda: (denali_scene(albedo=0.001), _dynamic_range_sensor(_base_sensor()), FID, "float32"),
    # a ~10-count return 5 cm behind the wall, inside the measured pulse's tail (~1e6 counts) of the direct peak
    "dynamic-range-tail-f64": lambda: (_tail_scene(), _dynamic_range_sensor(_base_sensor()), FID, "float64"),
    "dynamic-range-tail-f32": lambda: (_tail_scene(), _dynamic_range_sensor(_base_sensor()), FID, "float32"),
}


@lru_cache(maxsize=None)
def _scenario(name: str, jitter_ps: float | None = None) -> FastSimulator:
    """The simulator of a named scenario (built once), optionally with another jitter."""
    scenes, sensor, fidelity, dtype = _SCENARIOS[name]()
    if jitter_ps is not None:
        sensor = sensor.replace(jitter_fwhm_ps=jitter_ps)
    return FastSimulator(scenes, sensor, fidelity=fidelity, dtype=dtype)


@lru_cache(maxsize=None)
def _parts(name: str) -> dict:
    return _scenario(name).expected(parts=True)


def clear_caches() -> None:
    """Forget the simulators and results built so far (after changing the simulator's code or constants)."""
    for f in (_scenario, _parts, _gradient_of):
        f.cache_clear()


def _zones_without_wall(sim: FastSimulator) -> int:
    """Zones none of whose sub-rays reach the relay wall first."""
    s = sim.plan.sensor
    w = np.asarray(sim.plan.arrays["direct_w"]).reshape(len(sim.plan.zones), -1)
    return int(np.sum(w.sum(axis=1) <= 0)) if sim.plan.static.direct else s.n_zones


# --------------------------------------------------------------- 1. near the wall
def _coupling_singularity():
    h = 1e-3
    x = jnp.array([[0.0, 0.0, h]])
    n = jnp.array([[0.0, 0.0, -1.0]])
    square = jnp.array([[[-0.5, -0.5, 0.0], [0.5, -0.5, 0.0], [0.5, 0.5, 0.0], [-0.5, 0.5, 0.0]]])
    exact = float(polygon_coupling(x, n, square)[0, 0])
    mid = float(far_coupling(jnp.zeros((3, 1)), jnp.ones(1), x, n, jnp.array([h]))[0][0, 0])
    ok = math.isfinite(exact) and abs(exact - math.pi) < 1e-3 and math.isfinite(mid) and mid > 1e5
    return ok, (f"point 1 mm above a 1 m square: exact polygon coupling {exact:.6f} (pi - {math.pi - exact:.1e}); "
                f"midpoint kernel for the same cell {mid:.4g} (A/h^2)")


def near_wall_check(out: dict, reflectance: str) -> tuple[bool, str]:
    """Judge the object parts of :func:`_near_wall_scenes` (batch axis: lateral x major, height minor).

    In view (x = 0) both legs are in the near field: the exact form factor keeps the return bounded, so it
    changes by less than 2x from 5 to 2 mm and from 2 to 1 mm. Out of view the patch exchanges light with the
    zones only at grazing angles (cos at the patch ~ h/d) while the wall under it lights it with a bounded
    pi L: the return falls as h^p from 2 to 1 mm with 1 <= p <= 3.5 (p = 2 Lambertian; up to 3 for a
    retroreflector whose lobe is stretched at grazing incidence) and does not grow from 5 to 2 mm. A kernel
    that follows 1/d^4 near the wall makes it grow instead (p < 0); the midpoint rule under the patch makes
    it fall as h^4.
    """
    obj = np.asarray(out["object"]).reshape(len(LATERAL), len(HEIGHTS), -1).sum(-1)
    direct = float(np.asarray(out["direct"]).reshape(len(LATERAL), len(HEIGHTS), -1).sum(-1).min())
    ok = _all_ok(out) and bool(np.all(obj <= direct))
    parts = []
    for i, x in enumerate(LATERAL):
        o1, o2, o5 = (float(v) for v in obj[i])
        if x == 0.0:
            good = all(o > 0 for o in (o1, o2, o5)) and 0.5 <= o1 / o2 <= 2.0 and 0.5 <= o2 / o5 <= 2.0
            law = ""
        else:
            p = math.log(o2 / o1) / math.log(HEIGHTS[1] / HEIGHTS[0]) if o1 > 0 and o2 > 0 else math.nan
            good = 1.0 <= p <= 3.5 and o2 <= o5
            law = f" (h^{p:.1f})"
        ok &= bool(good)
        parts.append(f"x={x:g} m{' (in view)' if x == 0 else ''}: {o1:.3g}/{o2:.3g}/{o5:.3g}{law}"
                     f"{'' if good else ' <- FAIL'}")
    return ok, f"{reflectance} object counts at 1/2/5 mm: " + "; ".join(parts) + f"; all <= direct {direct:.3g}"


def _near_wall(reflectance: str):
    name = {"lambertian": "near-wall-lambertian", "retroreflective": "near-wall-retro", "mixed": "near-wall-mixed"}[
        reflectance]
    label = "mixed (retroreflective 0.5 + Lambertian 0.5)" if reflectance == "mixed" else reflectance
    return lambda: near_wall_check(_parts(name), label)


# --------------------------------------------------------------- 2. beyond the window
def _beyond_window():
    sim = _scenario("beyond-window")
    h = np.asarray(sim.expected())
    bg = np.asarray(_scenario("beyond-window-background").expected())
    left = [t.reason for t in sim.plan.terms if not t.computed and "time window" in t.reason]
    rel = float(np.abs(h - bg).max() / bg.max())
    # the pruning decision is right: the unpruned object part is zero in the window
    full = FastSimulator(sim.scenes, sim.plan.sensor, fidelity=FID, dtype="float64", prune=False)
    obj_full = float(np.asarray(full.expected(parts=True)["object"]).max())
    ok = bool(left) and not sim.plan.static.objects and _ok(h) and rel <= 1e-6 and obj_full <= 1e-6 * bg.max()
    why = left[0] if left else "object term NOT left out"
    return ok, (f"{why}; |h - background| max rel {rel:.1e}; unpruned object part max {obj_full:.1e} counts")


# --------------------------------------------------------------- 3. grazing
def _edge_on(name: str = "edge-on", what: str = "Lambertian"):
    def run():
        out = _parts(name)
        obj = np.asarray(out["object"]).reshape(2, -1).sum(-1)
        return _all_ok(out) and obj[1] > 0, (f"{what} 10 cm patch 0.3 m from the wall: object {obj[0]:.3g} counts "
                                             f"face-on, {obj[1]:.3g} turned 89.9 deg (its face looks along the wall, "
                                             "towards the field of view); all finite, >= 0")

    return run


def _fov120_zones():
    sim = _scenario("fov-120deg")
    out = _parts("fov-120deg")
    miss = _zones_without_wall(sim)
    sub = np.asarray(sim.plan.arrays["direct_w"])
    return _all_ok(out) and miss > 0, (f"DENALI rig, 120 deg FoV: {miss} of {sim.plan.sensor.n_zones} zones miss the "
                                       f"wall, {int(np.sum(sub <= 0))} of {sub.size} sub-rays; object "
                                       f"{float(out['object'].sum()):.3g} counts; all finite, >= 0")


def _grazing_wall():
    sim = _scenario("grazing-wall")
    out = _parts("grazing-wall")
    w = np.asarray(sim.plan.arrays["direct_w"])
    return _all_ok(out) and bool(np.any(w <= 0)), (
        f"LiDAR axis 85 deg from the wall normal: {int(np.sum(w <= 0))} of {w.size} sub-rays miss the wall; "
        f"direct {float(out['direct'].sum()):.3g}, object {float(out['object'].sum()):.3g} counts; finite, >= 0")


# --------------------------------------------------------------- 4. zero-area triangles
def _zero_area():
    a, b = _parts("zero-area"), _parts("zero-area-clean")
    oa, ob = np.asarray(a["object"]), np.asarray(b["object"])
    rel = float(np.abs(oa - ob).max() / ob.max())
    rel_total = float(np.abs(np.asarray(a["counts"]) - np.asarray(b["counts"])).max() / np.asarray(b["counts"]).max())
    n_bad = int(np.sum(_degenerate_mesh().face_areas == 0))
    return _all_ok(a) and rel <= 1e-6 and rel_total <= 1e-6, (
        f"{n_bad} zero-area faces (repeated, collinear vertices) among 2 real ones: object part differs from the "
        f"clean patch by {rel:.1e} of its max, counts by {rel_total:.1e}")


# --------------------------------------------------------------- 5. zone grids
def _zone_grids():
    totals, ok = {}, True
    for n in (1, 3, 16):
        out = _parts(f"zones-{n}x{n}")
        ok &= _all_ok(out)
        totals[n] = float(np.asarray(out["object"]).sum())
    ref = totals[3]
    spread = max(abs(v - ref) for v in totals.values()) / ref
    ok &= spread <= 1e-6
    return ok, ("object counts summed over zones, same 48x48 flash grid: "
                + ", ".join(f"{n}x{n} {v:.6g}" for n, v in totals.items()) + f"; max rel diff {spread:.1e}")


# --------------------------------------------------------------- 6. field of view
def _fov(name: str):
    def run():
        out = _parts(name)
        obj = float(np.asarray(out["object"]).sum())
        ref = float(np.asarray(_parts("fov-33deg")["object"]).sum())
        sim = _scenario(name)
        ok = _all_ok(out) and obj >= 0
        if name == "fov-1deg":
            ok &= obj < 0.01 * ref
        return ok, (f"{sim.plan.sensor.fov_x_deg:g} deg FoV: object {obj:.3g} counts (33 deg: {ref:.3g}), "
                    f"{_zones_without_wall(sim)} of {sim.plan.sensor.n_zones} zones miss the wall; finite, >= 0")

    return run


# --------------------------------------------------------------- 7. float32 next to a huge peak
def dynamic_range_check(o64: dict, o32: dict, rtol: float = 1e-3) -> tuple[bool, str]:
    """Compare float32 and float64 parts in the bins where the object part exceeds 1e-3 of its max.

    The object part and the counts must agree to ``rtol`` (relative); the signal a user extracts,
    ``counts - direct - floor``, must agree to ``rtol`` of the Poisson noise ``sqrt(counts)`` (float32
    cannot resolve a 0.1-count return under 1e6 counts of a pulse tail, and need not).
    """
    obj64, obj32 = np.asarray(o64["object"], np.float64), np.asarray(o32["object"], np.float64)
    c64, c32 = np.asarray(o64["counts"], np.float64), np.asarray(o32["counts"], np.float64)
    sig64 = c64 - np.asarray(o64["direct"], np.float64) - np.asarray(o64["floor"], np.float64)
    sig32 = c32 - np.asarray(o32["direct"], np.float64) - np.asarray(o32["floor"], np.float64)
    sel = obj64 > 1e-3 * obj64.max()
    e_obj = float(np.max(np.abs(obj32[sel] - obj64[sel]) / obj64[sel]))
    e_cnt = float(np.max(np.abs(c32[sel] - c64[sel]) / c64[sel]))
    e_sig = float(np.max(np.abs(sig32[sel] - sig64[sel]) / np.sqrt(c64[sel])))
    ok = _all_ok(o32) and _all_ok(o64) and e_obj <= rtol and e_cnt <= rtol and e_sig <= rtol
    peak = float(np.asarray(o64["direct"]).max())
    under = float(np.asarray(o64["direct"], np.float64)[sel].max())
    return ok, (f"direct peak {peak:.2g}, object max {obj64.max():.3g} in {int(sel.sum())} bins under up to "
                f"{under:.2g} direct counts: f32 vs f64 rel diff object {e_obj:.1e}, counts {e_cnt:.1e}, signal "
                f"{e_sig:.1e} of sqrt(counts)")


def _dynamic_range():
    ok1, m1 = dynamic_range_check(_parts("dynamic-range-f64"), _parts("dynamic-range-f32"))
    ok2, m2 = dynamic_range_check(_parts("dynamic-range-tail-f64"), _parts("dynamic-range-tail-f32"))
    return ok1 and ok2, f"DENALI: {m1}; corner, return in the pulse tail: {m2} (tolerance 1e-3)"


# --------------------------------------------------------------- 8. gradients
#: Scenarios of the gradient check (every scene of a batch: they share one compiled gradient). The sensor gets
#: 30 ps of jitter so the Gaussian impulse response, and its width, are traced.
GRADIENT_SCENARIOS = ("near-wall-1mm", "near-wall-1mm-retro", "near-wall-1mm-mixed", "beyond-window", "grazing-wall",
                      "zero-area", "zones-1x1", "zones-16x16", "fov-1deg", "fov-120deg")
GRADIENT_JITTER_PS = 30.0


def gradient_entries(sim: FastSimulator) -> np.ndarray:
    """d(weighted counts)/d(object translation x, y, z; jitter FWHM; bin width) of every scene, (N, 5), float64.

    The loss weights every zone and bin by a fixed pseudo-random number in [0.5, 1.5] (so the jitter
    derivative is not zero by conservation of counts). Reverse mode (``jax.grad``), as an optimizer uses it.
    """
    static = sim.plan.static
    arrays = to_jax(sim.plan.arrays, jnp.float64)
    scenes_p, sp = sim.params()
    scenes_p = to_jax(scenes_p, jnp.float64)
    sp = jax.tree_util.tree_map(lambda a: a[0], to_jax(sp, jnp.float64))
    w = jnp.asarray(np.random.default_rng(0).uniform(0.5, 1.5, (static.n_zones, sim.plan.sensor.n_bins)))

    def loss(v, arrays, sc, sp, w):
        objs = [dict(o) for o in sc["objects"]]
        if objs:
            objs[0]["to_world"] = objs[0]["to_world"].at[:3, 3].add(v[:3])
        sp = {**sp, "jitter_fwhm_ps": sp["jitter_fwhm_ps"] + v[3], "bin_width_ps": sp["bin_width_ps"] + v[4]}
        return jnp.sum(forward(static, arrays, {**sc, "objects": objs}, sp) * w)

    def one(i):
        return jax.tree_util.tree_map(lambda a: a[i], scenes_p)

    grad = _compile_cheaply(jax.jit(jax.grad(loss)), jnp.zeros(5), arrays, one(0), sp, w)
    return np.stack([np.asarray(grad(jnp.zeros(5), arrays, one(i), sp, w)) for i in range(len(sim.scenes))])


#: XLA options tried in turn for the one-off gradient programs. The transport's backward pass takes ~5-10 s
#: to compile on a 2-core CPU with the defaults and ~2-4 s without LLVM optimisation and the fusion emitters;
#: the gradients agree to 1e-10 and each program runs a handful of times, so its speed does not matter.
CHEAP_COMPILE = ({"xla_backend_optimization_level": 0, "xla_cpu_use_fusion_emitters": False},
                 {"xla_backend_optimization_level": 0})


def _compile_cheaply(jitted, *args):
    lowered = jitted.lower(*args)
    for options in CHEAP_COMPILE:
        try:
            return lowered.compile(compiler_options=options)
        except Exception:  # noqa: BLE001 - an option this JAX/XLA does not know: try the next, then the default
            continue
    return jitted


@lru_cache(maxsize=None)
def _gradient_of(name: str) -> np.ndarray:
    return gradient_entries(_scenario(name, GRADIENT_JITTER_PS))


def _gradients():
    bad, mags, n = [], [], 0
    for name in GRADIENT_SCENARIOS:
        g = _gradient_of(name)
        n += len(g)
        if not np.all(np.isfinite(g)):
            bad.append(f"{name}: {np.round(g, 3).tolist()}")
        mags.append(float(np.abs(g[:, :3]).max()))
    detail = (f"{n} scenes of {len(GRADIENT_SCENARIOS)} scenarios x (translation x, y, z; jitter; bin width), jitter "
              f"30 ps: " + ("all finite" if not bad else "NON-FINITE " + "; ".join(bad))
              + f"; max |d/d translation| per scenario from {min(mags):.2g} to {max(mags):.2g}")
    return not bad, detail


# --------------------------------------------------------------- 9-10. invalid input
def _one_line_error(make, must_contain: str):
    try:
        make()
    except UserError as exc:
        msg = str(exc)
        return (must_contain in msg and "\n" not in msg), msg
    return False, "accepted"


def _reject_bad_meshes():
    v, f = _facing_wall_patch()
    nan_v = v.copy()
    nan_v[2, 1] = np.nan
    ok1, m1 = _one_line_error(lambda: corner_scene(object=Mesh(vertices=nan_v, faces=f)), "finite")
    ok2, m2 = _one_line_error(lambda: Mesh(vertices=np.zeros((0, 3)), faces=np.zeros((0, 3), int)), "no vertices")
    ok3, m3 = _one_line_error(lambda: Mesh(vertices=v, faces=np.zeros((0, 3), int)), "no triangles")
    pose = np.eye(4)
    pose[0, 3] = np.nan
    ok4, m4 = _one_line_error(lambda: HiddenObject(mesh=Mesh(vertices=v, faces=f), to_world=pose), "finite")
    return ok1 and ok2 and ok3 and ok4, f"UserError: {m1} | {m2} | {m3} | {m4}"


def _reject_zones():
    s, sc = _base_sensor(), corner_scene()
    ok, msg = _one_line_error(lambda: FastSimulator(sc, s, zones=[(5, 5)]), "(5,5)")
    ok_e, _ = _one_line_error(lambda: FastSimulator(sc, s, zones=[]), "no zones")
    ok_d, _ = _one_line_error(lambda: FastSimulator(sc, s, zones=[(0, 0), (0, 0)]), "twice")
    return ok and ok_e and ok_d, f"UserError: {msg} (empty and repeated zone lists also rejected: {ok_e and ok_d})"


CASES: list[Case] = [
    Case("coupling-1mm", "exact wall coupling 1 mm above a 1 m square equals pi (1e-3); the midpoint kernel "
         "diverges (~1e6)", _coupling_singularity),
    Case("object-1mm-lambertian", "5 cm Lambertian patch 1, 2, 5 mm from the wall: finite, >= 0, <= direct; in "
         "view changes < 2x per step; out of view falls as h^p, 1 <= p <= 3.5 (grazing exchange), never grows",
         _near_wall("lambertian")),
    Case("object-1mm-retro", "5 cm retroreflective patch 1, 2, 5 mm from the wall: finite, >= 0, <= direct; in view "
         "changes < 2x per step; out of view falls as h^p, 1 <= p <= 3.5 (grazing exchange), never grows",
         _near_wall("retroreflective")),
    Case("object-1mm-mixed", "5 cm mixed patch (retroreflective 0.5 + Lambertian 0.5) 1, 2, 5 mm from the wall: "
         "finite, >= 0, <= direct; in view changes < 2x per step; out of view falls as h^p, 1 <= p <= 3.5",
         _near_wall("mixed")),
    Case("mount-1mm", "DENALI object with its mount and plate in the signal, 1, 2, 5 mm from the wall: finite, >= 0, "
         "<= direct, changes < 2x per step", lambda: mount_near_wall_check(_parts("mount-near-wall"), HEIGHTS)),
    Case("object-beyond-window", "object 10 m away: term left out for the time window, histogram equals the "
         "background (1e-6), unpruned object part 0 in the window", _beyond_window),
    Case("grazing-object", "patch turned 89.9 deg (face almost perpendicular to the wall): finite, >= 0", _edge_on()),
    Case("grazing-object-mixed", "mixed patch (retroreflective + Lambertian) turned 89.9 deg: finite, >= 0",
         _edge_on("edge-on-mixed", "mixed (retroreflective 0.5 + Lambertian 0.5)")),
    Case("grazing-fov-120deg", "120 deg FoV on the DENALI rig (zones miss the wall): finite, >= 0", _fov120_zones),
    Case("grazing-relay-wall", "LiDAR 85 deg from the wall normal (sub-rays miss it): finite, >= 0", _grazing_wall),
    Case("zero-area-triangles", "degenerate faces added to a patch: finite, equal to the clean patch (1e-6)",
         _zero_area),
    Case("zones-1-3-16-object", "1x1, 3x3, 16x16 zones on DENALI: finite, >= 0; object counts summed over zones "
         "agree (1e-6) on the same flash grid", _zone_grids),
    Case("fov-1deg-object", "1 deg FoV on DENALI: finite, object part >= 0 and < 1% of the 33 deg one",
         _fov("fov-1deg")),
    Case("fov-120deg-object", "120 deg FoV on DENALI: finite, >= 0 with the three-bounce term", _fov("fov-120deg")),
    Case("dynamic-range-3bounce-f32", "1e7-count direct peak, ~10-count three-bounce return (DENALI; corner with it "
         "in the pulse tail): float32 object part and counts within 1e-3 of float64, signal within 1e-3 sqrt(counts)",
         _dynamic_range),
    Case("gradients-transport", "jax.grad w.r.t. object translation, jitter and bin width finite: 1 mm (Lambertian, "
         "retro, mixed), beyond window, grazing wall, zero-area, 1x1, 16x16, FoV 1 and 120 deg", _gradients),
    Case("reject-bad-mesh", "NaN vertices, no vertices, no triangles, NaN pose: one-line UserError naming the problem",
         _reject_bad_meshes),
    Case("reject-zone-outside-grid", "zones=[(5, 5)] on 3x3 rejected with one line", _reject_zones),
]
