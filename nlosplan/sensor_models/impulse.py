"""The width of the Gaussian impulse response, computed once for every room.

The pulse and the timing jitter are Gaussians (FWHM in ps) convolved
together: the impulse response's FWHM is ``sqrt(pulse^2 + jitter^2)`` (widths
add in quadrature) and its standard deviation that over
``FWHM_PER_SIGMA`` (2.3548). The sensor pipeline, the fast transport, the
degradation of a captured reference to a design, the calibration and the
design cost all use these two functions.
"""

from __future__ import annotations

import math

from nlosplan.constants import FWHM_PER_SIGMA

__all__ = ["impulse_fwhm_ps", "impulse_sigma_ps"]


def impulse_fwhm_ps(pulse_fwhm_ps, jitter_fwhm_ps):
    """FWHM of pulse ⊗ jitter, ps: ``sqrt(pulse_fwhm_ps**2 + jitter_fwhm_ps**2)``.

    Parameters
    ----------
    pulse_fwhm_ps, jitter_fwhm_ps : float or array
        Python or NumPy floats give a float (``math.hypot``, exact); JAX
        arrays and tracers give an array with a finite gradient at zero width
        (traceable, for the fast transport and the fits).
    """
    if isinstance(pulse_fwhm_ps, (int, float)) and isinstance(jitter_fwhm_ps, (int, float)):
        return math.hypot(pulse_fwhm_ps, jitter_fwhm_ps)
    from nlosplan._jax import jnp

    s2 = pulse_fwhm_ps * pulse_fwhm_ps + jitter_fwhm_ps * jitter_fwhm_ps
    ok = s2 > 0
    return jnp.where(ok, jnp.sqrt(jnp.where(ok, s2, 1.0)), 0.0)


def impulse_sigma_ps(pulse_fwhm_ps, jitter_fwhm_ps):
    """Standard deviation of pulse ⊗ jitter, ps: :func:`impulse_fwhm_ps` / 2.3548 (float or array, as it)."""
    return impulse_fwhm_ps(pulse_fwhm_ps, jitter_fwhm_ps) / FWHM_PER_SIGMA
