"""Transients on a sub-bin time grid, and their exact binning by the sensor.

Light transport produces millions of arrival impulses per scene; binning
each one through the impulse response would cost ``O(paths x bins)``. The
transport instead deposits arrivals onto a uniform grid of *nodes*, ``q``
per sensor bin (linear split between the two nearest nodes: mass and mean
arrival time are preserved exactly, the added spread is at most
``Delta**2 / 4`` with ``Delta = bin_width / q``). The sensor then bins every
node impulse through the full impulse response (measured pulse (*) Gaussian
of pulse and jitter) in closed form, by :func:`~nlosplan.sensor_models.
pipeline.bin_arrivals`. Because the grid is aligned with the bin edges, the
node-to-bin map depends only on the node's position inside its bin and on
the bin offset, so it is one small kernel (``q x support``) gathered into a
banded matrix, and binning a transient is one matrix product.

Grid layout
-----------
The grid spans whole sensor bins ``first_bin .. first_bin + n_grid_bins - 1``
(``first_bin`` may be negative: arrivals before the window still reach it
through the pulse tail). Node ``k`` sits at time

    start_offset_ps + (first_bin * q + k + 0.5) * Delta

Everything here is a pure JAX function of the bin width, offset and impulse
response width, so it is differentiable in them.
"""

from __future__ import annotations

import math
import threading
from contextlib import contextmanager
from dataclasses import dataclass
from functools import partial
from typing import Any, Iterator, NamedTuple

import numpy as np

from nlosplan._jax import jax, jnp
from nlosplan.sensor_models import compiled
from nlosplan.sensor_models.config import SensorConfig
from nlosplan.sensor_models.pipeline import bin_arrivals, pulse_boxes
from nlosplan.sensor_models.zone_terms import walk_reach_ps

#: Impulse-response support is taken as the pulse shape plus this many Gaussian sigmas.
IRF_SIGMAS = 9.0


def irf_extent_ps(sensor: SensorConfig, sigma_ps: float | None = None) -> tuple[float, float]:
    """Time range ``(lo, hi)`` (ps) that an arrival at 0 can reach through the impulse response.

    Parameters
    ----------
    sensor : SensorConfig
    sigma_ps : float, optional
        Gaussian sigma to assume (default: the sensor's).
    """
    sigma = sensor.impulse_sigma_ps if sigma_ps is None else float(sigma_ps)
    lo = hi = 0.0
    pulse = pulse_boxes(sensor)
    if pulse is not None:
        offsets, width, _ = pulse
        lo, hi = float(offsets.min()), float(offsets.max() + width)
    return lo - IRF_SIGMAS * sigma, hi + IRF_SIGMAS * sigma


def move_reach_ps(sensor: SensorConfig, t_abs_ps: float) -> float:
    """Largest time (ps, either way) by which a sensor's zone clocks and time walk move light at times ``|t| <= t_abs``.

    The sum of the largest zone offset, the largest time scale's drift ``|s - 1|``
    over ``t_abs`` plus the moves themselves, and :func:`~nlosplan.sensor_models.
    zone_terms.walk_reach_ps` (0 for a sensor without them).
    """
    offsets = sensor.zone_time_offsets_ps
    scales = sensor.zone_time_scales
    shift = walk_reach_ps(sensor.time_walk_ps) + (0.0 if offsets is None else float(np.max(np.abs(offsets))))
    drift = 0.0 if scales is None else float(np.max(np.abs(np.asarray(scales, dtype=float) - 1.0)))
    return shift + drift * (t_abs_ps + 2.0 * shift)


