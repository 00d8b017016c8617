"""Atomic file writes: readers see either the old file or the complete new one.

A writer gets a temporary path in the target's directory, writes and closes
its file there; on success the temporary file is flushed to disk (``fsync``)
and renamed over the target with :func:`os.replace`, which is atomic on POSIX
and Windows when both paths are on the same file system. On any exception the
temporary file is removed and the exception propagates, so a failed write
never leaves a partial file behind nor clobbers an existing good one; an
``OSError`` (a full disk, a permission refused) becomes an :class:`OutputError`
that names the target and says what was kept.

Temporary names carry their owner, ``<host>-<pid>``: the temporaries a killed
process left (it could not remove them) are recognised by the next writer of
the same target on the same host, whose process is gone, and removed
(:func:`remove_stale`); a live process's temporary is never touched.
"""

from __future__ import annotations

import contextlib
import contextvars
import os
import re
import shutil
import socket
import tempfile
import time
from pathlib import Path

__all__ = [
    "same_file",
    "atomic_path",
    "EARLIER",
    "keep_copy",
    "keeping",
    "output_path",
    "output_folder",
    "default_mode",
    "fsync_file",
    "fsync_directory",
    "OutputError",
    "owned_prefix",
    "remove_stale",
    "process_running",
]

#: The tag of the name an earlier result keeps when a command writes another at its path (:func:`keeping`).
EARLIER = "earlier"
#: The rest of an :func:`atomic_path` temporary's name after its owner tag: :func:`tempfile.mkstemp`'s
#: eight random characters and the suffix.
TMP_TAIL = r"[a-z0-9_]{8}\.tmp"


class OutputError(OSError):
    """Writing an output file failed (disk full, permission, ...); the message names the file and what was
    kept (the earlier file unchanged, or none made). ``errno`` and ``filename`` are the failure's."""

    def __init__(self, path, cause: OSError, existed: bool):
        kept = "the existing file is unchanged" if existed else "no file was made"
        if cause.errno:  # HDF5's own words list buffers and offsets
            why = f"{os.strerror(cause.errno)} (errno {cause.errno})"
        else:
            why = " ".join((cause.strerror or str(cause) or type(cause).__name__).split())
        super().__init__(cause.errno, f"cannot write {str(path)!r}: {why}; {kept}", str(path))

    def __str__(self):
        return self.strerror


def owned_prefix(prefix: str) -> str:
    """``prefix`` followed by this process's owner tag, ``<host>-<pid>-``: the start of a temporary
    name that :func:`remove_stale` can tell apart from the live ones."""
    return f"{prefix}{socket.gethostname()}-{os.getpid()}-"


