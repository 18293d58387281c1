"""Single place where JAX is configured for nlosplan.

64-bit types are enabled so that float64 is *available*; every numerical
function follows the dtype of its inputs (float32 stays float32). Import
``jax``/``jnp`` from here inside the package.

Compiled programs are kept on disk between runs (JAX's persistent
compilation cache) in ``$NLOSPLAN_CACHE/jax`` or ``~/.cache/nlosplan/jax``,
at most :data:`COMPILATION_CACHE_BYTES` (least recently used dropped): the
simulator's batched forward pass and the bound's Jacobian take 5-20 s each
to compile on 2 cores, every run and every worker process, and a program
compiled once is loaded in well under a second after that. Only programs
that took at least 0.5 s to compile are kept. ``NLOSPLAN_JAX_CACHE=0``
turns it off; a cache folder set through JAX's own
``JAX_COMPILATION_CACHE_DIR`` is left as it is.
"""

import os
from pathlib import Path

import jax
import jax.numpy as jnp

from nlosplan.resources import cache_root

jax.config.update("jax_enable_x64", True)

#: Largest size of the on-disk compilation cache, bytes.
COMPILATION_CACHE_BYTES = 2 * 1024**3


def compilation_cache_dir() -> Path | None:
    """Where compiled programs are kept (None when ``NLOSPLAN_JAX_CACHE`` turns the cache off)."""
    if os.environ.get("NLOSPLAN_JAX_CACHE", "1").strip().lower() in ("0", "off", "false", "no"):
        return None
    if jax.config.jax_compilation_cache_dir:
        return Path(jax.config.jax_compilation_cache_dir)
    return cache_root() / "jax"


def _use_compilation_cache() -> None:
    where = compilation_cache_dir()
    if where is None:
        return
    jax.config.update("jax_compilation_cache_dir", str(where))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)
    jax.config.update("jax_compilation_cache_max_size", COMPILATION_CACHE_BYTES)


_use_compilation_cache()

__all__ = ["jax", "jnp", "compilation_cache_dir", "COMPILATION_CACHE_BYTES"]
