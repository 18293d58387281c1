"""Load Mitsuba 3 (+ mitransient) with a working variant.

Mitsuba's CPU variants (``llvm_ad_*``) need libLLVM >= 16: Debian 12's LLVM 15
fails at JIT time with "Cannot select: fminimum". This module finds a
suitable ``libLLVM-N.so`` by itself (``DRJIT_LIBLLVM_PATH`` if already set,
else the usual library directories, newest first), points Dr.Jit at it, sets
the variant and only then imports mitransient, which must come after.
Nothing here runs unless the Mitsuba backend is asked for.
"""

from __future__ import annotations

import glob
import os
import re
from pathlib import Path

from nlosplan.errors import UserError

MIN_LLVM = 16
_SEARCH_DIRS = (
    "/usr/lib/x86_64-linux-gnu",
    "/usr/lib/aarch64-linux-gnu",
    "/usr/lib64",
    "/usr/lib",
    "/usr/local/lib",
    "/opt/homebrew/opt/llvm/lib",
    "/usr/local/opt/llvm/lib",
)


def _llvm_major(path: str) -> int | None:
    m = re.search(r"libLLVM[-.](\d+)", os.path.basename(path))
    if m:
        return int(m.group(1))
    m = re.search(r"llvm-(\d+)", path)
    return int(m.group(1)) if m else None


def find_libllvm(search_dirs: tuple[str, ...] = _SEARCH_DIRS) -> str | None:
    """Path of the newest libLLVM with major version >= 16, or None.

    An existing ``DRJIT_LIBLLVM_PATH`` wins when it names a readable file.
    """
    env = os.environ.get("DRJIT_LIBLLVM_PATH")
    if env and Path(env).is_file():
        return env
    found: list[tuple[int, str]] = []
    for d in search_dirs:
        patterns = [f"{d}/libLLVM-*.so", f"{d}/libLLVM.so.*", f"{d}/llvm-*/lib/libLLVM*.so*", f"{d}/libLLVM.dylib"]
        for pat in patterns:
            for p in glob.glob(pat):
                major = _llvm_major(p)
                if major is not None and major >= MIN_LLVM and Path(p).is_file():
                    found.append((major, p))
    for p in glob.glob("/usr/lib/llvm-*/lib/libLLVM*.so*"):
        major = _llvm_major(p)
        if major is not None and major >= MIN_LLVM:
            found.append((major, p))
    if not found:
        return None
    found.sort(key=lambda mp: (-mp[0], len(mp[1])))
    return found[0][1]


def load_mitsuba(variant: str = "llvm_ad_rgb"):
    """Import mitsuba with ``variant`` set, then mitransient.

    Returns
    -------
    (module, module)
        ``(mitsuba, mitransient)``.

    Raises
    ------
    UserError
        When mitsuba/mitransient are not installed, libLLVM >= 16 cannot be
        found for an ``llvm_*`` variant, or the variant is unavailable.
    """
    if variant.startswith("llvm"):
        path = find_libllvm()
        if path is None:
            raise UserError(
                f"Mitsuba's {variant} variant needs libLLVM >= {MIN_LLVM}, none found; "
                "install it (Debian: apt-get install libllvm19) or set DRJIT_LIBLLVM_PATH to libLLVM-N.so"
            )
        os.environ["DRJIT_LIBLLVM_PATH"] = path
    try:
        import mitsuba as mi
    except ImportError:
        raise UserError("the mitsuba backend needs the 'mitsuba' package; install it with pip install mitsuba") from None
    if variant not in mi.variants():
        raise UserError(f"Mitsuba variant {variant!r} is not available; available: {', '.join(mi.variants())}")
    try:
        mi.set_variant(variant)
    except Exception as exc:  # noqa: BLE001 - Dr.Jit raises plain exceptions on backend init
        raise UserError(f"cannot start Mitsuba variant {variant!r}: {str(exc).splitlines()[0]}") from None
    try:
        import mitransient as mitr
    except ImportError:
        raise UserError("the mitsuba backend needs 'mitransient'; install it with pip install mitransient") from None
    return mi, mitr
