"""Single place where JAX is configured for nlosplan.

64-bit types are enabled so that float64 is *available*; every numerical
function follows the dtype of its inputs (float32 stays float32). Import
``jax``/``jnp`` from here inside the package.
"""

import jax
import jax.numpy as jnp

jax.config.update("jax_enable_x64", True)

__all__ = ["jax", "jnp"]
