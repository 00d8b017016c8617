"""Where, when and on what a benchmark ran: the header of every page a benchmark writes to docs/.

A page of measurements is only meaningful with the machine, the code and the time it was
measured on, so every script in ``benchmarks/`` starts its page with :func:`header_lines`
and writes it with :func:`write_page` (atomically: a failed run never leaves half a page).

    date (UTC), git commit (short hash, ``-dirty`` when tracked files differ from it),
    CPU model, logical cores (and how many this process may use), load average at start,
    OpenCL platform / device / driver, Python, NumPy, pyopencl and rsocl versions,
    and the command line that produced the page.

A setting of rsocl that a run changes through the environment (:data:`LANES_ENV`, applied when this
module is imported: :func:`apply_settings`) is listed in the header too.
"""

from __future__ import annotations

import datetime
import os
import platform
import shlex
import subprocess
import sys
from pathlib import Path

import numpy as np

#: The repository root (benchmarks/ is one level below it).
ROOT = Path(__file__).resolve().parents[1]
#: Where the benchmarks write their pages.
DOCS = ROOT / "docs"

__all__ = [
    "ROOT",
    "DOCS",
    "LANES_ENV",
    "SETTINGS",
    "apply_settings",
    "power_of_two",
    "git_revision",
    "cpu_model",
    "header_lines",
    "usable_cores",
    "write_page",
]

#: The environment variable that sets ``rsocl.solver.admm.GPU_PROJECT_LANES`` (a power of two) for every
#: benchmark of a run (``benchmarks/gpu_check.sh`` sets it from ``benchmarks/lanes_choice.py``'s choice).
LANES_ENV = "RSOCL_BENCH_PROJECT_LANES"


def power_of_two(n: int) -> bool:
    """Whether ``n`` is 1, 2, 4, 8, ...: a count of projection lanes (``rsocl.solver.admm.GPU_PROJECT_LANES``)."""
    return n >= 1 and not n & (n - 1)


def apply_settings() -> list:
    """Set what the environment asks for (:data:`LANES_ENV`) and return the header's lines that say so.

    Raises
    ------
    ValueError
        :data:`LANES_ENV` is set to something other than a power of two (1, 2, 4, ...).
    """
    text = os.environ.get(LANES_ENV, "").strip()
    if not text:
        return []
    if not text.isdigit() or not power_of_two(int(text)):
        raise ValueError(f"{LANES_ENV} must be a power of two (1, 2, 4, ...), got {text!r}")
    import rsocl.solver.admm as admm_module

    code = admm_module.GPU_PROJECT_LANES
    admm_module.GPU_PROJECT_LANES = int(text)
    return [f"- projection lanes on a device that is not a CPU: {int(text)} (set by {LANES_ENV}; rsocl's: {code})"]


def git_revision(root: Path = ROOT) -> str:
    """``git rev-parse --short HEAD`` of ``root``, with ``-dirty`` when tracked files that a measurement can
    depend on are modified: any but the pages (``docs/``, Markdown files), which the scripts write.

    For a copy of the tree sent to another machine, the environment variable ``RSOCL_GIT_COMMIT``
    names the commit the copy was made from, shown as ``"<commit> (copied tree)"``: it wins over
    whatever git state the copy carries. Without either, ``"unknown (not a git checkout)"``.
    """
    copied = os.environ.get("RSOCL_GIT_COMMIT", "").strip()
    if copied:
        return f"{copied} (copied tree)"
    try:
        head = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], cwd=root, capture_output=True, text=True, check=True
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no", "--", ".", ":(exclude)docs", ":(exclude)*.md"],
            cwd=root,
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown (not a git checkout)"
    return head + ("-dirty" if dirty else "")


def cpu_model() -> str:
    """The CPU's model name from ``/proc/cpuinfo`` (Linux), else :func:`platform.processor`."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as handle:
            for line in handle:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def usable_cores() -> int:
    """Logical cores this process may run on (its CPU affinity where the OS has one)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1


def _cores() -> str:
    return f"{os.cpu_count()} logical cores ({usable_cores()} usable by this process)"


def header_lines(title: str, device=None, argv=None) -> list:
    """Markdown lines: ``# title`` and the provenance list, ending with a blank line.

    Parameters
    ----------
    title : str
        The page's title.
    device : rsocl.device.Device, optional
        The OpenCL device the measurements ran on (platform, device and driver are listed).
    argv : list of str, optional
        The script's arguments (default ``sys.argv``), shown as the command that reproduces the page.
    """
    import pyopencl as cl

    import rsocl

    argv = sys.argv if argv is None else argv
    script = Path(argv[0]).resolve()
    try:
        script = script.relative_to(ROOT)
    except ValueError:
        pass
    command = " ".join(["python", str(script)] + [shlex.quote(a) for a in argv[1:]])
    now = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    lines = [
        f"# {title}",
        "",
        f"- measured: {now}, git commit {git_revision()}",
        f"- command: `{command}`",
        f"- CPU: {cpu_model()}, {_cores()}",
    ]
    if hasattr(os, "getloadavg"):
        lines.append("- load average at start: " + ", ".join(f"{x:.2f}" for x in os.getloadavg()))
    if device is not None:
        dev = device.device
        lines.append(
            f"- OpenCL device: {device.name} ({dev.version.strip()}; driver {dev.driver_version.strip()}; "
            f"{dev.max_compute_units} compute units)"
        )
    lines.append(
        f"- Python {platform.python_version()}, NumPy {np.__version__}, pyopencl {cl.VERSION_TEXT}, "
        f"rsocl {rsocl.__version__}"
    )
    return lines + SETTINGS + [""]


def write_page(path, lines) -> Path:
    """Write ``lines`` (joined by newlines) to ``path`` atomically; returns the path.

    The folder must exist (``FileNotFoundError`` otherwise, before anything is written).
    """
    from rsocl.files.atomic import atomic_path

    path = Path(path)
    with atomic_path(path) as tmp:
        tmp.write_text("\n".join(lines).rstrip("\n") + "\n", encoding="utf-8")
    print(f"written to {path}", file=sys.stderr)
    return path


def emit(lines, out=None):
    """Print the page ``lines`` and write it to ``out`` (atomically) when given."""
    print("\n".join(lines))
    if out is not None:
        write_page(out, lines)


#: The header's lines of the settings :func:`apply_settings` made when this module was imported.
SETTINGS = apply_settings()