@dataclass(frozen=True)
class TimeGrid:
    """A node grid aligned with a sensor's bins (static: only integers).

    Attributes
    ----------
    oversample : int
        Nodes per sensor bin, ``q`` (>= 1).
    first_bin : int
        Sensor-bin index of the grid's first bin (<= 0 when the grid starts
        before the window).
    n_grid_bins : int
        Whole sensor bins the grid spans.
    n_bins : int
        Bins of the sensor window.
    """

    oversample: int
    first_bin: int
    n_grid_bins: int
    n_bins: int

    @property
    def n_nodes(self) -> int:
        """Number of nodes, ``oversample * n_grid_bins``."""
        return self.oversample * self.n_grid_bins

    @classmethod
    def for_sensor(
        cls,
        sensor: SensorConfig,
        t_min_ps: float,
        t_max_ps: float,
        *,
        oversample: int = 4,
        sigma_ps: float | None = None,
    ) -> "TimeGrid":
        """Smallest grid holding every arrival in ``[t_min, t_max]`` that can reach the window.

        With zone clocks or a time walk, the arrivals that their largest move
        (:func:`move_reach_ps`) can bring into the window are kept, and the grid
        reaches that far beyond them, so moving nodes loses nothing that reaches the
        window, and a grid that reaches further (another scene's arrivals) changes nothing.

        Parameters
        ----------
        sensor : SensorConfig
        t_min_ps, t_max_ps : float
            Bounds on the arrival times the transport will deposit, ps.
        oversample : int
            Nodes per bin.
        sigma_ps : float, optional
            Largest Gaussian sigma the grid must serve (default: the sensor's).
        """
        if oversample < 1:
            raise ValueError("oversample must be >= 1")
        lo, hi = irf_extent_ps(sensor, sigma_ps)
        bw, t0 = sensor.bin_width_ps, sensor.start_offset_ps
        reach_lo, reach_hi = t0 - hi, t0 + sensor.window_ps - lo
        s = move_reach_ps(sensor, max(abs(reach_lo), abs(reach_hi)))
        # arrivals earlier than window_start - hi cannot reach the window, later than window_end - lo neither;
        # the zones' clocks and the time walk move light by up to s either way after the arrivals are deposited
        t_first = max(t_min_ps, reach_lo - s)
        t_last = min(t_max_ps, reach_hi + s)
        if t_last < t_first:  # nothing can reach the window: a one-bin grid keeps shapes valid
            return cls(oversample, 0, 1, sensor.n_bins)
        # nodes wherever the walk can move that light and it still reaches the window (a grid that reaches
        # further changes nothing in the window: a pruned object or a longer wall leaves the rest alone)
        t_first = max(t_first - s, min(t_first, reach_lo))
        t_last = min(t_last + s, max(t_last, reach_hi))
        first = math.floor((t_first - t0) / bw) - 1
        last = math.floor((t_last - t0) / bw) + 1
        return cls(oversample, first, last - first + 1, sensor.n_bins)

    def node_times(self, bin_width_ps, start_offset_ps):
        """Node times, shape ``(n_nodes,)``, ps (traceable in the bin width and offset)."""
        delta = bin_width_ps / self.oversample
        k = jnp.arange(self.n_nodes, dtype=jnp.result_type(bin_width_ps, float))
        return start_offset_ps + (self.first_bin * self.oversample + k + 0.5) * delta

    def node_position(self, times_ps, bin_width_ps, start_offset_ps):
        """Fractional node coordinate of arrival times (node ``k`` at ``k``)."""
        delta = bin_width_ps / self.oversample
        return (times_ps - start_offset_ps) / delta - self.first_bin * self.oversample - 0.5


#: How :func:`deposit_at` adds the arrivals: ``"kernel"`` (one compiled C++ loop, an XLA custom call built on
#: first use: :mod:`~nlosplan.sensor_models.compiled`; the fast simulator's default where it builds),
#: ``"window"`` (one scatter-add of both split weights as a two-node window, the XLA default since issue 20) or
#: ``"scatter"`` (two scalar scatter-adds, the path before; kept for ``nlosplan bench simulate --baseline``).
#: All three give the same sums up to float summation order, and the same derivatives.
DEPOSIT_METHODS = ("kernel", "window", "scatter")


class _Method(threading.local):
    """The method :func:`deposit_at` traces with, per thread (simulators trace in their callers' threads)."""

    name = "window"


_DEPOSIT_METHOD = _Method()


def default_deposit() -> str:
    """The fastest deposit this process can run: ``"kernel"`` where it builds and loads, else ``"window"``."""
    return "kernel" if compiled.available() else "window"


@contextmanager
def deposit_method(name: str) -> Iterator[None]:
    """Trace :func:`deposit_at` calls inside the block with method ``name`` (see :data:`DEPOSIT_METHODS`)."""
    if name not in DEPOSIT_METHODS:
        raise ValueError(f"deposit method {name!r} is not one of {DEPOSIT_METHODS}")
    old, _DEPOSIT_METHOD.name = _DEPOSIT_METHOD.name, name
    try:
        yield
    finally:
        _DEPOSIT_METHOD.name = old


