"""The ``rsocl`` command: :func:`build_parser` gathers one subcommand per module, :func:`main` runs one.

Subcommands: demo, simulate, reconstruct, info, plan, bench, capture, calibrate, devices, plugins
(:mod:`rsocl.cli.demo`, ...); each module has ``add_parser(subparsers)`` and its ``cmd_*``. The
arguments they share are in :mod:`rsocl.cli.options`.
"""

from __future__ import annotations

import argparse
import os
import re
import signal
import sys
import threading
import warnings

from rsocl.cli import bench, calibrate, capture, demo, devices, info, plan, plugins, reconstruct, simulate
from rsocl.common import interrupts
from rsocl.common.interrupts import Terminated

__all__ = ["build_parser", "main", "entry", "as_typed", "Terminated"]

#: In the order ``rsocl --help`` lists them.
SUBCOMMANDS = (demo, simulate, reconstruct, info, plan, bench, capture, calibrate, devices, plugins)


def build_parser() -> argparse.ArgumentParser:
    """The ``rsocl`` argument parser with every subcommand; each sets ``func`` to its ``cmd_*``."""
    from rsocl import __version__

    parser = argparse.ArgumentParser(
        prog="rsocl", description="High-speed video from rotated rolling-shutter cameras, reconstructed on OpenCL."
    )
    parser.add_argument("--version", action="version", version=f"rsocl {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    for module in SUBCOMMANDS:
        module.add_parser(sub)
    return parser


def _warning_line(command, shown=None):
    """A ``warnings.showwarning`` that writes ``rsocl COMMAND: warning: MESSAGE`` (one line per
    warning, no source line, each message once) to stderr, as errors are written. Deprecation warnings (meant for
    developers, from the libraries underneath) keep ``shown``'s form (None: the current one)."""
    shown = warnings.showwarning if shown is None else shown
    said: set = set()

    def show(message, category, filename, lineno, file=None, line=None):
        if issubclass(category, (DeprecationWarning, PendingDeprecationWarning)):
            return shown(message, category, filename, lineno, file, line)
        if str(message) in said:  # once: a rig built again (a crop, each camera's backend) warns again
            return None
        said.add(str(message))
        print(f"rsocl {command}: warning: {message}", file=sys.stderr if file is None else file)

    return show


def main(argv=None) -> int:
    """Run ``rsocl`` with ``argv`` (default ``sys.argv[1:]``); returns the exit status.

    0: done; 1: the command reports a failure of its own (no OpenCL device, a camera failed, the host
    memory ran out part way: sizes that cannot fit are refused first, with 2), or the system refused a
    file (disk full, permission, a lock another process holds: one line, :func:`fault_line`); 2: bad
    arguments or input (the message names them); 130: interrupted (Ctrl-C); 143: terminated (SIGTERM, which
    ends the command as Ctrl-C does, in the main thread). An interrupted command's line says what it kept.
    """
    from rsocl.device.context import NoOpenCLError

    args = build_parser().parse_args(argv)
    previous = {}
    if threading.current_thread() is threading.main_thread():
        interrupts.forget()
        previous[signal.SIGTERM] = signal.signal(signal.SIGTERM, interrupts.handle)
        if signal.getsignal(signal.SIGINT) is signal.default_int_handler:  # an ignored Ctrl-C stays ignored
            previous[signal.SIGINT] = signal.signal(signal.SIGINT, interrupts.handle)
    try:
        with warnings.catch_warnings():
            warnings.showwarning = _warning_line(args.command)
            check_options = getattr(args, "check_options", None)  # combinations of shared options, checked first
            if check_options is not None:
                check_options(args)
            return int(args.func(args) or 0)
    except (ValueError, FileNotFoundError, NoOpenCLError, FloatingPointError) as exc:
        print(
            f"rsocl {args.command}: error: {as_typed(str(exc), sys.argv[1:] if argv is None else argv)}",
            file=sys.stderr,
        )
        return 2
    except MemoryError as exc:
        print(
            f"rsocl {args.command}: error: out of host memory ({str(exc).strip() or 'MemoryError'}); "
            "a smaller grid, fewer sets or tiles (rsocl plan) need less",
            file=sys.stderr,
        )
        return 1
    except BrokenPipeError:  # a reader that stopped reading: entry() ends quietly
        raise
    except OSError as exc:
        print(f"rsocl {args.command}: error: {fault_line(exc)}", file=sys.stderr)
        return 1
    except KeyboardInterrupt as exc:  # a command may say what it kept (the interrupt's message)
        interrupts.forget()
        kept = f": {exc}" if str(exc) else ""
        how, code = ("terminated", 143) if isinstance(exc, Terminated) else ("interrupted", 130)
        print(f"rsocl {args.command}: {how}{kept}", file=sys.stderr)
        return code
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)


