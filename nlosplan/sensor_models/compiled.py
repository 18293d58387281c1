"""The transient's compiled kernels: built on first use, loaded into XLA as CPU custom calls.

Two linear maps of the fast simulator run as C++ loops (XLA FFI handlers in ``kernels/``):

- ``deposit.cc``: :func:`~nlosplan.sensor_models.transient.deposit_at` adds every arrival's weight onto
  two nodes of its row. On XLA's CPU backend the scatter-add of that map, and above all the fused loop
  that built its update windows from the raveled (samples x cells) arrivals, cost ~3/4 of a simulated
  DENALI scene (issue 20's profile, docs/fast-simulator.md); one C++ loop over the arrivals in their own
  shape made ``bench simulate`` 2-3.6x faster at equal results.
- ``sum_convolve.cc``: a Lambertian object's two legs convolved and summed over its samples
  (:func:`~nlosplan.sensor_models.transient.sum_convolve`), over the legs' non-zero spans instead of
  FFTs of every (sample, zone) row.
- ``sum_convolve.cc`` also: the detection leg's deposit and that sum in one pass
  (:func:`~nlosplan.sensor_models.transient.deposit_sum_convolve`), one sample's detection rows at a time in a
  small buffer instead of the whole (samples, zones, nodes) leg: the same sums in the same order.

The sources ship with the package and are compiled here into one library, once per machine and
jaxlib version, against the headers jaxlib ships (``jax.ffi.include_dir()``),
with the C++ compiler named by ``$CXX`` or found as ``c++``/``g++``/``clang++``.
The library is kept in ``$NLOSPLAN_CACHE/kernels`` (or
``~/.cache/nlosplan/kernels``) under a name that hashes the sources, the jaxlib
version, the compiler and its flags; a second process (or Dask worker) loads
it in milliseconds. Builds are atomic and locked, so parallel workers build it
once.

Where it cannot be built (no compiler, a failed build) the simulator uses the
XLA paths (the scatter-add ``deposit="window"`` and the FFTs), which give the
same result up to float rounding, and says so once (a ``RuntimeWarning``
naming the reason). ``NLOSPLAN_KERNELS=0`` turns the kernels off on purpose
(no warning).
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

#: XLA custom-call targets and the library symbols of their handlers.
TARGETS = {"nlosplan_deposit": "NlosplanDeposit", "nlosplan_sum_convolve": "NlosplanSumConvolve",
           "nlosplan_deposit_convolve": "NlosplanDepositConvolve"}
#: Environment variable that turns the kernels off (``0``, ``off``, ``false``, ``no``).
ENV_SWITCH = "NLOSPLAN_KERNELS"
#: Compiler flags (no ``-march``: the cached library may be shared by machines with different CPUs).
FLAGS = ("-O3", "-std=c++17", "-fPIC", "-fno-math-errno")
#: Longest a build may take, seconds.
BUILD_TIMEOUT_S = 300
#: The kernels' C++ sources, compiled into one library.
SOURCES = tuple(Path(__file__).with_name("kernels") / name for name in ("deposit.cc", "sum_convolve.cc"))

_STATE: dict = {}  # "ok": bool, "reason": str (when not ok), "path": Path (when ok)
_REGISTERED: list = []  # the library whose handlers XLA holds in this process


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
    """The kernels cannot be built or loaded here; the message says why (shown in the fallback's warning)."""


def library_path(cxx: str) -> Path:
    """Where the library built with ``cxx`` for these sources and jaxlib lives (built or not)."""
    import jaxlib

    key = hashlib.sha256()
    parts = (*(src.read_bytes() for src in SOURCES), jaxlib.__version__.encode(), _compiler_id(cxx).encode(),
             " ".join(FLAGS).encode())
    for part in parts:
        key.update(part)
        key.update(b"\0")
    return kernel_dir() / f"kernels-{key.hexdigest()[:20]}.so"


def _build(cxx: str, target: Path) -> None:
    """Compile the sources into ``target`` atomically (a temporary file in the same folder, then renamed)."""
    target.parent.mkdir(parents=True, exist_ok=True)
    with FileLock(str(target) + ".lock", timeout=BUILD_TIMEOUT_S):
        if target.exists():
            return
        with tempfile.TemporaryDirectory(prefix=target.name + ".", suffix=".tmp", dir=target.parent) as tmp:
            # each source on its own core (most of a compile is parsing jaxlib's FFI header), then one link
            objects = [os.path.join(tmp, src.stem + ".o") for src in SOURCES]
            _run_all(cxx, [[cxx, *FLAGS, "-I", jax.ffi.include_dir(), "-c", str(src), "-o", obj]
                           for src, obj in zip(SOURCES, objects)])
            library = os.path.join(tmp, "kernels.so")
            _run_all(cxx, [[cxx, "-shared", *objects, "-o", library]])
            os.replace(library, target)


def _run_all(cxx: str, commands: list[list[str]]) -> None:
    """Run the compiler commands at once; raise :class:`_BuildFailed` with the first error line of the first failing one."""
    try:
        procs = [subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True) for cmd in commands]
    except OSError as exc:
        raise _BuildFailed(f"{cxx} failed to run ({exc})") from None
    failures = []
    for proc in procs:
        try:
            _, err = proc.communicate(timeout=BUILD_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.communicate()
            err = f"error: no result after {BUILD_TIMEOUT_S} s"
        if proc.returncode != 0:
            failures.append(err)
    if failures:
        lines = failures[0].splitlines()
        errors = [ln for ln in lines if "error" in ln] or lines or ["?"]
        raise _BuildFailed(f"{cxx} failed: {errors[0].strip()}")


def _load() -> Path:
    missing = [src.name for src in SOURCES if not src.is_file()]
    if missing:
        raise _BuildFailed(f"the kernel sources {', '.join(missing)} are missing from the installed package")
    cxx = _compiler()
    if cxx is None:
        raise _BuildFailed("no C++ compiler (set CXX, or install g++ or clang++)")
    path = library_path(cxx)
    if not path.exists():
        _build(cxx, path)
    try:
        lib = ctypes.cdll.LoadLibrary(str(path))
        handlers = {target: getattr(lib, symbol) for target, symbol in TARGETS.items()}
    except (OSError, AttributeError) as exc:
        raise _BuildFailed(f"{path} does not load ({exc}); delete it to rebuild") from None
    if not _REGISTERED:  # XLA takes one handler per name and process (a library of the same sources)
        for target, handler in handlers.items():
            jax.ffi.register_ffi_target(target, jax.ffi.pycapsule(handler), platform="cpu")
        _REGISTERED.append(path)
    return path


def status() -> tuple[bool, str]:
    """``(available, why)``: whether the kernels are built and registered in this process (building them if needed).

    ``why`` is the library's path when available, else the reason it is not (the first call that finds it
    unavailable, other than by :data:`ENV_SWITCH`, also warns once).
    """
    if _disabled():
        return False, f"turned off by {ENV_SWITCH}={os.environ.get(ENV_SWITCH)}"
    backend = jax.default_backend()
    if backend != "cpu":   # a GPU: the kernels are CPU custom calls; XLA's scatter-add and FFTs run there
        return False, f"JAX computes on {backend}, and the kernels are CPU-only (XLA's own path runs there)"
    if "ok" not in _STATE:
        try:
            _STATE.update(ok=True, path=_load())
        except (_BuildFailed, OSError) as exc:
            _STATE.update(ok=False, reason=str(exc))
            warnings.warn(f"nlosplan: the compiled kernels are not available ({exc}); the fast simulator "
                          "uses XLA's scatter-add and FFTs instead (the same results, 2-4x slower)", RuntimeWarning,
                          stacklevel=2)
    return (True, str(_STATE["path"])) if _STATE["ok"] else (False, _STATE["reason"])


def available() -> bool:
    """Whether :func:`deposit` and :func:`sum_convolve` can be traced in this process (see :func:`status`)."""
    return status()[0]


def _require() -> None:
    ok, why = status()
    if not ok:
        raise RuntimeError(f"the compiled kernels are not available: {why}")


def deposit(positions, weights, rows, n_rows: int, n_nodes: int, step: int = 0):
    """The deposit as a custom call (no derivative rule: see ``transient._kernel_deposit``).

    Parameters
    ----------
    positions, weights : array, shape (..., L)
        Fractional node coordinates and weights, one float dtype.
    rows : array of int32, shape (..., L) or (L,)
        The row of each arrival, or of each position along the last axis: arrival ``k`` (flat index) is in
        row ``(k // L) * step + rows[k % L]``.
    n_rows, n_nodes : int
    step : int
        Rows added per block of ``L`` arrivals (0: the same rows in every block).

    Returns
    -------
    array, shape (n_rows, n_nodes)
        Batched under ``vmap`` (leading axes broadcast over all three inputs).
    """
    _require()
    out = jax.ShapeDtypeStruct((n_rows, n_nodes), positions.dtype)
    return jax.ffi.ffi_call("nlosplan_deposit", out, vmap_method="broadcast_all")(
        positions, weights, rows, n_rows=np.int64(n_rows), n_nodes=np.int64(n_nodes), step=np.int64(step))


def sum_convolve(a, b):
    """Both legs convolved along time and summed over samples, as a custom call (no derivative rule: see
    ``transient.sum_convolve``).

    Parameters
    ----------
    a : array, shape (M, N1)
        Leg 1 of each sample on the node grid.
    b : array, shape (M, Z, N2)
        Leg 2 of each sample and zone; the same float dtype as ``a``.

    Returns
    -------
    array, shape (Z, N1 + N2 - 1)
        ``out[z, t] = sum_m sum_u b[m, z, u] a[m, t - u]``; batched under ``vmap``.
    """
    _require()
    m, n1 = a.shape
    _, z, n2 = b.shape
    out = jax.ShapeDtypeStruct((z, n1 + n2 - 1), a.dtype)
    return jax.ffi.ffi_call("nlosplan_sum_convolve", out, vmap_method="broadcast_all")(
        a, b, m=np.int64(m), n1=np.int64(n1), z=np.int64(z), n2=np.int64(n2))


def deposit_convolve(a, positions, weights, rows, z: int, n2: int):
    """The detection leg deposited (as :func:`deposit` with ``step=z``) and convolved with leg 1 (as
    :func:`sum_convolve`) in one custom call (no derivative rule: see ``transient._kernel_deposit_convolve``).

    Parameters
    ----------
    a : array, shape (M, N1)
        Leg 1 of each sample on the node grid.
    positions, weights : array, shape (M, L)
        Fractional node positions (on leg 2's grid of ``n2`` nodes) and weights of each sample's detection cells.
    rows : array of int32, shape (L,)
        Each cell's zone (0 .. z - 1; others are dropped).
    z, n2 : int
        Zones and leg 2's nodes.

    Returns
    -------
    array, shape (Z, N1 + N2 - 1)
        Batched under ``vmap``.
    """
    _require()
    m, n1 = a.shape
    cells = positions.shape[-1]
    out = jax.ShapeDtypeStruct((z, n1 + n2 - 1), a.dtype)
    return jax.ffi.ffi_call("nlosplan_deposit_convolve", out, vmap_method="broadcast_all")(
        a, positions, weights, rows, m=np.int64(m), n1=np.int64(n1), cells=np.int64(cells), z=np.int64(z),
        n2=np.int64(n2))
