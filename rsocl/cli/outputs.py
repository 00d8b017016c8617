"""Results written by the command line: an earlier file at an output path is kept beside it.

``rsocl reconstruct`` (one set, every set of a capture, tiles, a stream) writes each HDF5 result with
:func:`save_result`: a file already at the path keeps a second name, ``<stem>.earlier-<UTC time>.h5``
(:func:`rsocl.files.atomic.keeping`: a hard link, or a copy), so running a command again never loses an
earlier result; a write that fails leaves the earlier file where it was, with no second name. An output that
must never replace a file of some kinds (a capture) is refused first, before any work (:func:`refuse_kinds`).
"""

from __future__ import annotations

import contextlib
from pathlib import Path

__all__ = [
    "save_result",
    "kept_note",
    "kept_clause",
    "interrupted",
    "written",
    "nothing_written",
    "refuse_same_file",
    "refuse_kinds",
    "require_hdf5_name",
    "set_aside_plot",
    "CAPTURES",
    "HDF5_FILES",
]

#: The kinds of :func:`rsocl.files.hdf5.file_kind` no derived output replaces: captures, from cameras or simulated.
CAPTURES = ("camera capture", "capture")
#: Every HDF5 file: what a file of another format (a rig file, a picture) never replaces.
HDF5_FILES = CAPTURES + ("reconstruction", "HDF5")


def save_result(path, datacube, rig, **kwargs) -> Path | None:
    """Write the reconstruction file ``path`` (:func:`rsocl.files.hdf5.save_reconstruction`, with its keyword
    arguments), keeping a file already there as ``<stem>.earlier-<UTC time><suffix>``.

    Returns
    -------
    pathlib.Path or None
        The earlier file's new name; None where ``path`` held no file.

    Raises
    ------
    rsocl.files.atomic.OutputError
        The write failed: ``path`` is unchanged and has no second name.
    """
    from rsocl.files.atomic import EARLIER, keeping
    from rsocl.files.hdf5_reconstruction import save_reconstruction

    with keeping(path, EARLIER) as kept:
        save_reconstruction(path, datacube, rig, **kwargs)
    return kept


def set_aside_plot(path) -> Path | None:
    """Move a PNG picture at ``path`` that an earlier run drew and this run does not draw again (the parameter
    search's plot, after a run without a search) to ``<stem>.earlier-<UTC time><suffix>``, so that it is not
    taken for this run's. A file there that is no PNG (this run's ``--out``, say) is left where it is.

    Returns
    -------
    pathlib.Path or None
        The picture's new name; None where ``path`` held no PNG.

    Raises
    ------
    rsocl.files.atomic.OutputError
        No second name could be made: ``path`` is unchanged.
    """
    from rsocl.files.atomic import EARLIER, keep_copy

    try:
        with open(path, "rb") as f:
            if f.read(8) != b"\x89PNG\r\n\x1a\n":
                return None
    except OSError:  # no file there (or none this process may read: not one it drew)
        return None
    kept = keep_copy(path, EARLIER)
    if kept is not None:
        Path(path).unlink()
    return kept


def kept_note(kept) -> str:
    """The words a command's last line adds for the earlier files ``kept`` (paths or None): empty where
    none was kept."""
    from rsocl.files.atomic import EARLIER

    kept = [Path(k) for k in kept if k is not None]
    if not kept:
        return ""
    if len(kept) == 1:
        return f" (the earlier file there is kept as {kept[0]})"
    return f" (the {len(kept)} earlier files there are kept as <stem>.{EARLIER}-<UTC time><suffix>: {kept[0]} ..)"


def kept_clause(kept) -> str:
    """:func:`kept_note` as a clause that follows another in one line: ``", the earlier file there is kept
    as ..."``; empty where none was kept."""
    return kept_note(kept).replace(" (", ", ", 1).rstrip(")")


