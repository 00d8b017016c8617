"""The one host-memory check: arrays that would not fit this machine are refused before they are allocated.

Every place a size enters rsocl (a :class:`~rsocl.model.rig.Rig`, a reconstruction's datacube, a
capture's stored rig, a ``.npy`` file, the command line's ``--shape``) calls
:func:`check_host_memory` with the bytes it is about to allocate and the field that makes them
large, so that the refusal is one line naming that field, not a ``MemoryError`` (or the system
killing the process) part way through.
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["host_memory_bytes", "size_text", "check_host_memory", "check_npy_size"]


def host_memory_bytes():
    """This machine's memory for one process, bytes: the physical memory, or the control group's
    limit when lower (a container); None where neither can be read."""
    total = None
    try:
        total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (AttributeError, ValueError, OSError):
        pass
    for limit in ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes"):
        try:
            text = Path(limit).read_text().strip()
        except OSError:
            continue
        if text.isdigit():
            total = int(text) if total is None else min(total, int(text))
    return total


def size_text(nbytes) -> str:
    """``nbytes`` in the largest binary unit it reaches, one decimal: ``"1.2 TiB"``, ``"512.0 KiB"``."""
    for unit, scale in (("TiB", 2**40), ("GiB", 2**30), ("MiB", 2**20)):
        if nbytes >= scale:
            return f"{nbytes / scale:.1f} {unit}"
    return f"{nbytes / 2**10:.1f} KiB"


def check_host_memory(need, option: str, what: str, hint: str = "choose a smaller grid") -> None:
    """Refuse, naming ``option``, an input whose arrays alone (``need`` bytes, a lower bound) exceed
    :func:`host_memory_bytes`, before they are allocated.

    Parameters
    ----------
    need : int
        Bytes ``what`` takes at least.
    option : str
        The parameter and value to name, e.g. ``"--shape 100000 100000"`` or ``"shape (30000, 30000)"``.
    what : str
        What takes the memory, for the message.
    hint : str
        The way out, for the message.

    Raises
    ------
    ValueError
        ``"{option}: {what} needs at least {need} of host memory, more than this machine's {limit}; {hint}"``.

    Examples
    --------
    >>> check_host_memory(2**50, "shape (10**7, 10**7)", "the rig")    # doctest: +SKIP
    ValueError: shape (10**7, 10**7): the rig needs at least 1024.0 TiB of host memory, more than ...
    """
    limit = host_memory_bytes()
    if limit is not None and need > limit:
        raise ValueError(
            f"{option}: {what} needs at least {size_text(need)} of host memory, more than this "
            f"machine's {size_text(limit)}; {hint}"
        )


def check_npy_size(name: str, path, member: str | None = None) -> None:
    """Refuse a ``.npy`` file (or the array ``member`` of an ``.npz`` archive) whose header claims an
    array that would not fit :func:`host_memory_bytes`, or more bytes than the file holds, reading
    the header only.

    Parameters
    ----------
    name : str
        The parameter the file was given as (``"path"``, ``"row_map_file"``), for the message.
    path : str or os.PathLike
        The file. A header that cannot be read is left to the loader's own message.
    member : str or None
        The array's name inside an ``.npz`` archive (None: ``path`` is a ``.npy`` file).

    Raises
    ------
    ValueError
        Naming ``name``, the file and the shape its header claims.
    """
    import zipfile

    import numpy as np

    path = Path(os.fspath(path))
    try:
        if member is None:
            with open(path, "rb") as fh:
                shape, dtype, offset = _npy_header(fh)
            held = path.stat().st_size - offset
        else:
            with zipfile.ZipFile(path) as archive:
                info = archive.getinfo(member + ".npy")
                with archive.open(info) as fh:
                    shape, dtype, offset = _npy_header(fh)
            held = info.file_size - offset
    except (OSError, ValueError, TypeError, SyntaxError, KeyError, zipfile.BadZipFile):
        return
    if dtype.hasobject:
        return
    count = int(np.prod(shape, dtype=object)) if shape else 1
    need = count * dtype.itemsize
    label = f"{name}: {str(path)!r}" + (f"[{member!r}]" if member is not None else "")
    sides = " x ".join(map(str, shape)) or "scalar"
    check_host_memory(
        need,
        label,
        f"the {sides} {dtype} array its header claims ({count:,} elements)",
        "the file is damaged or too large for this machine",
    )
    if need > held:
        raise ValueError(
            f"{label}: its header claims a {sides} {dtype} array ({size_text(need)}), the file holds "
            f"{size_text(max(held, 0))} of data: it is truncated or damaged"
        )


def _npy_header(fh) -> tuple:
    """``(shape, dtype, header bytes)`` of the ``.npy`` stream ``fh``, positioned at its start."""
    import numpy as np

    major, _ = np.lib.format.read_magic(fh)
    read = np.lib.format.read_array_header_1_0 if major == 1 else np.lib.format.read_array_header_2_0
    shape, _, dtype = read(fh)
    return shape, dtype, fh.tell()
