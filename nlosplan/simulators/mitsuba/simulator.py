"""`TwinSimulator`: the Mitsuba 3 + mitransient digital twin of a flash-LiDAR NLOS capture.

The twin renders the same :class:`~nlosplan.simulators.scene.Scene` as the
fast backend and produces the same kind of transient: photons per laser
iteration per unit photon scale, per zone, on a node grid aligned with the
sensor's bins (:class:`~nlosplan.sensor_models.transient.TimeGrid`). The
sensor pipeline then bins it through the impulse response and adds
crosstalk, ambient, dark counts, pile-up and the 24-bit clip, exactly as for
the fast backend.

Notes
-----
Flash mode (default): the projector emits the flash profile with unit
power; the film holds, per zone sub-pixel ``p`` (wall point ``x2``), the
time-resolved radiance ``L_p(t)`` leaving ``x2`` towards the LiDAR; a zone
collects ``sum_p s_p dOmega_p L_p(t)`` (sensitivity times exact sub-pixel
solid angle), the fast backend's ``L s dOmega``. Two renders: the direct
wall return (one bounce, deterministic: one sample per pixel) and the
three-bounce return of the hidden objects (``spp`` samples per pixel).

Spot mode (DENALI's own twin): a unit-power laser spot where the optical
axis meets the wall, laser sampling; the render's unit-area patch
convention is turned into unit power by ``r^2 / cos`` of the spot, and the
spot's direct return is the closed form ``s (rho_w / pi) cos / r^2``.
"""

from __future__ import annotations

import copy
import time

import numpy as np

from nlosplan._jax import jnp
from nlosplan.constants import C_M_PER_PS, MAX_COUNT_24BIT
from nlosplan.errors import UserError
from nlosplan.sensor_models.config import SensorConfig
from nlosplan.sensor_models.noise import CaptureNoise, floor_per_bin
from nlosplan.sensor_models.pipeline import bin_arrivals, counts_from_rates, dead_bins, pulse_boxes
from nlosplan.sensor_models.zone_terms import apply_zone_terms, move_nodes, walk_shift_ps, window_light, zone_values
from nlosplan.sensor_models.transient import bin_nodes_without_irf, deposit_at, irf_extent_ps, irf_matrix
from nlosplan.simulators.mitsuba.fidelity import resolve_twin_fidelity
from nlosplan.simulators.mitsuba.geometry import detection, film_time_axis, flash_texture, time_grid
from nlosplan.simulators.scene import Scene

ILLUMINATIONS = ("flash", "spot")


def _zone_list(sensor: SensorConfig, zones) -> tuple[list[int], bool]:
    if zones is None:
        return list(range(sensor.n_zones)), True
    out = []
    for rc in zones:
        try:
            r, c = (int(v) for v in rc)
        except (TypeError, ValueError):
            raise UserError(f"zones must be (row, col) pairs, got {rc!r}") from None
        if not (0 <= r < sensor.zones_rows and 0 <= c < sensor.zones_cols):
            raise UserError(f"zone ({r}, {c}) is outside the {sensor.zones_rows}x{sensor.zones_cols} grid")
        out.append(r * sensor.zones_cols + c)
    if not out:
        raise UserError("zones is empty; give at least one (row, col)")
    return out, False


def spot_point(scene: Scene) -> np.ndarray:
    """Where the LiDAR's optical axis meets the relay-wall plane (DENALI's single laser spot), shape (3,)."""
    w, lid = scene.wall, scene.lidar
    denom = float(lid.forward @ w.normal)
    if denom >= 0:
        raise UserError("spot illumination: the LiDAR's optical axis does not point at the relay wall")
    t = float((w.center - lid.position) @ w.normal) / denom
    p = lid.position + t * lid.forward
    if not bool(w.contains(p)):
        raise UserError("spot illumination: the LiDAR's optical axis misses the relay wall rectangle")
    return p


