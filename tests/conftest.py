import os
import tempfile
from pathlib import Path

import pytest

SHARED = Path(__file__).resolve().parents[1].parent / "shared"

# JAX's on-disk compilation cache (see nlosplan._jax) for this test session only, shared by the tests, the CLI
# processes they start and pytest-xdist's workers (set before JAX is imported, and before the workers start: they
# inherit it); the user's cache is never touched. The process that made it removes it at the end.
_JAX_CACHE = None
if "JAX_COMPILATION_CACHE_DIR" not in os.environ:
    _JAX_CACHE = os.environ["JAX_COMPILATION_CACHE_DIR"] = tempfile.mkdtemp(prefix="nlosplan-test-jax-")


def pytest_unconfigure(config):
    if _JAX_CACHE:
        import shutil

        shutil.rmtree(_JAX_CACHE, ignore_errors=True)


@pytest.fixture(scope="session", autouse=True)
def _reference_cache_in_tmp(tmp_path_factory):
    """The design reference cache of the test session in a temporary folder, not the user's."""
    mp = pytest.MonkeyPatch()
    mp.setenv("NLOSPLAN_CACHE", str(tmp_path_factory.mktemp("nlosplan-cache")))
    yield
    mp.undo()


@pytest.fixture(scope="module", autouse=True)
def _release_compiled_code():
    """Drop JAX's compiled executables after each test module.

    Every XLA CPU executable keeps its own memory mappings, and the caches keep
    every executable: a whole test run in one process (~1,300 tests, ~65
    mappings each) passed the kernel's vm.max_map_count (65,530), and XLA's
    next compilation died with SIGSEGV (three full runs, at different tests).
    Cleared per module the process stays near 1,000 mappings.
    """
    yield
    import sys

    if "jax" in sys.modules:
        import gc

        sys.modules["jax"].clear_caches()
        gc.collect()


@pytest.fixture
def shared_data() -> Path:
    path = SHARED / "data"
    if not path.is_dir():
        pytest.skip(f"shared data not found at {path}")
    return path


@pytest.fixture
def one_torch_thread():
    """One torch thread: faster than two on a shared 2-core runner, and the same results every run."""
    import torch

    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


@pytest.fixture(scope="session")
def grbl_sim_exe(tmp_path_factory) -> Path:
    """GRBL 1.1h built with grbl-sim from ../shared/vendor, once per test run (skipped only without gcc/make)."""
    from grbl_firmware import build_grbl_sim, missing_tools

    missing = missing_tools()
    if missing:
        pytest.skip(f"real-firmware tests need {' and '.join(missing)} to build grbl-sim")
    return build_grbl_sim(tmp_path_factory.mktemp("grbl-sim"))


@pytest.fixture(params=[pytest.param("real", marks=pytest.mark.real_firmware), "emulated"])
def grbl_device(request, tmp_path):
    """The same GRBL scenarios on the real firmware (grbl-sim, fresh EEPROM) and on the project's emulator."""
    from grbl_firmware import GrblFirmware, mirror_grbl

    if request.param == "real":
        dev = GrblFirmware(request.getfixturevalue("grbl_sim_exe"), tmp_path / "grbl-eeprom")
    else:
        dev = mirror_grbl()
    dev.start()
    yield dev
    dev.close()
