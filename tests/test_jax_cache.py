"""Compiled programs are kept on disk between runs (nlosplan._jax), where the user's cache folder says."""

import os
import subprocess
import sys

import pytest

_SIMULATE = ("from nlosplan.simulators import FastSimulator, corner_scene\n"
             "from nlosplan.sensor_models import preset\n"
             "import nlosplan._jax as j, os\n"
             "if os.environ.get('NLOSPLAN_TEST_KEEP_ALL'): j.jax.config.update("
             "'jax_persistent_cache_min_compile_time_secs', 0.0)\n"
             "print(j.compilation_cache_dir())\n"
             "FastSimulator(corner_scene(), preset('tmf8828-3x3-short'), fidelity='draft').expected()\n")


def _run(env_extra: dict, tmp_path) -> str:
    env = {k: v for k, v in os.environ.items() if k not in ("JAX_COMPILATION_CACHE_DIR", "NLOSPLAN_JAX_CACHE")}
    env.update(env_extra)
    out = subprocess.run([sys.executable, "-c", _SIMULATE], env=env, capture_output=True, text=True, timeout=300,
                         cwd=tmp_path)
    assert out.returncode == 0, out.stderr[-2000:]
    return out.stdout.strip().splitlines()[-1]


@pytest.mark.parametrize("off", ["0", "off"])
def test_no_cache_when_turned_off(tmp_path, off):
    assert _run({"NLOSPLAN_CACHE": str(tmp_path), "NLOSPLAN_JAX_CACHE": off}, tmp_path) == "None"
    assert not (tmp_path / "jax").exists()


def test_simulator_programs_are_kept_under_the_cache_folder(tmp_path):
    # the product keeps programs that took 0.5 s or more to compile; on an idle machine the draft corner scene's
    # may take less, so this run keeps every program (the folder, not the machine's speed, is under test)
    env = {"NLOSPLAN_CACHE": str(tmp_path), "NLOSPLAN_TEST_KEEP_ALL": "1"}
    assert _run(env, tmp_path) == str(tmp_path / "jax")
    kept = sorted(p.name for p in (tmp_path / "jax").iterdir())
    assert any("batched" in name for name in kept), kept
    # JAX's own setting wins
    assert _run({"NLOSPLAN_CACHE": str(tmp_path), "JAX_COMPILATION_CACHE_DIR": str(tmp_path / "mine")},
                tmp_path) == str(tmp_path / "mine")
