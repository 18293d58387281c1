"""nlosplan._jax.FAST_COMPILE: XLA's CPU option for the programs that compile faster with it, only where the installed
jaxlib is one it was tested on and the programs compile for the CPU."""

import importlib.metadata

import numpy as np

import nlosplan._jax as J


def _options(monkeypatch, jaxlib: str, plugins=(), platforms: str | None = None) -> dict:
    monkeypatch.setattr(importlib.metadata, "version", lambda name: jaxlib)
    monkeypatch.setattr(J, "find_spec", lambda name: object() if name in plugins else None)
    if platforms is None:
        monkeypatch.delenv("JAX_PLATFORMS", raising=False)
    else:
        monkeypatch.setenv("JAX_PLATFORMS", platforms)
    return J._fast_compile()


def test_the_tested_jaxlib_on_the_cpu_compiles_without_fusion_emitters(monkeypatch):
    assert _options(monkeypatch, "0.10.2") == {"xla_cpu_use_fusion_emitters": False}
    # a GPU plugin told to stay on the CPU still compiles for the CPU
    assert _options(monkeypatch, "0.10.2", ("jax_cuda12_plugin",), "cpu") == {"xla_cpu_use_fusion_emitters": False}


def test_an_untested_jaxlib_or_a_gpu_gets_no_option(monkeypatch):
    assert _options(monkeypatch, "0.4.30") == {}
    assert _options(monkeypatch, "1.0.0") == {}
    assert _options(monkeypatch, "0.10.2", ("jax_cuda12_plugin",)) == {}
    assert _options(monkeypatch, "0.10.2", ("jax_cuda13_plugin",), "cuda,cpu") == {}


def test_a_program_compiled_with_the_options_gives_the_same_numbers():
    def f(x):
        return J.jnp.cumsum(J.jnp.sin(x) * J.jnp.exp(-x / 7.0)) @ x

    x = J.jnp.linspace(0.0, 5.0, 301, dtype=J.jnp.float32)
    fast = J.jax.jit(f, compiler_options=J.FAST_COMPILE or None)(x)
    plain = J.jax.jit(f)(x)
    assert np.isfinite(float(fast))
    np.testing.assert_allclose(float(fast), float(plain), rtol=1e-5)
