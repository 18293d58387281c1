"""The capture noise model, written once for every room: the floor per bin, and captures drawn from expectations.

Two halves:

- **Rates to counts per bin.** A rate ``r`` (Hz) puts ``r * bin_width * 1e-12`` photons into a bin per laser
  iteration (:func:`per_bin`; its inverse :func:`rate_hz`). The *floor* is the light that does not come from the
  flash: the dark rate plus, with the lights on, the ambient rate (:func:`floor_rate_hz`); per bin and iteration
  :func:`floor_per_bin`, per bin of a capture (``iterations`` times that) :func:`floor_counts`.
- **Expected counts to captures** (:class:`CaptureNoise`, built from a sensor by :meth:`CaptureNoise.of`): one
  capture's counts are Poisson about their expectation and clipped at the register maximum
  (:meth:`~CaptureNoise.draw`); the mean of ``repeats`` captures is drawn as one Poisson sum per bin, split into its
  captures only where the clip bites (:meth:`~CaptureNoise.mean_of_repeats`).

The simulators (``sample``, ``simulate``), the dataset build, the design planner's data, the ideal observer, the
capture planner's simulated rig and the TMF8828 emulator all draw through :class:`CaptureNoise`; nothing else calls
a Poisson sampler on captures (the benchmarks of histogram formation and of the serial link excepted).

Notes
-----
Where a new noise term goes: a term of the capture that is not plain Poisson about the expectation (a deterministic
pedestal, excess or sub-Poisson floor noise, a per-capture gain jitter) is a field of :class:`CaptureNoise` (neutral by
default), filled from its :class:`~nlosplan.sensor_models.config.SensorConfig` field in :meth:`CaptureNoise.of` and
applied in :meth:`~CaptureNoise.draw` and :meth:`~CaptureNoise.mean_of_repeats`: every room above then draws it.
A term of the *expectation* (what a bin holds on average) goes into
:func:`~nlosplan.sensor_models.pipeline.counts_from_rates` instead, which every backend calls.

Examples
--------
>>> import numpy as np
>>> from nlosplan.sensor_models import preset
>>> sensor = preset("tmf8828-3x3-short")
>>> noise = CaptureNoise.of(sensor)
>>> noise.max_count == 2**24 - 1
True
>>> noise.draw(np.random.default_rng(0), np.full((3, 3, 128), 5.0)).shape
(3, 3, 128)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nlosplan.errors import UserError

__all__ = ["EXACT_POISSON_MAX_MEAN", "CaptureNoise", "floor_counts", "floor_per_bin", "floor_rate_hz", "per_bin",
           "rate_hz", "sample_poisson"]

#: Means up to this value are sampled with JAX's exact Poisson sampler. It works in float32 internally, so its
#: draws are integer-exact only below 2**24; a mean of 4e6 keeps draws there with overwhelming probability
#: (>2000 standard deviations). Above, a Gaussian with the same mean and variance is used (its skewness,
#: ``lam**-0.5 < 5e-4``, is the only error).
EXACT_POISSON_MAX_MEAN: float = 4.0e6


# ----------------------------------------------------------------------------- rates -> counts per bin
def per_bin(rate_hz, bin_width_ps):
    """Photons per bin and laser iteration of a rate: ``rate_hz * bin_width_ps * 1e-12``.

    Parameters
    ----------
    rate_hz : float or array
        Photons per second (Hz).
    bin_width_ps : float or array
        Bin width, ps.

    Returns
    -------
    float or array (broadcast; JAX arrays and tracers stay JAX)
    """
    return rate_hz * bin_width_ps * 1e-12


def rate_hz(counts_per_bin, iterations, bin_width_ps):
    """The rate (Hz) whose counts per bin of a capture of ``iterations`` laser iterations are ``counts_per_bin``.

    The inverse of ``iterations * per_bin(rate, bin_width_ps)``: ``counts_per_bin / (iterations * bin_width_ps * 1e-12)``.
    """
    return counts_per_bin / (iterations * bin_width_ps * 1e-12)


def floor_rate_hz(dark_rate_hz, ambient_rate_hz, lights):
    """The floor's rate, Hz: ``dark_rate_hz + ambient_rate_hz * lights``.

    Parameters
    ----------
    dark_rate_hz, ambient_rate_hz : float or array
        The sensor's rates (a pruned term: 0).
    lights : float, bool or array
        1 with the lights on, 0 with them off.
    """
    return dark_rate_hz + ambient_rate_hz * lights


def floor_per_bin(sensor, lights_on: bool) -> float:
    """The sensor's floor (dark, plus ambient with the lights on) in photons per bin and laser iteration."""
    rate = floor_rate_hz(sensor.dark_rate_hz, sensor.ambient_rate_hz, 1.0 if lights_on else 0.0)
    return per_bin(rate, sensor.bin_width_ps)


