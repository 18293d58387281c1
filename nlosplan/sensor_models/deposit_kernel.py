"""The compiled arrival-time deposit: built on first use, loaded into XLA as a CPU custom call.

:func:`~nlosplan.sensor_models.transient.deposit_at` adds every arrival's
weight onto two nodes of its row. On XLA's CPU backend the scatter-add of that
linear map, and above all the fused loop that built its update windows from the
raveled (samples x cells) arrivals, cost ~3/4 of a simulated DENALI scene
(issue 20's profile, docs/fast-simulator.md); the same sums in one C++ loop
(``kernels/deposit.cc``, an XLA FFI handler) over the arrivals in their own
shape make ``bench simulate`` 2-3.6x faster at equal results.

The source ships with the package and is compiled here, once per machine and
jaxlib version, against the headers jaxlib ships (``jax.ffi.include_dir()``),
with the C++ compiler named by ``$CXX`` or found as ``c++``/``g++``/``clang++``.
The library is kept in ``$NLOSPLAN_CACHE/kernels`` (or
``~/.cache/nlosplan/kernels``) under a name that hashes the source, the jaxlib
version, the compiler and its flags; a second process (or Dask worker) loads
it in milliseconds. Builds are atomic and locked, so parallel workers build it
once.

Where it cannot be built (no compiler, a failed build) the simulator uses the
XLA scatter-add (``deposit="window"``), which gives the same result up to
float summation order, and says so once (a ``RuntimeWarning`` naming the
reason). ``NLOSPLAN_DEPOSIT_KERNEL=0`` turns the kernel off on purpose (no
warning).
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import shutil
import subprocess
import tempfile
import warnings
from pathlib import Path

import numpy as np
from filelock import FileLock

from nlosplan._jax import jax
from nlosplan.resources import cache_root

#: Name of the XLA custom-call target.
TARGET = "nlosplan_deposit"
#: Environment variable that turns the kernel off (``0``, ``off``, ``false``, ``no``).
ENV_SWITCH = "NLOSPLAN_DEPOSIT_KERNEL"
#: Compiler flags (no ``-march``: the cached library may be shared by machines with different CPUs).
FLAGS = ("-O3", "-std=c++17", "-shared", "-fPIC", "-fno-math-errno")
#: Longest a build may take, seconds.
BUILD_TIMEOUT_S = 300
SOURCE = Path(__file__).with_name("kernels") / "deposit.cc"

_STATE: dict = {}  # "ok": bool, "reason": str (when not ok), "path": Path (when ok)
_REGISTERED: list = []  # the library whose handler XLA holds in this process


def kernel_dir() -> Path:
    """``$NLOSPLAN_CACHE/kernels`` or ``~/.cache/nlosplan/kernels``."""
    return cache_root() / "kernels"


def _disabled() -> bool:
    return os.environ.get(ENV_SWITCH, "1").strip().lower() in ("0", "off", "false", "no")


def _compiler() -> str | None:
    named = os.environ.get("CXX")
    if named:
        return shutil.which(named) or (named if Path(named).is_file() else None)
    for name in ("c++", "g++", "clang++"):
        found = shutil.which(name)
        if found:
            return found
    return None


def _compiler_id(cxx: str) -> str:
    try:
        out = subprocess.run([cxx, "--version"], capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.SubprocessError) as exc:
        raise _BuildFailed(f"the C++ compiler {cxx} does not run ({exc})") from None
    return (out.stdout or out.stderr).splitlines()[0] if (out.stdout or out.stderr) else cxx


class _BuildFailed(Exception):
    """The kernel cannot be built or loaded here; the message says why (shown in the fallback's warning)."""


def library_path(cxx: str) -> Path:
    """Where the library built with ``cxx`` for this source and jaxlib lives (built or not)."""
    import jaxlib

    key = hashlib.sha256()
    for part in (SOURCE.read_bytes(), jaxlib.__version__.encode(), _compiler_id(cxx).encode(), " ".join(FLAGS).encode()):
        key.update(part)
        key.update(b"\0")
    return kernel_dir() / f"deposit-{key.hexdigest()[:20]}.so"


def _build(cxx: str, target: Path) -> None:
    """Compile the source into ``target`` atomically (a temporary file in the same folder, then renamed)."""
    target.parent.mkdir(parents=True, exist_ok=True)
    with FileLock(str(target) + ".lock", timeout=BUILD_TIMEOUT_S):
        if target.exists():
            return
        fd, tmp = tempfile.mkstemp(prefix=target.name + ".", suffix=".tmp", dir=target.parent)
        os.close(fd)
        try:
            cmd = [cxx, *FLAGS, "-I", jax.ffi.include_dir(), str(SOURCE), "-o", tmp]
            try:
                out = subprocess.run(cmd, capture_output=True, text=True, timeout=BUILD_TIMEOUT_S)
            except (OSError, subprocess.SubprocessError) as exc:
                raise _BuildFailed(f"{cxx} failed to run ({exc})") from None
            if out.returncode != 0:
                errors = [ln for ln in out.stderr.splitlines() if "error" in ln] or out.stderr.splitlines() or ["?"]
                raise _BuildFailed(f"{cxx} failed: {errors[0].strip()}")
            os.replace(tmp, target)
        finally:
            if os.path.exists(tmp):
                os.unlink(tmp)


def _load() -> Path:
    if not SOURCE.is_file():
        raise _BuildFailed(f"the kernel source {SOURCE} is missing from the installed package")
    cxx = _compiler()
    if cxx is None:
        raise _BuildFailed("no C++ compiler (set CXX, or install g++ or clang++)")
    path = library_path(cxx)
    if not path.exists():
        _build(cxx, path)
    try:
        lib = ctypes.cdll.LoadLibrary(str(path))
        handler = lib.NlosplanDeposit
    except (OSError, AttributeError) as exc:
        raise _BuildFailed(f"{path} does not load ({exc}); delete it to rebuild") from None
    if not _REGISTERED:  # XLA takes one handler per name and process (a library of the same source)
        jax.ffi.register_ffi_target(TARGET, jax.ffi.pycapsule(handler), platform="cpu")
        _REGISTERED.append(path)
    return path


def status() -> tuple[bool, str]:
    """``(available, why)``: whether the kernel is built and registered in this process (building it if needed).

    ``why`` is the library's path when available, else the reason it is not (the first call that finds it
    unavailable, other than by :data:`ENV_SWITCH`, also warns once).
    """
    if _disabled():
        return False, f"turned off by {ENV_SWITCH}={os.environ.get(ENV_SWITCH)}"
    if "ok" not in _STATE:
        try:
            _STATE.update(ok=True, path=_load())
        except (_BuildFailed, OSError) as exc:
            _STATE.update(ok=False, reason=str(exc))
            warnings.warn(f"nlosplan: the compiled deposit kernel is not available ({exc}); the fast simulator "
                          "uses XLA's scatter-add instead (the same results, 2-3x slower)", RuntimeWarning,
                          stacklevel=2)
    return (True, str(_STATE["path"])) if _STATE["ok"] else (False, _STATE["reason"])


def available() -> bool:
    """Whether :func:`call` can be traced in this process (see :func:`status`)."""
    return status()[0]


def call(positions, weights, rows, n_rows: int, n_nodes: int):
    """The deposit as a custom call (no derivative rule: see ``transient._kernel_deposit``).

    Parameters
    ----------
    positions, weights : array, shape (..., L)
        Fractional node coordinates and weights, one float dtype.
    rows : array of int32, shape (..., L) or (L,)
        The row of each arrival, or of each position along the last axis (the same for every leading index).
    n_rows, n_nodes : int

    Returns
    -------
    array, shape (n_rows, n_nodes)
        Batched under ``vmap`` (leading axes broadcast over all three inputs).
    """
    ok, why = status()
    if not ok:
        raise RuntimeError(f"the compiled deposit kernel is not available: {why}")
    out = jax.ShapeDtypeStruct((n_rows, n_nodes), positions.dtype)
    return jax.ffi.ffi_call(TARGET, out, vmap_method="broadcast_all")(
        positions, weights, rows, n_rows=np.int64(n_rows), n_nodes=np.int64(n_nodes))