@contextlib.contextmanager
def interrupted(kept):
    """Around a step of a command: an interrupt (Ctrl-C, or SIGTERM's :class:`rsocl.common.interrupts.Terminated`)
    that says nothing yet is re-raised, of its own type, with ``kept`` (a string, or a callable giving it
    then) as its message, which the command's last line prints."""
    try:
        yield
    except KeyboardInterrupt as exc:
        if str(exc):
            raise
        raise type(exc)(kept() if callable(kept) else kept) from None


def nothing_written(out) -> str:
    """What an interrupt before the result file ``out`` is written kept: one clause for :func:`interrupted`."""
    return f"nothing written, {out} unchanged" if Path(out).exists() else "nothing written"


@contextlib.contextmanager
def written(results, kept):
    """Around the pictures' writes after the results (``results``: the path, or words, of what is written;
    ``kept``: the earlier files kept, paths or None): a failed write (a full disk) or an interrupt (Ctrl-C,
    SIGTERM) that says nothing yet says, in its one line, that the results are written and what was kept."""
    from rsocl.files.atomic import OutputError

    done = f"{results} written" + kept_clause(kept)
    try:
        yield
    except OutputError as exc:
        exc.strerror = f"{exc.strerror}; {done}"
        raise
    except KeyboardInterrupt as exc:
        if str(exc):
            raise
        raise type(exc)(f"{done}; the pictures are not all drawn") from None


def refuse_same_file(option, path, derived, fix: str) -> None:
    """Refuse, before any work, a run that would write one of its ``derived`` outputs (a GIF, a plot) at
    ``path``, the path of ``option`` (another output or an input, a link or a hard link to it included):
    one would replace the other.

    Parameters
    ----------
    option : str
        The option that names ``path``, as typed (``"--out"``).
    path : path
        The file of ``option``.
    derived : iterable of (str, path)
        Each derived output: the words that say what it is and where its path comes from (``"the tuning plot
        of --gif"``), and its path.
    fix : str
        What to do instead, ending the message (``"choose another --out or --gif"``).

    Raises
    ------
    ValueError
        ``"--out 'x-tuning.png' is where the tuning plot of --gif ... would be written, replacing it; ..."``.
    """
    from rsocl.files.atomic import same_file

    for words, other in derived:
        if same_file(path, other):
            raise ValueError(f"{option} {str(path)!r} is where {words} would be written, replacing it; {fix}")


def refuse_kinds(named, kinds=CAPTURES) -> None:
    """Refuse, before any work, an output that would replace a file of one of ``kinds``
    (:func:`rsocl.files.hdf5.file_kind`), naming its option; nothing is written.

    Parameters
    ----------
    named : iterable of (str, path)
        The option (or words) that names each output, and its path.
    kinds : tuple of str
        The kinds of file the outputs never replace (:data:`CAPTURES`, :data:`HDF5_FILES`).

    Raises
    ------
    ValueError
        An output path holds such a file, or frames from cameras, or cannot be read to tell.
    """
    from rsocl.files.hdf5 import file_kind, refuse_camera_capture

    for name, path in named:
        refuse_camera_capture(path, name)  # frames from cameras (counted), or a file that cannot be read
        kind = file_kind(path)
        if kind in kinds:
            what = "an HDF5 file" if kind == "HDF5" else f"a {kind} file"
            raise ValueError(
                f"{name} {str(path)!r} is {what}; it is never replaced by this output: it is kept, move it or "
                f"choose another {name}"
            )


def require_hdf5_name(path, option: str = "--out") -> None:
    """Refuse, naming ``option``, a capture's path whose suffix is not an HDF5 one
    (:data:`~rsocl.files.hdf5_header.HDF5_SUFFIXES`): a capture named ``x.gif`` or ``x-tuning.png`` is taken for
    a picture, by people and by the commands that draw pictures beside a result. An existing folder is let
    through, for the message that says it is one."""
    from rsocl.files.hdf5_header import HDF5_SUFFIXES

    if Path(path).suffix.lower() not in HDF5_SUFFIXES and not Path(path).is_dir():
        raise ValueError(f"{option} must name an HDF5 file ({', '.join(HDF5_SUFFIXES)}), got {str(path)!r}")
