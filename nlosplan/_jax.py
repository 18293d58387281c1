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

Programs that compile faster without XLA's CPU fusion emitters at an equal run time take
:data:`FAST_COMPILE` as their ``compiler_options`` (the simulators' shared-term programs and the bound's Jacobian:
a design run's references; on a fresh cache a 3x3 reference's first run 12.7 -> 10.4 s of CPU on 2 cores). Not
every program: the plain batched simulator runs the retroreflective model ~10 % slower with them. Empty where the
installed jaxlib is not one of :data:`FAST_COMPILE_TESTED_ON` (an option XLA does not know fails the compile) and
where a GPU plugin is installed (:data:`GPU_PLUGINS`).
"""

import os
from importlib.util import find_spec
from pathlib import Path

import jax
import jax.numpy as jnp

from nlosplan.resources import cache_root

#: jaxlib versions (prefixes) known to take :data:`FAST_COMPILE`'s options.
FAST_COMPILE_TESTED_ON = ("0.10.",)
#: JAX's GPU plugins: with one installed (and ``JAX_PLATFORMS`` not ``cpu``) the programs compile for the GPU, where
#: the option is not the CPU backend's.
GPU_PLUGINS = ("jax_cuda12_plugin", "jax_cuda13_plugin", "jax_rocm7_plugin")


def _fast_compile() -> dict:
    from importlib.metadata import PackageNotFoundError, version

    try:
        jaxlib = version("jaxlib")
    except PackageNotFoundError:
        return {}
    on_cpu = os.environ.get("JAX_PLATFORMS", "").strip().lower() == "cpu" or not any(
        find_spec(name) for name in GPU_PLUGINS)
    return {"xla_cpu_use_fusion_emitters": False} if on_cpu and jaxlib.startswith(FAST_COMPILE_TESTED_ON) else {}


#: ``compiler_options`` of the programs that compile faster with them (see the module notes); {} where untested.
FAST_COMPILE: dict = _fast_compile()

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

__all__ = ["jax", "jnp", "compilation_cache_dir", "COMPILATION_CACHE_BYTES", "FAST_COMPILE",
           "FAST_COMPILE_TESTED_ON"]
