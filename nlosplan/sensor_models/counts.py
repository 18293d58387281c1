"""From expected photons per iteration to recorded counts.

Pile-up (Coates model) and its correction, Poisson sampling that stays exact
for small means and never overflows for huge ones, and 24-bit saturation.
Pure JAX functions with explicit random keys.
"""

from __future__ import annotations

from nlosplan._jax import jax, jnp
from nlosplan.constants import MAX_COUNT_24BIT

#: Means up to this value are sampled with the exact Poisson sampler. JAX's
#: sampler works in float32 internally, so its draws are integer-exact only
#: below 2**24; a mean of 4e6 keeps draws there with overwhelming probability
#: (>2000 standard deviations). Above, a Gaussian with the same mean and
#: variance is used (its skewness, ``lam**-0.5 < 5e-4``, is the only error).
EXACT_POISSON_MAX_MEAN: float = 4.0e6


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


def sample_poisson(key, mean, *, exact_max_mean: float = EXACT_POISSON_MAX_MEAN):
    """Draw Poisson counts, exactly for small means and without overflow for huge ones.

    Parameters
    ----------
    key : jax.random key
        Random key (explicit; no global state).
    mean : array, shape (...)
        Non-negative finite means.
    exact_max_mean : float
        Means up to this use the exact sampler; above, a moment-matched
        Gaussian rounded to integers and clipped at 0.

    Returns
    -------
    array of int64, shape (...)
    """
    mean = jnp.asarray(mean)
    mean = jnp.clip(mean, 0.0, None)
    k_exact, k_normal = jax.random.split(key)
    exact = jax.random.poisson(k_exact, jnp.minimum(mean, exact_max_mean), dtype=jnp.int64)
    mean64 = mean.astype(jnp.float64)
    z = jax.random.normal(k_normal, mean.shape, dtype=jnp.float64)
    approx = jnp.clip(jnp.round(mean64 + jnp.sqrt(mean64) * z), 0.0, 9.0e18).astype(jnp.int64)
    return jnp.where(mean <= exact_max_mean, exact, approx)


def saturate(counts, max_count: int = MAX_COUNT_24BIT):
    """Clip counts at the register maximum (``2**24 - 1`` on the TMF8828)."""
    return jnp.minimum(counts, max_count)
