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

__all__ = ["MAX_DESIGN_SEED", "MAX_SEED", "MAX_TRAIN_CAPTURES", "WATCH_PARENT_S", "end_with_parent",
           "THREADS_ENV", "MALLOC_ENV", "available_memory", "cache_root", "check_memory", "default_threads",
           "format_bytes", "keep_freed_memory"]

#: Largest seed every random generator of the project takes (numpy, JAX, torch): seeds are 0..2**32-1.
MAX_SEED = 2**32 - 1
#: Largest seed of a design run (``nlosplan design --seed``, ``[search] seed``): its evaluation seeds are
#: ``seed * 1000 + i`` (``planner.design.search_config.SEED_STRIDE``) and must stay within :data:`MAX_SEED`,
#: scikit-learn's limit on a split's ``random_state``.
MAX_DESIGN_SEED = 1_000_000
#: Most training captures a design learner may be given (``nlosplan design --train-captures``,
#: ``[search.fidelity.trained] train_captures``): four times DENALI's 25,200; an 8x8 design of 128 bins holds them
#: in about 3.3 GB of float32 per worker.
MAX_TRAIN_CAPTURES = 100_000

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


#: Environment variable: ``0`` leaves the C allocator as it is (see :func:`keep_freed_memory`).
MALLOC_ENV = "NLOSPLAN_KEEP_FREED_MEMORY"
#: glibc ``mallopt`` parameters and the values :func:`keep_freed_memory` sets (bytes).
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
TRIM_THRESHOLD_BYTES = 1024**3
MMAP_THRESHOLD_BYTES = 1024**3
_kept: bool | None = None


def keep_freed_memory() -> bool:
    """Let this process reuse the memory it frees instead of handing it back to the kernel at once (glibc).

    glibc's allocator serves blocks over 128 KiB with a fresh ``mmap`` and unmaps them when freed, and
    gives the top of its heap back above 128 KiB free (both limits rise on their own only after a larger
    block is freed, and never past 32 MiB): a loop that allocates and frees the same large arrays then pays a
    page fault for every page every time. In a fresh process a 1D CNN training step (batch 64, 128 bins, width
    0.25) took 1,000-2,600 page faults and 12-15 ms, and 0-3 faults and 8.6-10 ms with blocks up to 32 MiB
    served from the heap and 256 MiB of free heap kept (identical arithmetic, so identical results). An 8x8
    design's evaluations handle (3,000 x 8,192) float64 arrays, 197 MB each: blocks up to
    :data:`MMAP_THRESHOLD_BYTES` come from the heap and up to :data:`TRIM_THRESHOLD_BYTES` of it stays free,
    and numpy is told not to ask for transparent huge pages for its arrays (each huge page fault zeroes
    2 MiB, and with the kernel's ``madvise`` defragmentation may compact memory first). 40 shape and size
    evaluations at 3x3, 4x4 and 8x8 in one process, one thread: 27.0-27.2 s (5.9-6.4 s of it in the kernel)
    with the 32 MiB / 256 MiB limits, 23.8 s (2.8 s in the kernel) with these; 27.6 s with glibc's own. The
    process keeps at most that much more memory than it uses. The CLI and every design worker call this at
    start; ``NLOSPLAN_KEEP_FREED_MEMORY=0`` leaves the allocator and numpy alone.

    Returns
    -------
    bool
        Whether the settings are in force (False without glibc's ``mallopt``, e.g. musl or macOS, or when
        turned off).
    """
    global _kept
    if _kept is None:
        _kept = False
        if os.environ.get(MALLOC_ENV, "1").strip().lower() not in ("0", "off", "false", "no"):
            try:
                import ctypes

                mallopt = ctypes.CDLL(None).mallopt
            except (OSError, AttributeError):  # not glibc: its own allocator, left as it is
                return False
            mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
            # trim first: setting either fixes both (glibc then stops adjusting them itself)
            _kept = bool(mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD_BYTES)
                         and mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES))
            if _kept:
                _no_huge_pages()
    return _kept


def _no_huge_pages() -> None:
    """Tell numpy not to advise transparent huge pages for its arrays (its default on Linux; see
    :func:`keep_freed_memory`). A numpy without the switch is left as it is."""
    import numpy as np

    switch = getattr(getattr(np, "_core", None), "multiarray", None)
    setter = getattr(switch, "_set_madvise_hugepage", None)
    if setter is not None:
        setter(False)


def cache_root() -> Path:
    """``$NLOSPLAN_CACHE`` or ``~/.cache/nlosplan``: the folder of every cache (programs, references, kernels,
    surface quadratures)."""
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


#: Seconds between a child process's checks that the process which started it is still there (:func:`end_with_parent`).
WATCH_PARENT_S = 0.5


def end_with_parent(parent: int | None = None) -> None:
    """Make this process end when the process ``parent`` (default: this one's parent now) ends, also on its kill -9.

    A daemon thread polls the parent every :data:`WATCH_PARENT_S` seconds and ends this process when it is gone (it
    is then re-parented), so no design worker, nor the resource tracker workers keep open, nor the stability
    catalog's process outlives an interrupted run. A thread, not ``PR_SET_PDEATHSIG``: that signal follows the parent
    *thread* that started the process, and pools start workers from helper threads.
    """
    import threading
    import time

    parent = os.getppid() if parent is None else parent

    def watch() -> None:
        while True:
            time.sleep(WATCH_PARENT_S)
            if os.getppid() != parent:
                os._exit(1)

    if os.getppid() != parent:
        os._exit(1)
    threading.Thread(target=watch, name="nlosplan-parent-watch", daemon=True).start()
