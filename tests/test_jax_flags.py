"""nlosplan._jax: the XLA flags set before JAX starts its backend, and only where the installed jaxlib knows them."""

import importlib.metadata
import os
import subprocess
import sys

import nlosplan._jax as J


def _flags_after(monkeypatch, env: str | None, jaxlib: str) -> str | None:
    if env is None:
        monkeypatch.delenv("XLA_FLAGS", raising=False)
    else:
        monkeypatch.setenv("XLA_FLAGS", env)
    monkeypatch.setattr(importlib.metadata, "version", lambda name: jaxlib)
    J._default_xla_flags()
    return os.environ.get("XLA_FLAGS")


def test_the_default_flag_is_added_to_what_the_user_set(monkeypatch):
    assert _flags_after(monkeypatch, None, "0.10.2") == "--xla_cpu_use_fusion_emitters=false"
    assert _flags_after(monkeypatch, "--xla_force_host_platform_device_count=2", "0.10.2") == (
        "--xla_force_host_platform_device_count=2 --xla_cpu_use_fusion_emitters=false")


def test_a_flag_the_user_names_is_left_as_given(monkeypatch):
    assert _flags_after(monkeypatch, "--xla_cpu_use_fusion_emitters=true", "0.10.2") == (
        "--xla_cpu_use_fusion_emitters=true")


def test_an_untested_jaxlib_gets_no_flag_xla_could_stop_on(monkeypatch):
    assert _flags_after(monkeypatch, None, "0.4.30") is None
    assert _flags_after(monkeypatch, "--xla_dump_to=/tmp/x", "1.0.0") == "--xla_dump_to=/tmp/x"


def test_a_fresh_process_runs_jax_with_the_flag_set():
    code = ("import os, nlosplan._jax as J; x = J.jnp.arange(4.0).sum(); "
            "print(os.environ.get('XLA_FLAGS'), float(x))")
    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120)
    assert out.returncode == 0, out.stderr
    version = importlib.metadata.version("jaxlib")
    expected = "--xla_cpu_use_fusion_emitters=false" if version.startswith(J.XLA_FLAGS_TESTED_ON) else "None"
    assert out.stdout.split() == [expected, "6.0"]