class TwinSimulator:
    """The Mitsuba twin of one scene and sensor.

    Parameters
    ----------
    scene : Scene
    sensor : SensorConfig
    fidelity : str, dict or TwinFidelity
        ``draft``, ``low``, ``default``, ``high``, ``reference`` or knobs
        (``spp``, ``zone_sub``, ``time_oversample``, ``flash_resolution``).
    zones : list of (row, col), optional
        Render only these zones (the others cost nothing).
    seed : int
        Seed of the Monte-Carlo sampler (same seed, same result).
    variant : {"auto", "llvm_ad_rgb", "cuda_ad_rgb"}
    illumination : {"flash", "spot"}
        The sensor's flash, or DENALI's single laser spot on the wall centre.

    Attributes
    ----------
    seconds : dict
        Wall time of the direct render (``direct``), of the three-bounce
        renders (``object``: one per hidden object) and of the whole run.

    Examples
    --------
    >>> from nlosplan.simulators import denali_scene
    >>> from nlosplan.sensor_models import preset
    >>> sim = TwinSimulator(denali_scene("A", "8in", 19, reflectance="lambertian"),
    ...                     preset("tmf8828-3x3-short"), fidelity="draft")
    >>> sim.expected().shape
    (3, 3, 128)
    """

    def __init__(self, scene: Scene, sensor: SensorConfig, *, fidelity="default", zones=None, seed: int = 0,
                 variant: str = "auto", illumination: str = "flash"):
        if not isinstance(scene, Scene):
            raise UserError(f"scene must be a Scene, not {type(scene).__name__}")
        if not isinstance(sensor, SensorConfig):
            raise UserError(f"sensor must be a SensorConfig, not {type(sensor).__name__}")
        if illumination not in ILLUMINATIONS:
            raise UserError(f"illumination={illumination!r} is unknown; allowed: {', '.join(ILLUMINATIONS)}")
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or not 0 <= int(seed) < 2**32:
            raise UserError(f"seed={seed!r} must be an integer in 0..2**32-1")
        self.scene, self.sensor = scene, sensor
        self.fidelity = resolve_twin_fidelity(fidelity)
        self.zone_ids, self.full_grid = _zone_list(sensor, zones)
        self.seed = int(seed)
        self.variant = variant
        self.illumination = illumination
        self.grid = time_grid(sensor, self.fidelity.time_oversample)
        self.seconds: dict[str, float] = {}
        self._transient = None

    # ------------------------------------------------------------ transport
    def transient(self) -> dict:
        """Photons per iteration per unit photon scale on the node grid.

        Returns
        -------
        dict
            ``times_ps`` (K,) node times; ``direct``, ``object`` (every hidden
            object, fixtures included) and ``fixture`` (the fixtures alone,
            which stay in the background capture), (Z, K) for the asked zones
            (Z) in row-major order.
        """
        if self._transient is not None:
            return self._transient
        from nlosplan.simulators.mitsuba.env import load
        from nlosplan.simulators.mitsuba.render import projector, render, scene_dict

        t0 = time.perf_counter()
        mi, _, self.variant = load(self.variant)
        fid, scene, sensor = self.fidelity, self.scene, self.sensor
        det = detection(scene, sensor, fid.zone_sub, self.zone_ids)
        axis = film_time_axis(sensor, self.grid)
        to_zones = det.zone_matrix(self.zone_ids)  # (Z, P)
        k = self.grid.n_nodes
        times = np.asarray(self.grid.node_times(sensor.bin_width_ps, sensor.start_offset_ps), dtype=np.float64)
        spot = spot_point(scene) if self.illumination == "spot" else None
        if spot is None:
            emitter = projector(mi, scene, flash_texture(sensor, fid.flash_resolution))
            d, key = scene_dict(mi, scene, det, axis, spp=1, three_bounce=False, emitter=emitter)
            film, self.seconds["direct"] = render(mi, d, key, spp=1, seed=self.seed)
            direct = to_zones @ film
            scale = 1.0
        else:
            emitter = projector(mi, scene, None, aim=spot)
            direct = self._spot_direct(spot, det)
            q = spot - scene.lidar.position
            r = float(np.linalg.norm(q))
            scale = r * r / (abs(float(q @ scene.wall.normal)) / r)
        parts = {"object": np.zeros((len(self.zone_ids), k)), "fixture": np.zeros((len(self.zone_ids), k))}
        # one render per hidden object: objects do not shadow each other (as in the fast backend), and
        # hidden-geometry sampling is biased where meshes overlap (the object sits in its mount: +5-7 %)
        for i, o in enumerate(scene.objects):
            d, key = scene_dict(mi, scene, det, axis, spp=fid.spp, three_bounce=True, emitter=emitter,
                                laser=spot is not None, objects=[o])
            film, seconds = render(mi, d, key, spp=fid.spp, seed=self.seed + i)
            self.seconds["object"] = self.seconds.get("object", 0.0) + seconds  # all three-bounce renders
            parts["fixture" if o.fixture else "object"] += scale * (to_zones @ film)
        self.seconds["total"] = time.perf_counter() - t0
        self._transient = {"times_ps": times, "direct": direct, "object": parts["object"] + parts["fixture"],
                           "fixture": parts["fixture"]}
        return self._transient

    def without_objects(self) -> "TwinSimulator":
        """The same capture without hidden objects (DENALI's NOOBJECT), from this simulator's renders.

        The twin's direct wall return does not depend on the hidden objects,
        so the background is this transient with the three-bounce term of the
        objects set to zero; fixtures (the mount) stay in it, so they cancel
        from the signal. Nothing is rendered again.
        """
        tr = self.transient()
        bg = copy.copy(self)
        bg.scene = self.scene.without_objects(keep_fixtures=True)
        bg.seconds = {}
        bg._transient = {**tr, "object": np.array(tr["fixture"]), "fixture": np.array(tr["fixture"])}
        return bg

    def _spot_direct(self, spot: np.ndarray, det) -> np.ndarray:
        """Closed-form direct return of a unit-power spot, (Z, K) on the node grid."""
        scene, sensor = self.scene, self.sensor
        q = spot - scene.lidar.position
        r = float(np.linalg.norm(q))
        d = scene.lidar.points_to_sensor(spot)
        d = d / np.linalg.norm(d)
        from nlosplan.sensor_models.zones import zone_edges_tan

        ue, ve = zone_edges_tan(sensor)
        u, v = d[0] / d[2], d[1] / d[2]
        col = int(np.searchsorted(ue, u) - 1)
        row = int(np.searchsorted(-ve, -v) - 1)
        out = np.zeros((len(self.zone_ids), self.grid.n_nodes))
        z = row * sensor.zones_cols + col
        if not (0 <= row < sensor.zones_rows and 0 <= col < sensor.zones_cols) or z not in self.zone_ids:
            return out
        cos = abs(float(q @ scene.wall.normal)) / r
        w = d[2] ** sensor.sensitivity_cos_power * scene.wall.albedo / np.pi * cos / (r * r)
        pos = self.grid.node_position(2 * r / C_M_PER_PS, sensor.bin_width_ps, sensor.start_offset_ps)
        row_nodes = np.asarray(deposit_at(jnp.asarray([pos]), jnp.asarray([w]), None, 1, self.grid.n_nodes))
        out[self.zone_ids.index(z)] = row_nodes[0]
        return out

    # ------------------------------------------------------------ sensor
    def _zone(self, nodes: np.ndarray):
        """The sensor's per-zone terms on node transients (Z, K) (unchanged without any)."""
        s, grid = self.sensor, self.grid
        x = jnp.asarray(nodes, jnp.float64) if _x64() else jnp.asarray(nodes)
        zv = zone_values(s, self.zone_ids)
        if any(v is not None for v in zv.values()):
            x = apply_zone_terms(x, grid.node_times(s.bin_width_ps, s.start_offset_ps), s.bin_width_ps / grid.oversample,
                                 **zv)
        return x

    def _to_bins(self, nodes, shift_ps=None) -> np.ndarray:
        s, grid = self.sensor, self.grid
        pulse = pulse_boxes(s)
        x = jnp.asarray(nodes)
        if shift_ps is not None:
            x = move_nodes(x, grid.node_times(s.bin_width_ps, s.start_offset_ps), s.bin_width_ps / grid.oversample,
                           offsets_ps=shift_ps)
        if pulse is None and s.impulse_sigma_ps == 0:
            return np.asarray(bin_nodes_without_irf(grid, x), dtype=np.float64)
        mat = irf_matrix(grid, bin_width_ps=s.bin_width_ps, sigma_ps=s.impulse_sigma_ps, pulse=pulse,
                         extent_ps=irf_extent_ps(s), nominal_bin_width_ps=s.bin_width_ps)
        return np.asarray(x @ jnp.asarray(mat, x.dtype), dtype=np.float64)

    def _shape(self, a: np.ndarray) -> np.ndarray:
        s = self.sensor
        return a.reshape(s.zones_rows, s.zones_cols, -1) if self.full_grid else a

    def expected(self, parts: bool = False):
        """Expected counts through the sensor pipeline.

        Returns
        -------
        ndarray, shape (rows, cols, n_bins) or (len(zones), n_bins)
        dict of such arrays (with ``parts``)
            ``counts`` and the linear parts ``direct``, ``object``,
            ``background`` (ambient + dark), ``crosstalk``, as the fast backend.
        """
        s = self.sensor
        tr = self.transient()
        direct_n = s.photon_scale * self._zone(tr["direct"])
        obj_n = s.photon_scale * self._zone(tr["object"])
        z = direct_n.shape[0]
        zv = zone_values(s, self.zone_ids)
        g = np.ones(z) if zv["gains"] is None else zv["gains"]
        when = np.zeros(z) if zv["offsets_ps"] is None else zv["offsets_ps"].copy()
        shift = None
        if s.time_walk_ps != 0:  # each zone's light, crosstalk included, is recorded earlier the brighter it is
            times = self.grid.node_times(s.bin_width_ps, s.start_offset_ps)
            flux = np.asarray(window_light(direct_n + obj_n, times, s.start_offset_ps, s.window_ps)) + s.crosstalk * g
            shift = np.asarray(walk_shift_ps(flux, s.time_walk_ps), dtype=np.float64)
            when = when + shift
        direct = self._to_bins(direct_n, shift)
        obj = self._to_bins(obj_n, shift)
        xt = np.zeros_like(direct)
        if s.crosstalk > 0:  # the zone's gain and time offset, no overlap
            xt = np.asarray(bin_arrivals(when[:, None], (s.crosstalk * g)[:, None], s.bin_edges_ps(),
                                         s.impulse_sigma_ps, pulse_boxes(s)), dtype=np.float64)
        bg = floor_per_bin(s, self.scene.lights_on)
        counts = np.asarray(counts_from_rates(jnp.asarray(direct + obj + xt), iterations=float(s.iterations),
                                              floor_per_bin=bg, pileup=s.pileup,
                                              max_count=MAX_COUNT_24BIT if s.saturation else None,
                                              spads=s.spads_per_zone, dead_bins=dead_bins(s)), dtype=np.float64)
        if not parts:
            return self._shape(counts)
        it = float(s.iterations)
        return {"counts": self._shape(counts), "direct": self._shape(it * direct), "object": self._shape(it * obj),
                "floor": self._shape(np.full_like(counts, it * bg)), "crosstalk": self._shape(it * xt)}

    def sample(self, rng=0, repeats: int = 1) -> np.ndarray:
        """Poisson captures of the expected counts, shape ``(repeats, *expected().shape)``, int64."""
        import jax

        if int(repeats) < 1:
            raise UserError(f"repeats={repeats} must be >= 1")
        key = jax.random.key(int(rng)) if isinstance(rng, (int, np.integer)) else rng
        mean = np.broadcast_to(self.expected(), (int(repeats),) + self.expected().shape)
        return np.asarray(CaptureNoise.of(self.sensor).draw(key, jnp.asarray(mean)))

    def describe(self) -> dict:
        """What made this result: fidelity, variant, seed, illumination, timings (JSON-friendly)."""
        return {"backend": "mitsuba", "variant": self.variant, "seed": self.seed, "illumination": self.illumination,
                "fidelity": self.fidelity.to_dict(), "seconds": dict(self.seconds),
                "film": [self.sensor.zones_rows * self.fidelity.zone_sub, self.sensor.zones_cols * self.fidelity.zone_sub],
                "time_nodes": self.grid.n_nodes}


def _x64() -> bool:
    import jax

    return bool(jax.config.jax_enable_x64)