def _window_add(i0, r, lo, hi, n_rows: int, n_nodes: int):
    """Add ``lo`` at node ``i0`` and ``hi`` at ``i0 + 1`` of row ``r`` in one scatter-add of 2-node windows.

    Rows are padded by two guard nodes each side (node ``k`` at column ``k + 2``; ``i0`` clipped to
    ``[-2, n_nodes + 1]``), which catch the off-grid halves and are cut away.
    """
    width = n_nodes + 4
    idx = (r * width + i0 + 2)[:, None]
    upd = jnp.stack([lo, hi], -1)
    dn = jax.lax.ScatterDimensionNumbers(update_window_dims=(1,), inserted_window_dims=(),
                                         scatter_dims_to_operand_dims=(0,))
    out = jnp.zeros((n_rows * width + 1,), lo.dtype)  # +1: the window of the last guard column
    out = jax.lax.scatter_add(out, idx, upd, dn, mode=jax.lax.GatherScatterMode.FILL_OR_DROP)
    return out[: n_rows * width].reshape(n_rows, width)[:, 2:-2]


def _split(p, n_nodes: int):
    """``(i0, f)``: the first node of each arrival (clipped to ``[-2, n_nodes + 1]``, int32) and its fraction."""
    i0f = jnp.floor(p)
    # clip before the integer cast so far-off arrivals cannot overflow int32
    return jnp.clip(i0f, -2, n_nodes + 1).astype(jnp.int32), p - i0f


class RowPattern(NamedTuple):
    """Rows of arrivals that follow the arrival array's blocks, without materializing them.

    Arrival ``[..., j]`` of block ``b`` (the flat index over all but the last axis) is in row
    ``b * step + cells[j]``: for samples x cells arrivals, one row per sample is ``RowPattern(zeros, 1)``,
    one per cell ``RowPattern(arange(N), 0)``, a zone per cell and sample ``RowPattern(zone_of_cell, n_zones)``.

    Attributes
    ----------
    cells : array of int, shape (N,)
        The row offset of each position along the last axis.
    step : int
        Rows between consecutive blocks (a Python int).
    """

    cells: Any
    step: int


def _full_rows(r, step: int, shape):
    """The row of every arrival, ``shape``, from rows ``r`` (``shape`` itself, or the last axis repeated every
    block with ``step`` added per block)."""
    r = jnp.asarray(r, jnp.int32)
    if r.shape == tuple(shape):
        return r
    blocks = math.prod(shape) // r.shape[-1]
    return ((jnp.arange(blocks, dtype=jnp.int32) * step)[:, None] + r[None, :]).reshape(shape)


@partial(jax.custom_jvp, nondiff_argnums=(3, 4, 5))
def _kernel_deposit(p, w, r, n_rows, n_nodes, step):
    """The compiled deposit (:func:`~nlosplan.sensor_models.compiled.deposit`) with its derivative.

    ``p`` and ``w`` share one shape; ``r`` has it too, or is the rows of the last axis, repeated every block
    with ``step`` added per block (see :class:`RowPattern`).

    The map is linear in the weights and piecewise linear in the positions; its tangent is the deposit
    of ``dw (1 - f) - w dp`` and ``dw f + w dp`` on the same two nodes, traced as the XLA scatter-add so
    that reverse mode can transpose it (``grad`` and ``jacfwd`` see the same derivative as the XLA paths).
    ``n_rows``/``n_nodes``/``step`` arrive as Python ints (static).
    """
    return compiled.deposit(p, w, r, n_rows, n_nodes, step)


@_kernel_deposit.defjvp
def _kernel_deposit_jvp(n_rows, n_nodes, step, primals, tangents):
    p, w, r = primals
    dp, dw, _ = tangents
    out = _kernel_deposit(p, w, r, n_rows, n_nodes, step)
    r = _full_rows(r, step, p.shape)
    p, w, r, dp, dw = (jnp.ravel(a) for a in (p, w, r, dp, dw))
    i0, f = _split(p, n_nodes)
    return out, _window_add(i0, r, dw * (1.0 - f) - w * dp, dw * f + w * dp, n_rows, n_nodes)


