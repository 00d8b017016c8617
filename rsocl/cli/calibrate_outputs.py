"""Where ``rsocl calibrate`` writes, checked before any work, and what an interrupt's line says it kept.

The calibrated rig file goes to ``--out`` (else over ``--rig``; the file it replaces is kept as
``<stem>.before-calibration-<UTC time>.toml``), the marker overlay to ``--png`` (else
``<out stem>-calibration.png`` beside it). Neither may be an input, an HDF5 file (a capture, a
reconstruction), nor a frame file in a folder that the run reads frames from (a later run would read
the picture as a frame).
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["calibration_outputs", "interrupt_line", "REPLACED"]

#: The tag of the earlier rig file's second name (:func:`rsocl.files.atomic.keeping`).
REPLACED = "before-calibration"


def calibration_outputs(args) -> tuple[Path, Path | None]:
    """``(out, png)`` of ``rsocl calibrate``'s ``args``: the rig file and the overlay (None without ``--frames``).

    Raises
    ------
    ValueError
        An output is an input, an HDF5 file, a frame file inside a ``--frames``, ``--flicker`` or ``--flat``
        folder, or ``--png`` does not end in ``.png``; the message names the option as typed.
    """
    from rsocl.cli.calibrate_frames import IMAGE_SUFFIXES
    from rsocl.cli.outputs import HDF5_FILES, refuse_kinds
    from rsocl.files.atomic import output_path

    reads = (("--frames", args.frames), ("--flicker", args.flicker), ("--flat", args.flat))
    out = output_path(Path(args.out) if args.out else Path(args.rig), "--out", inputs=reads)
    named = [("--out" if args.out else "--rig", out)]  # a rig file (TOML) never replaces a capture or result
    png = None
    if args.frames is not None:
        default = out.with_name(out.stem + "-calibration.png")
        png = output_path(
            Path(args.png) if args.png else default, "--png", inputs=reads + (("--rig", args.rig), ("--out", out))
        )
        named.append(("--png" if args.png else "--png (by default beside the rig file)", png))
    if args.png is not None and Path(args.png).suffix.lower() != ".png":
        raise ValueError(f"--png must name a .png file (the overlay is written as a PNG), got {args.png!r}")
    refuse_kinds(named, HDF5_FILES)
    for option, path in named:
        for source_option, source in reads:
            if source is None or path.suffix.lower() not in IMAGE_SUFFIXES or not Path(source).is_dir():
                continue
            if path.parent.resolve() == Path(source).resolve():
                raise ValueError(
                    f"{option} {str(path)!r} lies in the {source_option} folder {str(source)!r}, whose "
                    f"{', '.join(IMAGE_SUFFIXES)} files are read as frames (it would replace one, or be read as "
                    "one by a later run); choose another folder"
                )
    return out, png


def interrupt_line(out: Path, png: Path | None, done: dict) -> str:
    """The line of an interrupt (Ctrl-C, SIGTERM) at some point of ``rsocl calibrate``: ``done`` holds ``"png"``
    once the overlay is written, ``"rig"`` once the rig file is, and ``"kept"``, the earlier rig file's
    second name (or None)."""
    from rsocl.cli.outputs import kept_clause, nothing_written

    if not done.get("png") and not done.get("rig"):
        return nothing_written(out)
    said = [f"{png} written"] if done.get("png") else []
    if done.get("rig"):
        said.append(f"{out} written" + kept_clause([done.get("kept")]))
    else:
        said.append(f"{out} unchanged" if out.exists() else "no rig file written")
    return ", ".join(said)
