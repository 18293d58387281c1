"""What the machine can give a request: memory available, the range of seeds, threads, and where caches live.

Commands estimate the memory a request needs from its sizes (zones x bins x
repeats, draws, scenes) before any work and refuse it with one line when it
exceeds what is available (:func:`check_memory`), instead of growing until
the kernel kills the process (or another one). The estimates' constants are
measured peaks (see each caller).
"""

from __future__ import annotations

import os
import resource
from pathlib import Path

from nlosplan.errors import UserError

__all__ = ["MAX_SEED", "THREADS_ENV", "available_memory", "cache_root", "check_memory", "default_threads", "format_bytes"]

#: Largest seed every random generator of the project takes (numpy, JAX, torch): seeds are 0..2**32-1.
MAX_SEED = 2**32 - 1

_GIB = 1024**3


#: Environment variable: how many chunks of a batch a simulator runs at once (threads); a design worker sets 1.
THREADS_ENV = "NLOSPLAN_SIM_THREADS"


def default_threads() -> int:
    """Chunks of a batch run at once: ``$NLOSPLAN_SIM_THREADS``, else the cores this process may use.

    The fast simulator runs a batch's chunks on this many threads: much of a compiled scene runs on one core
    (the kernels, the loop over a chunk's scenes), so two chunks on two cores ran 1.5-2x as fast as one after
    the other. A design worker process (:func:`~nlosplan.planner.design.workers.init_worker`) sets 1: the pool
    runs one worker per core.
    """
    named = os.environ.get(THREADS_ENV, "").strip()
    if named:
        try:
            value = int(named)
        except ValueError:
            raise UserError(f"{THREADS_ENV}={named!r} is not a whole number of threads") from None
        if value < 1:
            raise UserError(f"{THREADS_ENV}={named!r}: at least 1 thread")
        return value
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


def cache_root() -> Path:
    """``$NLOSPLAN_CACHE`` or ``~/.cache/nlosplan``: the folder of every cache (programs, references, kernels)."""
    return Path(os.environ.get("NLOSPLAN_CACHE") or Path.home() / ".cache" / "nlosplan")


def _meminfo_available() -> int | None:
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


def _cgroup_available() -> int | None:
    """Memory left under this process's cgroup v2 limit (None without a limit)."""
    try:
        rel = Path("/proc/self/cgroup").read_text().strip().split("::")[-1]
        base = Path("/sys/fs/cgroup") / rel.lstrip("/")
        limit = (base / "memory.max").read_text().strip()
        if limit == "max":
            return None
        return int(limit) - int((base / "memory.current").read_text().strip())
    except (OSError, ValueError):
        return None


def _rlimit_available() -> int | None:
    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    if soft == resource.RLIM_INFINITY:
        return None
    try:
        used = int(Path("/proc/self/statm").read_text().split()[0]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError):
        used = 0
    return soft - used


def available_memory() -> int:
    """Bytes this process may still allocate: the least of free RAM, the cgroup limit and the address-space limit."""
    values = [v for v in (_meminfo_available(), _cgroup_available(), _rlimit_available()) if v is not None]
    if not values:  # pragma: no cover - no /proc
        return int(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_AVPHYS_PAGES"))
    return max(0, min(values))


def format_bytes(n: float) -> str:
    """``1.5 GB``, ``320 MB``."""
    if n >= _GIB:
        return f"{n / _GIB:.1f} GB"
    return f"{n / 1024**2:.0f} MB"


def check_memory(needed: float, what: str, hint: str = "") -> None:
    """Refuse (UserError, one line) when ``needed`` bytes exceed what is available.

    Parameters
    ----------
    needed : float
        Estimated peak bytes of the request.
    what : str
        The request as the user typed it, e.g. ``"--zones 16x16 --bins 4096"``.
    hint : str
        What to change, e.g. ``"use fewer --repeats"``.
    """
    have = available_memory()
    if needed > have:
        tail = f"; {hint}" if hint else ""
        raise UserError(f"{what} needs about {format_bytes(needed)} of memory, more than the "
                        f"{format_bytes(have)} available{tail}")
