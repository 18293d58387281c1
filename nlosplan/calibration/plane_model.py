"""The all-zone forward model of plane captures, its parameters and their normalization.

A capture is a flat plane square-on at a known distance ``d``; its simulated
arrivals per zone ``(t_k, w_k)`` (zone sub-rays off the plane, e.g.
:func:`nlosplan.simulators.wall_arrivals`) are computed once by the caller.
The model of zone ``z``, bin ``j`` is the sensor pipeline with every term the
plane data asks for:

    lam_zj = s g_z sum_k w_k O_z(t_k) IRF_j(s_z t_k + delta_z) + a_z
    mu_zj  = N (1 - exp(-lam_zj)) exp(-sum_{i<j} lam_zi)         (pile-up on)
    mu_zj  = N lam_zj                                            (pile-up off)

``s`` the photon scale, ``g_z`` the zone gains, ``O_z`` the near-field overlap
``r^2 / (r^2 + d0_z^2)`` at ``r = c t / 2``, ``delta_z`` the zone time offsets
(the zone's clock runs at ``s_z``: it records ``t`` at ``s_z t + delta_z``),
``IRF`` the pulse (``P`` free samples of one bin width) followed by an
exponential tail of share ``a_tail`` and decay ``tau``, ``N`` the iterations of
the captures (identified by the pile-up), ``a_z`` each capture zone's ambient
per bin, measured on the bins before any return (``floor / N``).

Arrivals are deposited on a node grid (``oversample`` nodes per bin, linear
split: exact in mass and mean time) and binned by one node-to-bin matrix
(:mod:`~nlosplan.sensor_models.transient`), as in the simulators.

Every optimizer sees normalized variables in [0, 1] (linear or logarithmic
maps of each parameter's bounds). The model removes the mean of the zone
offsets and of the log gains and log time scales: the start offset, photon
scale and bin width carry the common part (:func:`zone_arrays`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from nlosplan._jax import jnp
from nlosplan.errors import UserError
from nlosplan.sensor_models.config import SensorConfig
from nlosplan.sensor_models.counts import pileup_expected
from nlosplan.sensor_models.transient import TimeGrid, deposit, irf_matrix
from nlosplan.sensor_models.zone_terms import overlap_factor

#: Physics terms the plane model can switch on, in the order of the ablation table.
TERMS = ("offsets", "scales", "gains", "overlap", "pileup", "tail", "walk")
#: Length of the exponential tail's box train, bins (one window).
TAIL_BINS = 128


@dataclass(frozen=True)
class PlaneData:
    """Plane captures of some zones with their simulated arrivals.

    Attributes
    ----------
    distance_m : ndarray, shape (N,)
    counts : ndarray, shape (N, Z, B)
        Measured counts.
    times_ps, weights : ndarray, shape (N, Z, K)
        Simulated arrivals of each capture zone (albedo 1, unit photon scale).
    floor : ndarray, shape (N, Z)
        Mean counts per bin on the bins before any return (ambient + dark, measured).
    zones : tuple of int
        Flat zone index (row-major) of each of the Z columns.
    labels : tuple of str
    """

    distance_m: np.ndarray
    counts: np.ndarray
    times_ps: np.ndarray
    weights: np.ndarray
    floor: np.ndarray
    zones: tuple
    labels: tuple

    def subset(self, idx) -> "PlaneData":
        """The captures at ``idx``."""
        idx = np.asarray(idx, dtype=int)
        return PlaneData(self.distance_m[idx], self.counts[idx], self.times_ps[idx], self.weights[idx],
                         self.floor[idx], self.zones, tuple(self.labels[i] for i in idx))


@dataclass(frozen=True)
class Block:
    """One group of parameters: ``n`` values with bounds ``[lo, hi]`` (log map if ``log``)."""

    name: str
    n: int
    lo: float
    hi: float
    log: bool
    unit: str

    def to_unit(self, v):
        v = np.asarray(v, dtype=np.float64)
        if self.log:
            return (np.log(v) - math.log(self.lo)) / (math.log(self.hi) - math.log(self.lo))
        return (v - self.lo) / (self.hi - self.lo)

    def from_unit(self, z):
        if self.log:
            return jnp.exp(math.log(self.lo) + z * (math.log(self.hi) - math.log(self.lo)))
        return self.lo + z * (self.hi - self.lo)


def blocks(terms, n_zones: int, n_pulse: int) -> tuple[Block, ...]:
    """The parameter blocks of a model with ``terms`` (parameters a term leaves out are not blocks).

    Per-zone gains, offsets and time scales are fitted as free values whose mean
    (of the logarithm for gains and scales) the model removes: the photon scale,
    start offset and bin width carry the common part, so every block is
    identifiable but for that one flat direction.
    """
    terms = set(terms)
    out = [Block("bin_width_ps", 1, 70.0, 130.0, False, "ps"),
           Block("start_offset_ps", 1, -3000.0, 1000.0, False, "ps"),
           Block("photon_scale", 1, 1e-6, 1e4, True, "photons/iteration per unit weight"),
           Block("pulse", n_pulse, 1e-9, 1.0, True, "share of the pulse per sample")]
    if "offsets" in terms:
        out.append(Block("zone_time_offsets_ps", n_zones, -600.0, 600.0, False, "ps"))
    if "scales" in terms:
        out.append(Block("zone_time_scales", n_zones, 0.9, 1.1, True, "relative"))
    if "gains" in terms:
        out.append(Block("zone_gains", n_zones, 1e-3, 1e3, True, "relative"))
    if "overlap" in terms:  # fitted as d0^2: the overlap is stationary in d0 at d0 = 0, not in d0^2
        out.append(Block("zone_overlap_m2", n_zones, 0.0, 0.04, False, "m^2"))
    if "pileup" in terms:
        out.append(Block("iterations", 1, 1e4, 1e9, True, "laser iterations"))
    if "tail" in terms:
        out += [Block("pulse_tail_fraction", 1, 0.0, 0.05, False, "share of the impulse response"),
                Block("pulse_tail_decay_ps", 1, 50.0, 50_000.0, True, "ps")]
    if "walk" in terms:
        out.append(Block("time_walk_ps", 1, -300.0, 300.0, False, "ps per decade of zone flux"))
    return tuple(out)


def zone_arrays(v: dict) -> dict:
    """The per-zone values the model uses (means removed), from block values."""
    out = {}
    if "zone_gains" in v:
        lg = jnp.log(v["zone_gains"])
        out["gains"] = jnp.exp(lg - jnp.mean(lg))
    if "zone_time_scales" in v:
        ls = jnp.log(v["zone_time_scales"])
        out["scales"] = jnp.exp(ls - jnp.mean(ls))
    if "zone_time_offsets_ps" in v:
        out["offsets_ps"] = v["zone_time_offsets_ps"] - jnp.mean(v["zone_time_offsets_ps"])
    if "zone_overlap_m2" in v:
        out["overlap_m"] = jnp.sqrt(v["zone_overlap_m2"])
    return out


def pack(bl: tuple[Block, ...], values: dict) -> np.ndarray:
    """Normalized vector (clipped into [0, 1]) of physical ``values`` by block name."""
    parts = [np.clip(np.atleast_1d(b.to_unit(values[b.name])), 0.0, 1.0) for b in bl]
    return np.concatenate(parts)


def unpack(bl: tuple[Block, ...], z) -> dict:
    """Physical values (JAX arrays) of a normalized vector, by block name."""
    out, i = {}, 0
    for b in bl:
        out[b.name] = b.from_unit(z[i:i + b.n])
        i += b.n
    return out


def _tail_masses(n: int, step, decay):
    edges = jnp.arange(n + 1) * step
    m = -jnp.diff(jnp.exp(-edges / decay))
    return m / jnp.sum(m)


def make_plane_model(data: PlaneData, terms, fixed: dict, *, n_pulse: int, pulse_t0_ps: float,
                     nominal_bin_width_ps: float, nominal_offset_ps: float, oversample: int = 4):
    """``f(values) -> mu (N, Z, B)``: expected counts from physical values (blocks and ``fixed``).

    Parameters
    ----------
    data : PlaneData
    terms : iterable of str
        Subset of :data:`TERMS`.
    fixed : dict
        ``iterations`` (used without pile-up, where it is not a block).
    n_pulse : int
        Free pulse samples ``P`` (one nominal bin width each).
    pulse_t0_ps : float
        Left edge of the first pulse sample relative to the nominal arrival, ps.
    nominal_bin_width_ps, nominal_offset_ps : float
        Time base that sizes the node grid and the impulse-response kernel.
    """
    terms = set(terms)
    n, z, k = data.times_ps.shape
    n_bins = data.counts.shape[-1]
    nominal = SensorConfig(n_bins=n_bins, bin_width_ps=float(nominal_bin_width_ps),
                           start_offset_ps=float(nominal_offset_ps))
    lead = pulse_t0_ps - 2.0 * nominal_bin_width_ps
    n_boxes = n_pulse + (TAIL_BINS if "tail" in terms else 0)
    extent = (lead, pulse_t0_ps + (n_boxes + 2) * nominal_bin_width_ps)
    t_max = float(np.max(data.times_ps)) + 700.0
    grid = TimeGrid.for_sensor(nominal.replace(n_bins=n_bins), -3000.0, t_max, oversample=int(oversample))
    # widen the grid to hold arrivals moved by the zone offsets and a bin width off its nominal value
    grid = TimeGrid(grid.oversample, grid.first_bin - 8, grid.n_grid_bins + 16, n_bins)
    t = jnp.asarray(data.times_ps, jnp.float64)
    w = jnp.asarray(data.weights, jnp.float64)
    floor = jnp.asarray(data.floor, jnp.float64)
    rows = jnp.asarray(np.repeat(np.arange(n * z), k), jnp.int32)

    def model(v):
        bw = v["bin_width_ps"][0]
        t0 = v["start_offset_ps"][0]
        iters = v["iterations"][0] if "iterations" in v else fixed["iterations"]
        zv = zone_arrays(v)
        times, wts = t, w * v["photon_scale"][0]
        if "gains" in zv:
            wts = wts * zv["gains"][None, :, None]
        if "overlap_m" in zv:
            wts = wts * overlap_factor(times, zv["overlap_m"][None, :, None])
        if "scales" in zv:
            times = times * zv["scales"][None, :, None]
        if "time_walk_ps" in v:  # brighter zones record earlier: -w log10(photons per iteration in the zone)
            flux = jnp.maximum(jnp.sum(wts, axis=-1, keepdims=True), 1e-30)
            times = times - v["time_walk_ps"][0] * jnp.log10(flux)
        if "offsets_ps" in zv:
            times = times + zv["offsets_ps"][None, :, None]
        p = v["pulse"] / jnp.sum(v["pulse"])
        offs = pulse_t0_ps + nominal_bin_width_ps * jnp.arange(p.shape[0])
        step = nominal_bin_width_ps
        if "tail" in terms:
            a = v["pulse_tail_fraction"][0]
            offs = jnp.concatenate([offs, offs[-1] + step * jnp.arange(1, TAIL_BINS + 1)])
            p = jnp.concatenate([(1.0 - a) * p, a * _tail_masses(TAIL_BINS, step, v["pulse_tail_decay_ps"][0])])
        # the pulse is sampled at the nominal bin width; a fitted bin width scales the whole time axis
        scale_t = bw / nominal_bin_width_ps
        nodes = deposit(grid, times.reshape(-1) / scale_t, wts.reshape(-1), rows, n * z,
                        bin_width_ps=nominal_bin_width_ps, start_offset_ps=t0 / scale_t)
        mat = irf_matrix(grid, bin_width_ps=nominal_bin_width_ps, sigma_ps=0.0, pulse=(offs, step, p),
                         extent_ps=extent, nominal_bin_width_ps=nominal_bin_width_ps)
        lam = (nodes @ mat).reshape(n, z, n_bins)
        if "pileup" in terms:
            return pileup_expected(lam + (floor / iters)[..., None], iters)
        return iters * lam + floor[..., None]

    return model


def canonical(values: dict) -> dict:
    """Plain-float physical values: per-zone values as the model uses them (means removed), lists per zone."""
    zv = {k: np.asarray(v, dtype=np.float64) for k, v in zone_arrays(values).items()}
    out = {}
    for k, v in values.items():
        if k in ("zone_gains", "zone_time_scales", "zone_time_offsets_ps", "zone_overlap_m2"):
            continue
        v = np.asarray(v, dtype=np.float64)
        out[k] = [float(x) for x in v] if k == "pulse" else float(v[0])
    names = {"gains": "zone_gains", "scales": "zone_time_scales", "offsets_ps": "zone_time_offsets_ps",
             "overlap_m": "zone_overlap_m"}
    for k, v in zv.items():
        out[names[k]] = [float(x) for x in v]
    if "pulse" in out:
        total = sum(out["pulse"])
        out["pulse"] = [x / total for x in out["pulse"]]
    return out


def check_terms(terms) -> list[str]:
    """The terms as a list in :data:`TERMS` order; UserError for unknown ones."""
    terms = [t.strip() for t in terms if t and t.strip()]
    bad = [t for t in terms if t not in TERMS]
    if bad:
        raise UserError(f"unknown plane-model term(s) {', '.join(bad)}; allowed: {', '.join(TERMS)}")
    return [t for t in TERMS if t in terms]


def first_return_bin(sensor: SensorConfig, pulse_t0_ps: float) -> int:
    """Bins before this one hold no return light (zero optical path, pulse lead and one bin of margin)."""
    return int(math.floor((pulse_t0_ps - sensor.start_offset_ps) / sensor.bin_width_ps)) - 1