def process_running(pid: int) -> bool:
    """Whether process ``pid`` exists on this host (another user's included)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        pass
    except (OverflowError, OSError):
        return False
    return True


def remove_stale(directory, prefix: str, tail: str) -> list:
    """Remove the temporaries in ``directory`` named ``owned_prefix(prefix) + tail`` by a process of this
    host that no longer runs; returns the paths removed.

    Parameters
    ----------
    directory : str or os.PathLike
        Where the temporaries are.
    prefix : str
        The start of their names, before the owner tag (e.g. ``"out.h5."``).
    tail : str
        A regular expression for the rest of the name after ``<host>-<pid>-`` (e.g. :data:`TMP_TAIL`).

    A file is unlinked, a folder removed with its content. Temporaries of other hosts (a shared
    folder) and of running processes are kept; nothing is done where processes cannot be asked
    (not POSIX). Errors while removing are ignored (another process may remove them first).
    """
    if os.name != "posix":
        return []
    directory = Path(os.fspath(directory))
    start = f"{prefix}{socket.gethostname()}-"
    pattern = re.compile(r"(\d+)-" + tail)
    removed = []
    try:
        entries = list(directory.iterdir())
    except OSError:
        return []
    for entry in entries:
        if not entry.name.startswith(start):
            continue
        found = pattern.fullmatch(entry.name[len(start) :])
        if not found or int(found.group(1)) == os.getpid() or process_running(int(found.group(1))):
            continue
        if entry.is_dir() and not entry.is_symlink():
            shutil.rmtree(entry, ignore_errors=True)
        else:
            with contextlib.suppress(OSError):
                entry.unlink()
        removed.append(entry)
    return removed


def default_mode() -> int:
    """Permission bits a newly created regular file gets: ``0o666`` minus the umask."""
    # os.umask can only be read by setting it; restore it at once.
    umask = os.umask(0o022)
    os.umask(umask)
    return 0o666 & ~umask


def fsync_file(path: Path) -> None:
    """Flush the file at ``path`` to disk (``fsync``)."""
    with open(path, "rb+") as handle:
        os.fsync(handle.fileno())


def fsync_directory(directory: Path) -> None:
    """Flush ``directory`` to disk, which persists a rename in it (best effort: not every platform can
    open a directory)."""
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def output_path(path, name: str = "path", inputs=()) -> Path:
    """``path`` as a Path whose folder exists and takes new files, which is not a directory and
    not one of the files ``inputs`` (``(option, path)`` pairs: what the run reads).

    Raises ``FileNotFoundError`` (missing folder) or ``ValueError`` (a directory, a folder where
    no file can be created, or an input, which the write would replace), naming the parameter ``name``.
    """
    path = Path(os.fspath(path))
    directory = path.parent if str(path.parent) else Path(".")
    if not directory.is_dir():
        raise FileNotFoundError(f"{name}: directory {str(directory)!r} does not exist (writing {str(path)!r})")
    if path.is_dir():
        raise ValueError(f"{name} must name a file, {str(path)!r} is a directory")
    for option, source in inputs:
        if source is not None and same_file(path, Path(os.fspath(source))):
            raise ValueError(f"{name} {str(path)!r} is the {option} it reads; writing it would replace the input")
    _check_takes_files(directory, name, prefix=f".{path.name}.")
    return path


def output_folder(path, name: str = "path") -> Path:
    """``path`` as a Path of a folder that exists, or can be made, and takes new files; nothing is created.

    Raises ``ValueError`` naming the parameter ``name`` when ``path`` (or the nearest of its parents
    that exists) is a file rather than a folder, or when no file can be created in that folder.
    """
    path = Path(os.fspath(path))
    if path.exists() and not path.is_dir():
        raise ValueError(f"{name} must name a folder (several files are written into it), {str(path)!r} is a file")
    existing = path
    while not existing.exists():  # the folder (and its parents) are made by the writer
        existing = existing.parent
    if not existing.is_dir():
        raise ValueError(f"{name}: {str(existing)!r} is a file, so the folder {str(path)!r} cannot be made")
    _check_takes_files(existing, name, prefix=".rsocl.")
    return path


def _check_takes_files(directory: Path, name: str, prefix: str) -> None:
    """Raise a ``ValueError`` naming ``name`` when no new file can be created in ``directory`` (a
    read-only mount, root with ``chattr +i``): a probe file is created and removed."""
    try:
        fd, probe = tempfile.mkstemp(dir=directory, prefix=prefix, suffix=".probe")
    except OSError as err:
        raise ValueError(f"{name}: cannot create files in {str(directory)!r} ({err.strerror})") from None
    os.close(fd)
    os.unlink(probe)


def same_file(a, b) -> bool:
    """Whether the paths ``a`` and ``b`` name one file (the same inode, a link or a hard link included, when
    both exist, else the same resolved path)."""
    a, b = Path(a), Path(b)
    try:
        if a.exists() and b.exists():
            return os.path.samefile(a, b)
        return a.resolve() == b.resolve()
    except OSError:
        return False


@contextlib.contextmanager
def atomic_path(path):
    """Context manager yielding a temporary path that replaces ``path`` on success.

    The temporary file is created (empty) with :func:`tempfile.mkstemp` in the
    directory of ``path``, named ``<name>.<host>-<pid>-<random>.tmp``; the temporaries
    of ``path`` that killed processes of this host left are removed first
    (:func:`remove_stale`). The caller writes
    the complete file there and closes it before the ``with`` block ends;
    writers that pick a format from the file name must be told the format
    explicitly (e.g. ``savefig(tmp, format="png")``), since the name ends in
    ``.tmp``.

    Parameters
    ----------
    path : str or os.PathLike
        Final destination. Its directory must exist. An existing file there is
        replaced only when the block completes without an exception; it keeps
        its permission bits, a new file gets the usual ``0o666 & ~umask``.

    Yields
    ------
    pathlib.Path
        The temporary path to write to.

    Raises
    ------
    FileNotFoundError
        If the directory of ``path`` does not exist.
    ValueError
        If ``path`` names an existing directory.
    OutputError
        If the write fails with an ``OSError`` (disk full, permission refused): ``path`` is
        unchanged (or not made) and the temporary file removed.

    Examples
    --------
    >>> with atomic_path("out.npy") as tmp:          # doctest: +SKIP
    ...     with open(tmp, "wb") as handle:
    ...         np.save(handle, array)
    """
    path = output_path(path)
    directory = path.parent
    existed = path.exists()
    mode = (path.stat().st_mode & 0o7777) if existed else default_mode()
    remove_stale(directory, path.name + ".", TMP_TAIL)
    try:
        fd, tmp_name = tempfile.mkstemp(prefix=owned_prefix(path.name + "."), suffix=".tmp", dir=directory)
    except OSError as exc:
        raise OutputError(path, exc, existed) from exc
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        yield tmp
        os.chmod(tmp, mode)
        fsync_file(tmp)
        os.replace(tmp, path)
    except BaseException as exc:
        with contextlib.suppress(OSError):
            tmp.unlink()
        if isinstance(exc, OSError) and not isinstance(exc, (OutputError, FileNotFoundError)):
            raise OutputError(path, exc, existed) from exc
        raise
    fsync_directory(directory)


def keep_copy(path, tag: str) -> Path | None:
    """Give the file ``path`` a second name beside it, before a command replaces it:
    ``<stem>.<tag>-<UTC time><suffix>``, a name no file has (``-1``, ``-2``, ... added where needed). A hard
    link where the file system makes one (no bytes copied; replacing ``path`` leaves the link the earlier
    file), else a copy written atomically (:func:`atomic_path`).

    Parameters
    ----------
    path : str or os.PathLike
        The file about to be replaced.
    tag : str
        Why it is kept, in the second name (letters, digits, ``-`` and ``_``).

    Returns
    -------
    pathlib.Path or None
        The second name; None where ``path`` is no file (nothing to keep).

    Raises
    ------
    OutputError
        Neither a link nor a copy could be made (nothing was made; ``path`` is unchanged).

    Examples
    --------
    >>> keep_copy("rig.toml", "before-calibration")      # doctest: +SKIP
    PosixPath('rig.before-calibration-20261127T094500Z.toml')
    """
    path = Path(path)
    if not re.fullmatch(r"[A-Za-z0-9_-]+", tag):
        raise ValueError(f"tag must be letters, digits, '-' or '_', got {tag!r}")
    if not path.is_file():
        return None
    stem = f"{path.stem}.{tag}-{time.strftime('%Y%m%dT%H%M%SZ', time.gmtime())}"
    copy, n = path.with_name(stem + path.suffix), 0
    while copy.exists() or copy.is_symlink():
        n += 1
        copy = path.with_name(f"{stem}-{n}{path.suffix}")
    try:
        os.link(path, copy)
    except OSError:  # no hard links here (or another race): a copy
        with atomic_path(copy) as tmp:
            shutil.copy2(path, tmp)
    return copy


#: The paths the :func:`keeping` blocks of this thread keep now (absolute): a block within one keeps nothing more.
_KEEPING: contextvars.ContextVar[frozenset] = contextvars.ContextVar("rsocl_keeping", default=frozenset())


@contextlib.contextmanager
def keeping(path, tag: str):
    """Context manager for a block that replaces the file ``path``: the earlier file keeps a second name
    (:func:`keep_copy`, yielded; None where there was no file), which is removed again if the block fails
    while ``path`` is still the earlier file (as an :func:`atomic_path` write that fails leaves it); a block
    that fails (an interrupt, say) after ``path`` was replaced leaves the second name, the earlier file's
    only one. Within a block that keeps ``path`` already (a command around a save that keeps too), it keeps
    nothing more and yields None.

    Examples
    --------
    >>> with keeping("rec.h5", "earlier") as kept:       # doctest: +SKIP
    ...     save_reconstruction("rec.h5", cube, rig)
    """
    key = os.path.abspath(os.fspath(path))
    if key in _KEEPING.get():
        yield None
        return
    token = _KEEPING.set(_KEEPING.get() | {key})
    try:
        kept = keep_copy(path, tag)
        try:
            yield kept
        except BaseException:
            if kept is not None and _still_earlier(path, kept):
                with contextlib.suppress(OSError):
                    kept.unlink()
            raise
    finally:
        _KEEPING.reset(token)


def _still_earlier(path, kept: Path) -> bool:
    """Whether ``path`` is still the file that :func:`keep_copy` gave the name ``kept``: the same inode (a
    link), or the same size and modification time (a copy keeps them)."""
    try:
        now, held = os.stat(path), os.stat(kept)
    except OSError:
        return False
    return os.path.samestat(now, held) or (now.st_size, now.st_mtime_ns) == (held.st_size, held.st_mtime_ns)