def deposit_at(positions, weights, rows, n_rows: int, n_nodes: int):
    """Deposit weights at fractional node positions (linear split), one row per zone or leg.

    Parameters
    ----------
    positions : array, shape (...)
        Fractional node coordinates (node ``k`` at ``k``), any shape (e.g. samples x cells).
    weights : array, shape (...)
        Broadcast to the positions' shape.
    rows : array of int, shape (...), RowPattern or None
        Row of each arrival, broadcast to the positions' shape, or a :class:`RowPattern` over the positions'
        blocks (``None``: all in row 0).
    n_rows, n_nodes : int
        Output shape.

    Returns
    -------
    array, shape (n_rows, n_nodes)
        Arrivals off the grid are dropped.

    Notes
    -----
    An arrival at ``p`` puts ``1 - f`` on node ``floor(p)`` and ``f`` on the
    next (``f = p - floor(p)``), preserving its weight and mean time exactly.
    The method (the compiled kernel, one windowed scatter-add or two scalar
    ones, equal up to the float summation order) is chosen with
    :func:`deposit_method` at trace time.
    """
    method = _DEPOSIT_METHOD.name
    if method == "kernel" and not compiled.available():
        method = "window"  # a worker process or machine that cannot build it (it warned): the same sums
    if method == "kernel":
        # not raveled: a flat view of a broadcast (M, N) product makes XLA's fused loop that computes the
        # weights and times find a 2-D index per element (a division), ~10x slower than the loop over the
        # array as it is (issue 20's profile); the kernel reads the buffers flat either way
        dtype = jnp.result_type(positions, weights)
        p = jnp.asarray(positions, dtype)
        w = jnp.broadcast_to(jnp.asarray(weights, dtype), p.shape)
        step = 0
        if rows is None:
            r = jnp.zeros(p.shape[-1:], jnp.int32)
        elif isinstance(rows, RowPattern):  # passed once per block: the kernel adds step per block
            r, step = jnp.asarray(rows.cells, jnp.int32).reshape(p.shape[-1:]), int(rows.step)
        elif p.ndim and jnp.shape(rows)[-1:] == p.shape[-1:] and all(d == 1 for d in jnp.shape(rows)[:-1]):
            r = jnp.ravel(jnp.asarray(rows, jnp.int32))  # rows along the last axis only: passed once, repeated
        else:
            r = jnp.broadcast_to(jnp.asarray(rows, jnp.int32), p.shape)
        return _kernel_deposit(p, w, r, int(n_rows), int(n_nodes), step).astype(jnp.result_type(weights))
    p = jnp.ravel(positions)
    w = jnp.ravel(jnp.broadcast_to(weights, jnp.shape(positions)))
    i0, f = _split(p, n_nodes)
    if rows is None:
        r = jnp.zeros_like(i0)
    elif isinstance(rows, RowPattern):
        r = jnp.ravel(_full_rows(rows.cells, int(rows.step), jnp.shape(positions)))
    else:
        r = jnp.ravel(jnp.broadcast_to(jnp.asarray(rows, jnp.int32), jnp.shape(positions)))
    if method == "window":
        return _window_add(i0, r, w * (1.0 - f), w * f, n_rows, n_nodes)
    big = n_rows * n_nodes  # out of range: mode="drop" discards it
    idx0 = jnp.where((i0 >= 0) & (i0 < n_nodes), r * n_nodes + i0, big)
    idx1 = jnp.where((i0 + 1 >= 0) & (i0 + 1 < n_nodes), r * n_nodes + i0 + 1, big)
    out = jnp.zeros((big,), w.dtype)
    out = out.at[idx0].add(w * (1.0 - f), mode="drop")
    out = out.at[idx1].add(w * f, mode="drop")
    return out.reshape(n_rows, n_nodes)


def _fft_sum_convolve(a, b, fft_len: int):
    """:func:`sum_convolve` with FFTs of every row (the XLA path)."""
    fa = jnp.fft.rfft(a, fft_len, axis=-1)
    fb = jnp.fft.rfft(b, fft_len, axis=-1)
    return jnp.fft.irfft(jnp.einsum("mf,mzf->zf", fa, fb), fft_len, axis=-1)[:, : a.shape[-1] + b.shape[-1] - 1]


@partial(jax.custom_jvp, nondiff_argnums=(2,))
def _kernel_sum_convolve(a, b, fft_len):
    """The compiled sum-convolution (:func:`~nlosplan.sensor_models.compiled.sum_convolve`) with its derivative.

    The map is bilinear; its tangent ``conv(da, b) + conv(a, db)`` is traced with the FFTs, which reverse
    mode can transpose.
    """
    return compiled.sum_convolve(a, b)


@_kernel_sum_convolve.defjvp
def _kernel_sum_convolve_jvp(fft_len, primals, tangents):
    a, b = primals
    da, db = tangents
    out = _kernel_sum_convolve(a, b, fft_len)
    return out, _fft_sum_convolve(da, b, fft_len) + _fft_sum_convolve(a, db, fft_len)


