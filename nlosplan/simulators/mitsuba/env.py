"""Start Mitsuba 3 + mitransient for the twin: variant choice and version check.

Builds on :func:`nlosplan.simulators.mitsuba_env.load_mitsuba` (which finds
libLLVM >= 16 for the CPU variants and imports mitransient after the variant
is set). Here the variant is chosen (``"auto"``: ``cuda_ad_rgb`` when a CUDA
device answers, else ``llvm_ad_rgb``) and the Mitsuba version is checked
against the range mitransient declares, *before* mitransient is imported, so
an incompatible pair gives one clear line instead of a warning and odd
failures later. Nothing here is imported unless the mitsuba backend is used.
"""

from __future__ import annotations

import re
from importlib import metadata

from nlosplan.errors import UserError

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
    from nlosplan.simulators.mitsuba_env import load_mitsuba

    mi, mitr = load_mitsuba(variant)
    from nlosplan.simulators.mitsuba.plugins import register

    register(mi)
    _LOADED[variant] = (mi, mitr, variant)
    return _LOADED[variant]
