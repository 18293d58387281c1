"""Product files: written atomically, and their paths checked before any work.

Every file the product writes (reports, sensor files, arrays, plots,
checkpoints, tables) goes through :func:`atomic_path`: the content is written
to a temporary file in the same folder, flushed and fsynced, then renamed over
the target (and the folder fsynced). A reader sees the old file or the new
one, never a part; a failure (full disk, read-only target, a crash) leaves
no temporary file and no 0-byte or truncated product behind.

The checks (:func:`check_output_file`, :func:`check_output_dir`,
:func:`check_plot_path`) run when a command starts, before it computes
anything: a path inside a file, an existing file where a folder is expected
(or a folder where a file is), a folder that cannot be written, an unknown
plot extension all raise :class:`~nlosplan.errors.UserError` naming the
flag as typed.
"""

from __future__ import annotations

import errno
import json
import os
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

from nlosplan.errors import UserError

__all__ = ["PLOT_BYTES", "PLOT_SUFFIXES", "WriteFailed", "atomic_path", "check_output_dir", "check_output_file",
           "check_plot_path",
           "check_free_space", "write_bytes", "write_json", "write_text", "save_npy", "writing"]

#: Plot file types matplotlib writes without extra packages (the suffix picks the format).
PLOT_SUFFIXES = (".png", ".pdf", ".svg", ".svgz", ".jpg", ".jpeg", ".eps", ".ps", ".tif", ".tiff", ".webp")

#: errno values that mean "the target cannot take the file" (not a bug).
_WRITE_ERRNOS = (errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EACCES, errno.EPERM, errno.ENOTDIR, errno.EISDIR,
                 errno.EEXIST, errno.ENAMETOOLONG, errno.EFBIG, errno.EIO)


class WriteFailed(UserError):
    """A product file could not be written (full disk, read-only target, ...); nothing partial was left."""


def _fsync_dir(folder: Path) -> None:
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:  # pragma: no cover - platforms without directory fds
        return
    try:
        os.fsync(fd)
    except OSError:  # pragma: no cover - some file systems refuse fsync on folders
        pass
    finally:
        os.close(fd)


@contextmanager
def atomic_path(path, *, mkdir: bool = True) -> Iterator[Path]:
    """A temporary path beside ``path`` to write to; renamed over ``path`` when the block ends without error.

    The temporary name keeps the suffix (``.name.XXXX.tmp.png``) so that
    writers that pick the format from it (matplotlib, ``numpy.save``) behave.
    On an exception the temporary file is removed and the exception goes on;
    an ``OSError`` of a full disk or an unwritable target becomes
    :class:`WriteFailed` (one line naming the file).

    Examples
    --------
    >>> with atomic_path("out/a.npy") as tmp:  # doctest: +SKIP
    ...     np.save(tmp, arr)
    """
    path = Path(path)
    try:
        if mkdir:
            path.parent.mkdir(parents=True, exist_ok=True)
        fd, name = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=f".tmp{path.suffix}", dir=path.parent)
    except OSError as exc:
        raise _failed(path, exc) from None
    os.close(fd)
    tmp = Path(name)
    try:
        yield tmp
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, path)
    except BaseException as exc:
        try:
            tmp.unlink()
        except OSError:
            pass
        if isinstance(exc, OSError) and (exc.errno in _WRITE_ERRNOS or exc.errno is None):
            raise _failed(path, exc) from None  # errno None: e.g. numpy's "N requested and M written"
        raise
    _fsync_dir(path.parent)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _failed(path: Path, exc: OSError) -> WriteFailed:
    import shutil

    reason = exc.strerror or str(exc)
    try:
        free = shutil.disk_usage(_first_existing(path.parent)).free
        reason += f"; {_size(free)} free on that disk"
    except OSError:
        pass
    return WriteFailed(f"cannot write {path}: {reason}")