def sum_convolve(a, b, fft_len: int):
    """Each sample's two legs convolved along time and summed over the samples.

    Parameters
    ----------
    a : array, shape (M, N1)
        Leg 1 of each sample on the node grid (the light reaching it).
    b : array, shape (M, Z, N2)
        Leg 2 of each sample towards each zone on the node grid.
    fft_len : int
        FFT length of the XLA path, at least ``N1 + N2 - 1``.

    Returns
    -------
    array, shape (Z, N1 + N2 - 1)
        ``out[z, t] = sum_m sum_u b[m, z, u] a[m, t - u]``.

    Notes
    -----
    With :func:`deposit_method` ``"kernel"`` (and the kernels available) this is the compiled loop over the
    legs' non-zero spans, exact sums; otherwise the FFTs of every row and a spectral product summed over
    samples (round-off ~1e-7 of the largest value in float32). The derivatives are the FFT path's.
    """
    if _DEPOSIT_METHOD.name == "kernel" and compiled.available():
        dtype = jnp.result_type(a, b)
        return _kernel_sum_convolve(jnp.asarray(a, dtype), jnp.asarray(b, dtype), int(fft_len))
    return _fft_sum_convolve(a, b, int(fft_len))


@partial(jax.custom_jvp, nondiff_argnums=(4, 5, 6))
def _kernel_deposit_convolve(a, p, w, r, z, n2, fft_len):
    """The compiled deposit-and-sum (:func:`~nlosplan.sensor_models.compiled.deposit_convolve`) with its derivative:
    that of the deposit followed by the sum-convolution (their own rules), so every mode sees the same derivative
    as the two kernels' path."""
    return compiled.deposit_convolve(a, p, w, r, z, n2)


@_kernel_deposit_convolve.defjvp
def _kernel_deposit_convolve_jvp(z, n2, fft_len, primals, tangents):
    a, p, w, r = primals
    da, dp, dw, _ = tangents
    m = p.shape[0]

    def composed(a, p, w):
        leg2 = _kernel_deposit(p, w, r, m * z, n2, z).reshape(m, z, n2)
        return _kernel_sum_convolve(a, leg2, fft_len)

    return _kernel_deposit_convolve(a, p, w, r, z, n2, fft_len), jax.jvp(composed, (a, p, w), (da, dp, dw))[1]


def deposit_sum_convolve(a, positions, weights, rows: RowPattern, n2: int, fft_len: int):
    """A Lambertian object's detection leg deposited (:func:`deposit_at`) and summed with leg 1 (:func:`sum_convolve`).

    Parameters
    ----------
    a : array, shape (M, N1)
        Leg 1 of each sample on the node grid.
    positions, weights : array, shape (M, L)
        Fractional node positions and weights of each sample's detection cells on leg 2's grid of ``n2`` nodes.
    rows : RowPattern
        ``RowPattern(zone_of_cell (L,), Z)``: a row per sample and zone.
    n2 : int
        Leg 2's nodes.
    fft_len : int
        FFT length of the XLA path, at least ``N1 + n2 - 1``.

    Returns
    -------
    array, shape (Z, N1 + n2 - 1)
        ``sum_convolve(a, deposit_at(positions, weights, rows, M * Z, n2).reshape(M, Z, n2), fft_len)``.

    Notes
    -----
    With :func:`deposit_method` ``"kernel"`` (and the kernels available) one compiled pass that never holds the
    (M, Z, n2) leg (the same sums in the same order as the two kernels, so the same result); otherwise the two
    steps. Derivatives are the two steps'.
    """
    m, z = positions.shape[0], int(rows.step)
    if _DEPOSIT_METHOD.name == "kernel" and compiled.available():
        dtype = jnp.result_type(a, positions, weights)
        p = jnp.asarray(positions, dtype)
        w = jnp.broadcast_to(jnp.asarray(weights, dtype), p.shape)
        r = jnp.asarray(rows.cells, jnp.int32).reshape(p.shape[-1:])
        return _kernel_deposit_convolve(jnp.asarray(a, dtype), p, w, r, z, int(n2), int(fft_len))
    leg2 = deposit_at(positions, weights, rows, m * z, int(n2)).reshape(m, z, int(n2))
    return sum_convolve(a, leg2, fft_len)


