"""The width of the Gaussian impulse response, and Gaussian widths that add, computed once for every room.

The pulse and the timing jitter are Gaussians (FWHM in ps) convolved
together: the impulse response's FWHM is ``sqrt(pulse^2 + jitter^2)`` (widths
add in quadrature, :func:`in_quadrature`) and its standard deviation that over
``FWHM_PER_SIGMA`` (2.3548, :func:`sigma_of_fwhm`). The same sum widens a
jitter by an extra jitter (a degradation's or a plausible world's
``extra_jitter_fwhm_ps``). The sensor pipeline, the fast transport, the
degradation of a captured reference to a design, the calibration, the design
cost and the design planner's worlds all use these functions.

Names (one per meaning): ``jitter_fwhm_ps`` the sensor's timing jitter,
``pulse_fwhm_ps`` its pulse, ``extra_jitter_fwhm_ps`` jitter added to captures
that already carry the sensor's, ``impulse_fwhm_ps``/``impulse_sigma_ps`` the
whole impulse response (``SensorConfig.impulse_sigma_ps``).
"""

from __future__ import annotations

import math

from nlosplan.constants import FWHM_PER_SIGMA

__all__ = ["impulse_fwhm_ps", "impulse_sigma_ps", "in_quadrature", "sigma_of_fwhm"]


def in_quadrature(fwhm_a, fwhm_b):
    """The FWHM of two Gaussians convolved, ps: ``sqrt(fwhm_a**2 + fwhm_b**2)``.

    Parameters
    ----------
    fwhm_a, fwhm_b : float or array
        Python or NumPy floats give a float (``math.hypot``, exact); JAX
        arrays and tracers give an array with a finite gradient at zero width
        (traceable, for the fast transport and the fits).
    """
    if isinstance(fwhm_a, (int, float)) and isinstance(fwhm_b, (int, float)):
        return math.hypot(fwhm_a, fwhm_b)
    from nlosplan._jax import jnp

    s2 = fwhm_a * fwhm_a + fwhm_b * fwhm_b
    ok = s2 > 0
    return jnp.where(ok, jnp.sqrt(jnp.where(ok, s2, 1.0)), 0.0)


def sigma_of_fwhm(fwhm_ps):
    """A Gaussian's standard deviation from its FWHM: ``fwhm_ps / 2.3548`` (float or array, as given)."""
    return fwhm_ps / FWHM_PER_SIGMA


def impulse_fwhm_ps(pulse_fwhm_ps, jitter_fwhm_ps):
    """FWHM of pulse ⊗ jitter, ps: :func:`in_quadrature` of the two (float or array, as it)."""
    return in_quadrature(pulse_fwhm_ps, jitter_fwhm_ps)


def impulse_sigma_ps(pulse_fwhm_ps, jitter_fwhm_ps):
    """Standard deviation of pulse ⊗ jitter, ps: :func:`impulse_fwhm_ps` / 2.3548 (float or array, as it)."""
    return sigma_of_fwhm(impulse_fwhm_ps(pulse_fwhm_ps, jitter_fwhm_ps))