def floor_counts(sensor, lights_on: bool) -> float:
    """The sensor's floor in counts per bin of one capture: :func:`floor_per_bin` times ``iterations``."""
    return floor_per_bin(sensor, lights_on) * sensor.iterations


# ----------------------------------------------------------------------------- expected counts -> captures
def sample_poisson(key, mean, *, exact_max_mean: float = EXACT_POISSON_MAX_MEAN):
    """Draw Poisson counts with a JAX key, exactly for small means and without overflow for huge ones.

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
    jax array of int64, shape (...)
    """
    from nlosplan._jax import jax, jnp

    mean = jnp.asarray(mean)
    mean = jnp.clip(mean, 0.0, None)
    k_exact, k_normal = jax.random.split(key)
    exact = jax.random.poisson(k_exact, jnp.minimum(mean, exact_max_mean), dtype=jnp.int64)
    mean64 = mean.astype(jnp.float64)
    z = jax.random.normal(k_normal, mean.shape, dtype=jnp.float64)
    approx = jnp.clip(jnp.round(mean64 + jnp.sqrt(mean64) * z), 0.0, 9.0e18).astype(jnp.int64)
    return jnp.where(mean <= exact_max_mean, exact, approx)


def _is_numpy(rng) -> bool:
    """True for a NumPy Generator, False for a JAX key (JAX is imported only then: the emulators draw with NumPy)."""
    if isinstance(rng, np.random.Generator):
        return True
    from nlosplan._jax import jax

    if isinstance(rng, jax.Array):
        return False
    raise UserError(f"draw captures with a numpy Generator or a JAX random key, not {type(rng).__name__}")


@dataclass(frozen=True)
class CaptureNoise:
    """How a capture's counts scatter about their expectation (see the module notes).

    Parameters
    ----------
    max_count : int or None
        The register maximum a bin is clipped at (the TMF8828's 24 bits); None: no clip.

    Notes
    -----
    Hashable: a JAX program that draws captures takes it as a static argument.
    """

    max_count: int | None = None

    @classmethod
    def of(cls, sensor) -> "CaptureNoise":
        """The noise of ``sensor``'s captures: its register clip when ``saturation`` is on."""
        return cls(max_count=int(sensor.max_count) if sensor.saturation else None)

    def draw(self, rng, mean):
        """One capture per entry of ``mean``: Poisson counts, clipped at :attr:`max_count`.

        Parameters
        ----------
        rng : numpy.random.Generator or jax random key
            Explicit randomness; a Generator draws with NumPy (``rng.poisson``), a key with
            :func:`sample_poisson` (traceable: ``jit`` and ``vmap`` apply).
        mean : array, shape (...)
            Expected counts (negative entries count as 0). Broadcast it to ``(repeats, ...)`` for repeats.

        Returns
        -------
        ndarray (NumPy) or jax array (JAX) of int64, shape (...)
        """
        if _is_numpy(rng):
            counts = rng.poisson(np.maximum(mean, 0.0))
            return counts if self.max_count is None else np.minimum(counts, self.max_count)
        from nlosplan._jax import jnp

        counts = sample_poisson(rng, mean)
        return counts if self.max_count is None else jnp.minimum(counts, self.max_count)

    def mean_of_repeats(self, rng: np.random.Generator, mean, repeats: int) -> np.ndarray:
        """The mean of ``repeats`` independent captures of ``mean``, float64, same shape.

        Drawn as one Poisson sum per bin, ``S ~ Poisson(repeats * mean)``, divided by ``repeats``: the same
        distribution as the mean of ``repeats`` captures at ``1 / repeats`` of the draws. Where a sum exceeds
        :attr:`max_count` with ``repeats > 1``, it is split into its captures (multinomially: given the sum, that is
        their joint law) and each is clipped first, so the clip stays exact.

        Parameters
        ----------
        rng : numpy.random.Generator
        mean : array, shape (...)
            Expected counts of one capture.
        repeats : int
            Captures averaged (>= 1).
        """
        if not isinstance(rng, np.random.Generator):
            raise UserError(f"the mean of repeated captures is drawn with a numpy Generator, not {type(rng).__name__}")
        if isinstance(repeats, bool) or int(repeats) < 1:
            raise UserError(f"repeats={repeats!r} must be >= 1")
        repeats = int(repeats)
        total = rng.poisson(np.maximum(repeats * np.asarray(mean, np.float64), 0.0))
        top = self.max_count
        if top is not None and repeats > 1 and np.any(total > top):
            over = np.flatnonzero(total > top)
            left, clipped = total.reshape(-1)[over], np.zeros(over.size, np.int64)
            for k in range(repeats, 1, -1):  # one capture's share of what is left, then the rest
                part = rng.binomial(left, 1.0 / k)
                clipped += np.minimum(part, top)
                left = left - part
            clipped += np.minimum(left, top)
            total.reshape(-1)[over] = clipped
        elif top is not None:
            total = np.minimum(total, top)
        return total / float(repeats)
