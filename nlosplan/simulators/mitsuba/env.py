"""Start Mitsuba 3 + mitransient for the twin: libLLVM, variant choice and version check (the one start-up module).

Mitsuba's CPU variants (``llvm_ad_*``) need libLLVM >= 16: Debian 12's LLVM 15
fails at JIT time with "Cannot select: fminimum". :func:`find_libllvm` finds
a suitable ``libLLVM-N.so`` by itself (``DRJIT_LIBLLVM_PATH`` if already set,
else the usual library directories, newest first) and :func:`load_mitsuba`
points Dr.Jit at it, sets the variant and only then imports mitransient,
which must come after. :func:`load` chooses the variant (``"auto"``:
``cuda_ad_rgb`` when a CUDA device answers, else ``llvm_ad_rgb``) and checks
the Mitsuba version against the range mitransient declares, *before*
mitransient is imported, so an incompatible pair gives one clear line
instead of a warning and odd failures later. Mitsuba is imported only when
these functions are called (the mitsuba backend asked for).
"""

from __future__ import annotations

import glob
import os
import re
from importlib import metadata
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


VARIANTS = ("auto", "llvm_ad_rgb", "cuda_ad_rgb")
#: Mitsuba versions mitransient 1.3 supports: [min, max).
_FALLBACK_RANGE = ("3.6.0", "3.10.0")

_LOADED: dict[str, tuple] = {}


def _version(text: str) -> tuple[int, int, int]:
    m = re.match(r"\s*v?(\d+)\.(\d+)\.(\d+)", str(text))
    if not m:
        raise UserError(f"cannot read the version string {text!r}")
    return tuple(int(x) for x in m.groups())  # type: ignore[return-value]


def mitransient_range() -> tuple[str, str]:
    """The Mitsuba version range ``[min, max)`` the installed mitransient declares.

    Read from ``mitransient/version.py`` without importing mitransient (its
    import needs a variant already set); a fixed range when it cannot be read.
    """
    try:
        dist = metadata.distribution("mitransient")
        text = dist.locate_file("mitransient/version.py").read_text()
    except (metadata.PackageNotFoundError, OSError):
        return _FALLBACK_RANGE
    lo = re.search(r"__mi_version_min__\s*=\s*'([^']+)'", text)
    hi = re.search(r"__mi_version_max__\s*=\s*'([^']+)'", text)
    return (lo.group(1) if lo else _FALLBACK_RANGE[0], hi.group(1) if hi else _FALLBACK_RANGE[1])


def check_versions(mitsuba_version: str, supported: tuple[str, str] | None = None) -> None:
    """Raise :class:`UserError` when Mitsuba is outside mitransient's supported range.

    Parameters
    ----------
    mitsuba_version : str
        e.g. ``"3.9.1"``.
    supported : (str, str), optional
        ``[min, max)``; default :func:`mitransient_range`.
    """
    lo, hi = supported or mitransient_range()
    v = _version(mitsuba_version)
    if not (_version(lo) <= v < _version(hi)):
        raise UserError(
            f"mitsuba {mitsuba_version} is not supported by the installed mitransient (needs >= {lo} and < {hi}); "
            f"install a matching pair, e.g. pip install 'mitsuba>={lo},<{hi}'"
        )


def cuda_available() -> bool:
    """Whether Dr.Jit can start its CUDA backend (a GPU and driver are present)."""
    try:
        import drjit as dr

        return bool(dr.has_backend(dr.JitBackend.CUDA))
    except Exception:  # noqa: BLE001 - no driver, no GPU: not available
        return False


def resolve_variant(variant: str) -> str:
    """``"auto"`` -> ``cuda_ad_rgb`` when a CUDA device is present, else ``llvm_ad_rgb``."""
    if variant not in VARIANTS:
        raise UserError(f"unknown Mitsuba variant {variant!r}; allowed: {', '.join(VARIANTS)}")
    if variant == "auto":
        return "cuda_ad_rgb" if cuda_available() else "llvm_ad_rgb"
    return variant


def load(variant: str = "auto"):
    """Mitsuba and mitransient with ``variant`` set, versions checked, nlosplan plugins registered.

    Returns
    -------
    (module, module, str)
        ``(mitsuba, mitransient, variant)``.

    Raises
    ------
    UserError
        Not installed, no libLLVM >= 16 for the CPU variant (the message names
        the package), an unavailable variant, or incompatible versions.
    """
    variant = resolve_variant(variant)
    if variant in _LOADED:
        return _LOADED[variant]
    try:
        mi_version = metadata.version("mitsuba")
    except metadata.PackageNotFoundError:
        raise UserError("the mitsuba backend needs the 'mitsuba' package; install it with pip install mitsuba") from None
    check_versions(mi_version)
    mi, mitr = load_mitsuba(variant)
    from nlosplan.simulators.mitsuba.plugins import register

    register(mi)
    _LOADED[variant] = (mi, mitr, variant)
    return _LOADED[variant]