#: API words of error messages and what the command line says instead.
_API_WORDS = (
    ("(tune=False, or nothing left to choose", "(--fixed, or nothing left to choose"),
    (
        "give the start as x0 (an array or 'interp3d'), or leave blend None",
        "drop --fixed, or a value you gave that the search would choose (--lam, --reg-opt), so that the run "
        "starts from the interpolation; or leave out --blend",
    ),
)


def as_typed(message: str, argv) -> str:
    """``message`` with the API parameter it starts with (``lam must be >= 0``, ``tile: ...``,
    ``iterations='auto' applies ...``, ``blend = 0.5 ...``, ``option tv_iterations ...``) written as the
    option the command line ``argv`` gave for it (``--lam``, ``--tile``, ``--iterations auto``,
    ``--blend 0.5``, ``--tv-iterations``); as it is where it names no option of ``argv``.

    Examples
    --------
    >>> as_typed("lam must be >= 0, got -1.0", ["reconstruct", "c.h5", "--lam", "-1"])
    '--lam must be >= 0, got -1.0'
    >>> as_typed("option tv_iterations must be in [1, 100000], got 0", ["reconstruct", "--tv-iterations", "0"])
    '--tv-iterations must be in [1, 100000], got 0'
    """
    for api, words in _API_WORDS:  # advice that names API arguments the command line does not have
        message = message.replace(api, words)
    found = re.match(r"(?:option )?([a-z][a-z0-9_]*)(='auto'| = (?=\S))?(?=[\s:=\[]|(?<= = ))", message)
    if found is None:
        return message
    option = "--" + found.group(1).replace("_", "-")
    if option not in {str(a).split("=", 1)[0] for a in argv}:
        return message
    value = {None: "", "='auto'": " auto"}.get(found.group(2), " ")  # "blend = 0.5" as "--blend 0.5"
    return option + value + message[found.end() :]


def fault_line(exc: OSError) -> str:
    """One line for a file the system refused: the path, the cause and what was kept.

    An :class:`~rsocl.files.atomic.OutputError` says it all; another ``OSError`` (HDF5's messages span
    lines and list buffers) is named by its file and the system's words for its error number."""
    from rsocl.files.atomic import OutputError

    if isinstance(exc, OutputError):
        return str(exc)
    if isinstance(exc, BlockingIOError) or "unable to lock file" in str(exc):
        why = "another process holds its lock (it is being written)"
    elif exc.errno:
        why = f"{os.strerror(exc.errno)} (errno {exc.errno})"
    else:
        why = " ".join(str(exc).split()) or type(exc).__name__
    where = f"{exc.filename!r}: " if exc.filename else ""
    return f"{where}{why}; outputs replace a file only once complete, so the files already there are unchanged"


def entry(argv=None) -> int:
    """The ``rsocl`` console script (and ``python -m rsocl``): :func:`main`, with output to a reader
    that stopped reading (``rsocl plugins | head -1``) ending quietly, as a command killed by SIGPIPE
    does (exit status 141, nothing on stderr)."""
    try:
        status = main(argv)
        sys.stdout.flush()
        return status
    except BrokenPipeError:
        try:  # the interpreter's final flush would fail again: send what is left nowhere
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        except (AttributeError, OSError, ValueError):
            pass
        return 141


if __name__ == "__main__":  # pragma: no cover
    sys.exit(entry())