def write_bytes(path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically; return the path."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    return Path(path)


def write_text(path, text: str) -> Path:
    """Write UTF-8 ``text`` to ``path`` atomically; return the path."""
    return write_bytes(path, text.encode("utf-8"))


def write_json(path, data, **kw) -> Path:
    """Write ``json.dumps(data, **kw)`` to ``path`` atomically; return the path."""
    return write_text(path, json.dumps(data, **kw))


def save_npy(path, array) -> Path:
    """``numpy.save`` to ``path`` atomically (no pickle); return the path."""
    import numpy as np

    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            np.save(fh, array, allow_pickle=False)
    return Path(path)


@contextmanager
def writing(kept: str = "", cont: str = "") -> Iterator[None]:
    """Turn a failed product write inside the block into one line saying what was kept and how to go on.

    Parameters
    ----------
    kept : str
        What survives the failure, e.g. ``"the 120 captures committed to s.sqlite are kept"``.
    cont : str
        How to continue, e.g. ``"free some space and rerun the same command to resume"``.
    """
    tail = "; ".join(t for t in (kept, cont) if t)
    try:
        yield
    except WriteFailed as exc:
        raise WriteFailed(f"{exc}{'; ' + tail if tail else ''}") from None
    except OSError as exc:
        if exc.errno not in _WRITE_ERRNOS:
            raise
        raise WriteFailed(f"{_failed(Path(exc.filename or '?'), exc)}{'; ' + tail if tail else ''}") from None


# ----------------------------------------------------------------------------- checks before work
def _first_existing(path: Path) -> Path:
    """``path`` or its nearest existing ancestor; UserError when an ancestor is a file."""
    p = path
    while not p.exists():
        if p.parent == p:
            break
        p = p.parent
    return p


def _probe_writable(folder: Path, flag: str, shown: Path) -> None:
    try:
        fd, name = tempfile.mkstemp(prefix=".nlosplan-probe.", dir=folder)
    except OSError as exc:
        raise UserError(f"{flag} {shown}: cannot write in {folder} ({exc.strerror or exc})") from None
    os.close(fd)
    os.unlink(name)


def _check_parents(path: Path, flag: str) -> Path:
    """The nearest existing ancestor of ``path`` (a writable folder), or a UserError."""
    anc = _first_existing(path.parent)
    if not anc.is_dir():
        raise UserError(f"{flag} {path}: {anc} is a file, not a folder")
    _probe_writable(anc, flag, path)
    return anc


def _checked_name(path, flag: str, what: str) -> Path:
    """``path`` as a Path; UserError when it is empty or has a name no file system takes (over 255 bytes)."""
    text = str(path)
    if text == "" or (text == "." and what != "folder"):   # "." is the current folder: a folder, not a file
        raise UserError(f"{flag}: give a {what}")
    long = [part for part in Path(text).parts if len(os.fsencode(part)) > 255]
    if long or len(os.fsencode(text)) > 4095:
        raise UserError(f"{flag} {text[:60]}...: a name in the path is longer than 255 bytes (or the path than 4095); "
                        "choose a shorter one")
    return Path(text)


def _checking(flag: str, path):
    """Turn an OSError of a check (no permission to look into a folder, ...) into one line naming the flag."""
    @contextmanager
    def guard():
        try:
            yield
        except OSError as exc:
            raise UserError(f"{flag} {path}: {exc.strerror or exc}") from None

    return guard()


def check_output_file(path, flag: str = "--out", *, suffixes: tuple[str, ...] | None = None) -> Path:
    """Check, before any work, that a file can be written at ``path``.

    Raises
    ------
    UserError
        ``path`` is empty, too long, a folder, lies inside a file, its folder
        cannot be written, or (with ``suffixes``) its suffix is not one of them.
    """
    path = _checked_name(path, flag, "file path")
    if suffixes is not None and path.suffix.lower() not in suffixes:
        raise UserError(f"{flag} {path}: unknown file type {path.suffix or '(none)'!r}; allowed: {', '.join(suffixes)}")
    with _checking(flag, path):
        if path.is_dir():
            raise UserError(f"{flag} {path} is a folder; give a file path")
        _check_parents(path, flag)
        if path.exists() and not os.access(path, os.W_OK):
            raise UserError(f"{flag} {path}: the file is read-only")
    return path


#: Free space a figure needs (the largest figures nlosplan writes, e.g. the design report's, are ~0.18 MB).
PLOT_BYTES = 2**20


def check_plot_path(path, flag: str = "--plot") -> Path:
    """:func:`check_output_file` for a figure: the suffix must be a format matplotlib writes, and its disk must
    have :data:`PLOT_BYTES` free (a full disk is found before the work, not when the figure is saved)."""
    path = check_output_file(path, flag, suffixes=PLOT_SUFFIXES)
    check_free_space(path, PLOT_BYTES, flag)
    return path


def check_output_dir(path, flag: str = "--out") -> Path:
    """Check, before any work, that ``path`` is (or can become) a writable folder.

    Raises
    ------
    UserError
        ``path`` is empty (it would be the current folder), too long, an
        existing file, lies inside a file, or cannot be written.
    """
    path = _checked_name(path, flag, "folder")
    with _checking(flag, path):
        if path.exists() and not path.is_dir():
            raise UserError(f"{flag} {path} is a file; give a folder (files with fixed names are written inside it)")
        if path.is_dir():
            _probe_writable(path, flag, path)
        else:
            _check_parents(path, flag)
    return path


def check_free_space(path, needed_bytes: float, flag: str = "--out") -> None:
    """Refuse before work when the file system of ``path`` has less than ``needed_bytes`` free."""
    import shutil

    anc = _first_existing(Path(path))
    try:
        free = shutil.disk_usage(anc if anc.is_dir() else anc.parent).free
    except OSError:   # a file system that cannot say: the write itself will tell
        return
    if needed_bytes > free:
        raise UserError(f"{flag} {path}: the output needs about {_size(needed_bytes)} but only {_size(free)} is free "
                        f"on that disk; free some space or choose another place")


def _size(n: float) -> str:
    for unit in ("bytes", "KB", "MB", "GB", "TB"):
        if n < 1024 or unit == "TB":
            return f"{n:.0f} {unit}" if unit == "bytes" else f"{n:.1f} {unit}"
        n /= 1024
    return f"{n:.1f} TB"  # pragma: no cover