def deposit(grid: TimeGrid, times_ps, weights, rows, n_rows: int, *, bin_width_ps, start_offset_ps):
    """Deposit weighted arrival times onto ``grid`` (see :func:`deposit_at`).

    Parameters
    ----------
    times_ps, weights : array, shape (N,)
    rows : array of int, shape (N,) or None
    n_rows : int
    bin_width_ps, start_offset_ps : scalar
        Sensor time base (traceable).

    Returns
    -------
    array, shape (n_rows, n_nodes)
    """
    pos = grid.node_position(jnp.ravel(times_ps), bin_width_ps, start_offset_ps)
    return deposit_at(pos, weights, rows, n_rows, grid.n_nodes)


def _kernel_range(grid: TimeGrid, sensor_extent: tuple[float, float], bin_width_ps: float) -> tuple[int, int]:
    lo, hi = sensor_extent
    m_lo = math.floor(lo / bin_width_ps) - 1
    m_hi = math.ceil(hi / bin_width_ps) + 1
    # no node is farther than the grid from any window bin
    m_lo = max(m_lo, -(grid.first_bin + grid.n_grid_bins))
    m_hi = min(m_hi, grid.n_bins - grid.first_bin)
    return m_lo, max(m_hi, m_lo)


def irf_matrix(grid: TimeGrid, *, bin_width_ps, sigma_ps, pulse, extent_ps, nominal_bin_width_ps):
    """Node-to-bin matrix of the impulse response, shape ``(n_nodes, n_bins)``.

    ``M[k, j]`` is the fraction of a unit impulse at node ``k`` that lands in
    sensor bin ``j`` through the measured pulse (if any) and a Gaussian of
    standard deviation ``sigma_ps``, computed in closed form.

    Parameters
    ----------
    grid : TimeGrid
    bin_width_ps, sigma_ps : scalar
        Traceable time base and Gaussian width, ps.
    pulse : tuple or None
        Measured pulse boxes from :func:`~nlosplan.sensor_models.pipeline.pulse_boxes`.
    extent_ps : (float, float)
        Support of the impulse response, from :func:`irf_extent_ps`.
    nominal_bin_width_ps : float
        Concrete bin width used to size the kernel (static).

    Returns
    -------
    array, shape (n_nodes, n_bins)
    """
    q = grid.oversample
    dtype = jnp.result_type(bin_width_ps, sigma_ps, float)
    bw = jnp.asarray(bin_width_ps, dtype)
    m_lo, m_hi = _kernel_range(grid, extent_ps, float(nominal_bin_width_ps))
    # node r of a bin sits at (r + 0.5) * Delta from the bin's left edge; edges of bins m_lo..m_hi
    pos = (jnp.arange(q, dtype=dtype) + 0.5) * (bw / q)
    edges = jnp.arange(m_lo, m_hi + 2, dtype=dtype) * bw
    kern = bin_arrivals(pos[:, None], jnp.ones((q, 1), dtype), edges, jnp.asarray(sigma_ps, dtype), pulse)
    # gather: node k in grid bin b = first_bin + k // q, sub-position r = k % q; M[k, j] = kern[r, j - b - m_lo]
    k = np.arange(grid.n_nodes)
    r = k % q
    b = grid.first_bin + k // q
    m = np.arange(grid.n_bins)[None, :] - b[:, None] - m_lo
    valid = (m >= 0) & (m < kern.shape[1])
    gathered = kern[r[:, None], np.clip(m, 0, kern.shape[1] - 1)]
    return jnp.where(valid, gathered, 0.0)


def bin_nodes_without_irf(grid: TimeGrid, transient):
    """Bin a node transient with an ideal impulse response (sum of each bin's nodes).

    Exact when the sensor has no pulse shape and zero Gaussian width: the
    node impulses then land in their own bins.

    Parameters
    ----------
    transient : array, shape (..., n_nodes)

    Returns
    -------
    array, shape (..., n_bins)
    """
    q = grid.oversample
    per_bin = transient.reshape(transient.shape[:-1] + (grid.n_grid_bins, q)).sum(-1)
    lo = -grid.first_bin  # grid-bin index of sensor bin 0
    start, stop = max(lo, 0), min(lo + grid.n_bins, grid.n_grid_bins)
    if stop <= start:  # the grid does not overlap the window
        return jnp.zeros(transient.shape[:-1] + (grid.n_bins,), transient.dtype)
    pad = [(0, 0)] * (per_bin.ndim - 1) + [(start - lo, lo + grid.n_bins - stop)]
    return jnp.pad(per_bin[..., start:stop], pad)

