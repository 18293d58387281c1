"""From expected photons per iteration to recorded counts: pile-up (Coates model) and its correction.

Pure JAX functions. Drawing captures from expected counts (Poisson noise, the register clip) is the noise
model's (:mod:`~nlosplan.sensor_models.noise`).
"""

from __future__ import annotations

from nlosplan._jax import jax, jnp


def _exclusive_cumsum(x):
    """``sum_{i<j} x_i`` along the last axis, without the cancellation of ``cumsum - x``."""
    pad = jnp.zeros(x.shape[:-1] + (1,), x.dtype)
    return jnp.concatenate([pad, jnp.cumsum(x, axis=-1)[..., :-1]], axis=-1)


def pileup_expected(rate_per_iteration, iterations):
    """Expected counts of a first-photon detector (Coates' model).

    Parameters
    ----------
    rate_per_iteration : array, shape (..., B)
        Mean photons arriving in each bin per laser iteration (>= 0).
    iterations : float
        Number of laser iterations.

    Returns
    -------
    array, shape (..., B)
        Expected recorded counts, ``N * (1 - exp(-lam_j)) * exp(-sum_{i<j} lam_i)``.

    Notes
    -----
    The detector records at most one photon per iteration, the first one, so
    later bins are shadowed by earlier ones. Computed with ``expm1`` and an
    exclusive cumulative sum, so it stays finite as detection probability -> 1.
    """
    lam = jnp.asarray(rate_per_iteration)
    lam = jnp.clip(lam, 0.0, None)
    before = _exclusive_cumsum(lam)
    return iterations * (-jnp.expm1(-lam)) * jnp.exp(-before)


def deadtime_expected(rate_per_iteration, iterations, spads=1, dead_bins=None):
    """Expected counts of a zone of ``spads`` detectors, each with a non-paralyzable dead time.

    Parameters
    ----------
    rate_per_iteration : array, shape (..., B)
        Mean photons reaching the zone in each bin per laser iteration (>= 0),
        shared equally by its detectors.
    iterations : float
        Number of laser iterations.
    spads : int or float
        Independent detectors in the zone, ``M`` (>= 1).
    dead_bins : float or None
        Dead time after a detection, in bins (> 0); None: blind for the rest of
        the iteration (Coates' first-photon model per detector).

    Returns
    -------
    array, shape (..., B)
        ``N * M * d_j`` with ``d_j`` the detection probability of one detector in
        bin ``j``.

    Notes
    -----
    Each detector sees ``mu_j = lam_j / M`` and is alive at the start of the
    window. A detection in bin ``i`` (uniform inside the bin) keeps it dead in
    the next ``k = floor(D)`` bins and in a fraction ``f = D - k`` of bin
    ``i + k + 1``, ``D`` the dead time in bins:

        d_j = (1 - sum_{m=1..k} d_{j-m} - f d_{j-k-1}) (1 - exp(-mu_j)).

    With no dead time limit this is ``(1 - exp(-mu_j)) exp(-sum_{i<j} mu_i)``
    (Coates). For a constant rate ``n`` per bin it tends to ``n / (1 + n D)``,
    the non-paralyzable formula, once ``n`` is small. Computed by a scan over
    the bins (differentiable).
    """
    lam = jnp.clip(jnp.asarray(rate_per_iteration), 0.0, None)
    m = jnp.asarray(spads, lam.dtype)
    if dead_bins is None:
        return m * pileup_expected(lam / m, iterations)
    p = -jnp.expm1(-lam / m)
    n_bins = lam.shape[-1]
    dead = jnp.asarray(dead_bins, lam.dtype)
    k = jnp.floor(dead)
    f = dead - k
    k = k.astype(jnp.int32)
    lead = p.shape[:-1]
    pt = jnp.moveaxis(p, -1, 0)  # (B, ...)

    def cum_at(cum, i):
        # cum[i] = sum of detections before bin i (0 for i <= 0)
        return jnp.where(i > 0, jnp.take(cum, jnp.clip(i, 0, n_bins), axis=0), 0.0)

    def step(cum, j):
        dead_full = cum_at(cum, j) - cum_at(cum, j - k)
        dead_part = f * (cum_at(cum, j - k) - cum_at(cum, j - k - 1))
        d = jnp.clip(1.0 - dead_full - dead_part, 0.0, 1.0) * pt[j]
        cum = cum.at[j + 1].set(cum_at(cum, j) + d)
        return cum, d

    cum0 = jnp.zeros((n_bins + 1,) + lead, lam.dtype)
    _, d = jax.lax.scan(step, cum0, jnp.arange(n_bins))
    return iterations * m * jnp.moveaxis(d, 0, -1)


def coates_correction(counts, iterations):
    """Invert pile-up: estimate photons per iteration per bin from counts.

    Parameters
    ----------
    counts : array, shape (..., B)
        Recorded counts (or their expectation).
    iterations : float
        Number of laser iterations.

    Returns
    -------
    array, shape (..., B)
        ``lam_j = -log(1 - c_j / (N - sum_{i<j} c_i))``. Bins after the
        detector was fully saturated (no iterations left) get ``inf``; a bin
        that took every remaining iteration also gets ``inf``: the data hold no
        finite estimate there.
    """
    c = jnp.asarray(counts)
    remaining = iterations - _exclusive_cumsum(c)
    safe_remaining = jnp.where(remaining > 0, remaining, 1.0)
    frac = jnp.where(remaining > 0, c / safe_remaining, 1.0)
    frac = jnp.clip(frac, 0.0, 1.0)
    return -jnp.log1p(-frac)
