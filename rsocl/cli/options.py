"""Arguments shared by the ``rsocl`` subcommands: the rig, the OpenCL device, the solver (the lines they
print about a result: :mod:`rsocl.cli.result_lines`)."""

from __future__ import annotations

import argparse
import re
import warnings

from rsocl.common.memory import check_host_memory, host_memory_bytes
from rsocl.model.plausible import RIG_BYTES_PER_PIXEL, check_rig_memory, check_window_us, warn_unlikely_times_us

__all__ = [
    "US",
    "RIG_BYTES_PER_PIXEL",
    "add_rig_args",
    "rig_from",
    "refuse_rig_args",
    "host_memory_bytes",
    "check_host_memory",
    "check_rig_memory",
    "load_rig_file",
    "check_datacube_memory",
    "add_device_args",
    "add_solver_args",
    "check_solver_args",
    "reg_options",
    "regularizer_from",
    "solver_options",
    "progress_bar",
    "say",
    "tuning_plot_path",
    "tuning_plot_files",
    "run_reconstruction",
]

#: One microsecond, seconds (the command line gives times in µs).
US = 1e-6


class _RigOption(argparse.Action):
    """Store the value, as argparse's default action does, and note the option (its first name) in
    ``args.rig_options_given``: the rig options given on the command line, even at their default value."""

    def __call__(self, parser, namespace, values, option_string=None):
        setattr(namespace, self.dest, values)
        given = getattr(namespace, "rig_options_given", ())
        if self.option_strings[0] not in given:
            namespace.rig_options_given = (*given, self.option_strings[0])


def add_rig_args(p, cameras=4, shape=(64, 64)):
    """Add the rig group (cameras, ROI, t_e, t_r, dt in µs, mask) to parser ``p``.

    ``args.rig_options_given`` lists the ones given on the command line (``()``: none), for
    :func:`refuse_rig_args`.
    """
    g = p.add_argument_group("rig (the paper's array: angles 0, 90, 180, 270, 45, 135, 225, 315)")
    g.add_argument(
        "--cameras", type=int, default=cameras, action=_RigOption, help=f"number of cameras, 1..8 (default {cameras})"
    )
    g.add_argument(
        "--shape",
        type=int,
        nargs=2,
        default=list(shape),
        metavar=("M", "N"),
        action=_RigOption,
        help=f"ROI rows and columns, pixels (default {shape[0]} {shape[1]})",
    )
    g.add_argument(
        "--t-e-us", type=float, default=180.0, action=_RigOption, help="exposure time, µs, > 0 (default 180)"
    )
    g.add_argument(
        "--t-r-us", type=float, default=35.0, action=_RigOption, help="row readout time, µs, > 0 (default 35)"
    )
    g.add_argument(
        "--dt-us", type=float, default=None, action=_RigOption, help="sub-frame duration, µs, >= --t-r-us (default t_r)"
    )
    g.add_argument(
        "--mask",
        choices=["exact", "binary"],
        default="exact",
        action=_RigOption,
        help="shutter weights (default exact)",
    )
    p.set_defaults(rig_options_given=())


def refuse_rig_args(args, option: str, why: str) -> None:
    """Refuse the rig options of :func:`add_rig_args` given together with ``option``, which brings its
    own rig (``why`` says where it comes from): a ``ValueError`` naming them (the CLI's exit status 2),
    rather than ignoring them."""
    given = getattr(args, "rig_options_given", ())
    if given:
        raise ValueError(
            f"{', '.join(given)} cannot be used with {option}: {why}; leave {'it' if len(given) == 1 else 'them'} out"
        )


def rig_from(args):
    """The :class:`~rsocl.model.rig.Rig` of the arguments :func:`add_rig_args` added.

    The times are checked in the µs the options are given in, naming the option (an exposure of
    more sub-frames than one may span, :data:`~rsocl.model.plausible.MAX_WINDOW`, names ``--t-e-us``);
    a ``--shape`` whose rig alone would not fit this machine's memory
    (:func:`check_host_memory`) is refused before anything is allocated.
    """
    from rsocl.common import validation as check
    from rsocl.model.rig import SNAP, Rig

    t_e = check.positive("--t-e-us", args.t_e_us, "µs")
    t_r = check.positive("--t-r-us", args.t_r_us, "µs")
    dt = t_r
    if args.dt_us is not None:
        dt = check.positive("--dt-us", args.dt_us, "µs")
        if dt < t_r * (1 - SNAP):
            raise ValueError(
                f"--dt-us must be >= --t-r-us = {t_r:g} µs (a sub-frame lasts at least one row time), got {dt:g}"
            )
    check_window_us(t_e, dt)
    if warn_unlikely_times_us(t_e, t_r):  # said in µs, naming the option: not again in seconds by each camera
        warnings.filterwarnings("ignore", message=r"camera t_[er] = .* times are in seconds", category=UserWarning)
    m, n = check.grid_shape("--shape", args.shape)
    cameras = check.positive_int("--cameras", args.cameras, maximum=8)
    check_rig_memory(cameras, (m, n), f"--shape {m} {n}")
    dt = None if args.dt_us is None else args.dt_us * US
    return Rig.paper_array(cameras, (m, n), t_e=args.t_e_us * US, t_r=args.t_r_us * US, dt=dt, mask=args.mask)


def load_rig_file(path):
    """The :class:`~rsocl.files.rigfile.RigFile` at ``path`` (``--rig``); a ``[rig] shape`` whose rig alone
    would not fit this machine's memory (:func:`check_rig_memory`) is refused, naming the file and the
    shape, before any row map is read or the rig is built."""
    from rsocl.files.rigfile import load_rigfile

    def fits(shape, cameras):
        m, n = shape
        check_rig_memory(cameras, shape, f"shape = [{m}, {n}]", hint="choose a smaller [rig] shape")

    return load_rigfile(path, check_shape=fits)


def check_datacube_memory(rig, option=None, hint="choose a smaller grid or a longer --dt-us (fewer sub-frames)"):
    """Refuse a rig whose ``(T, m, n)`` float32 datacube (a scene, a reconstruction) alone exceeds
    :func:`host_memory_bytes`, naming ``option`` (default ``--shape M N``)."""
    m, n = rig.shape
    check_host_memory(
        4 * rig.T * m * n,
        option or f"--shape {m} {n}",
        f"the {rig.T} x {m} x {n} float32 datacube (T sub-frames x rows x columns)",
        hint,
    )


def add_device_args(p, dtype="float32"):
    """Add ``--device``, ``--dtype`` (default ``dtype``; None: float64 where the device has it, else
    float32) and ``--quiet`` to parser ``p``."""
    p.add_argument(
        "--device",
        default=None,
        help="OpenCL device: 'P:D' indices from 'rsocl devices', or a name substring "
        "(default: RSOCL_DEVICE, PYOPENCL_CTX, else first GPU, else CPU)",
    )
    default = "float64 where the device has it, else float32" if dtype is None else dtype
    p.add_argument(
        "--dtype", choices=["float32", "float64"], default=dtype, help=f"device precision (default {default})"
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar, only errors and the result line")


def add_solver_args(p):
    """Add the solver group (iterations, lam, eta, inner iterations, projection, regularizer) to ``p``."""
    from rsocl.solver.ladder import QUALITIES, RUNGS
    from rsocl.solver.problem import DEFAULTS

    g = p.add_argument_group("solver (defaults for scenes in [0, 1])")
    g.add_argument(
        "--iterations",
        type=iterations_arg,
        default=None,
        metavar="N|auto",
        help="ADMM iterations (default: the --quality rung's: "
        + ", ".join(f"{name} {r.iterations}" for name, r in RUNGS.items())
        + "); auto: until the residual settles, with a cap (not with --fast, whose rung runs a fixed count)",
    )
    g.add_argument(
        "--quality",
        choices=QUALITIES,
        default=None,
        help="rung of the speed/quality ladder: its iterations, parameter search and static-part fix "
        "(default balanced; docs/quality_ladder.md)",
    )
    g.add_argument(
        "--lam",
        type=float,
        default=None,
        help=f"regularization weight (default: the regularizer's recommendation, else {DEFAULTS['lam']})",
    )
    g.add_argument(
        "--eta",
        type=float,
        default=None,
        help=f"ADMM penalty; 0 runs GAP (default: the regularizer's recommendation, else {DEFAULTS['eta']})",
    )
    g.add_argument("--tv-iterations", type=int, default=None, help="inner denoiser iterations (TV default 10)")
    g.add_argument("--projection", choices=["exact", "paper"], default="exact")
    g.add_argument("--regularizer", default="tv", help="regularizer name (see 'rsocl plugins')")
    g.add_argument(
        "--reg-opt",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="regularizer option, repeatable (iterations=N is --tv-iterations N: give one of them)",
    )
    g.add_argument(
        "--saturation",
        type=float,
        default=None,
        metavar="LEVEL",
        help="snapshot value (the capture's units) at and above which a pixel is clipped: a lower bound, "
        "fitted one-sided (default: none; docs/saturation.md)",
    )
    g.add_argument("--fast", action="store_true", help="--quality fast: the cheapest rung of the ladder")
    g.add_argument(
        "--fixed",
        action="store_true",
        help="no parameter search: the fixed lam and regularizer options, zero start (by default the "
        "values not given are chosen from the snapshots by cross-validation, as --quality says; a "
        "tiled run chooses once, on the centre block, for every tile)",
    )
    g.add_argument(
        "--blend",
        type=float,
        default=None,
        metavar="B",
        help="in [0, 1]: return start + B (result - start), the solver's result moved back towards the "
        "interpolation a self-tuned run starts from; 1: the solver's own result (default: the "
        "blend chosen from the snapshots with the other values)",
    )
    p.set_defaults(check_options=check_solver_args)


def check_solver_args(args) -> None:
    """Refuse solver options that contradict each other, before the command runs (``rsocl.cli.main``
    calls it): ``--reg-opt iterations=N`` with a different ``--tv-iterations M`` (one of them was
    silently ignored); a ``--reg-opt`` that is not ``KEY=VALUE``; an unknown ``--regularizer`` or an
    option it refuses (name or range); ``--saturation`` not above 0; ``--blend`` outside [0, 1], or
    below 1 with ``--fixed`` (a zero start); ``--fast`` with another ``--quality``; ``--iterations
    auto`` on a rung that refuses it, before anything is simulated, loaded or run."""
    from rsocl.common import validation as check
    from rsocl.solver.ladder import check_iterations

    options = reg_options(args.reg_opt)
    if args.fast and args.quality not in (None, "fast"):
        raise ValueError(f"--fast is --quality fast; it contradicts --quality {args.quality}: give one of them")
    check_iterations(args.iterations, quality_of(args))
    if args.saturation is not None:
        check.positive("--saturation", args.saturation, "(the capture's snapshot units)")
    if args.blend is not None:
        check.in_range("--blend", args.blend, 0.0, 1.0)
        if args.blend < 1 and args.fixed:
            raise ValueError(
                f"--blend {args.blend:g} moves the result towards the interpolation a self-tuned run "
                "starts from; --fixed runs from zeros: leave out --fixed or --blend"
            )
    if args.tv_iterations is not None and "iterations" in options:
        given = options["iterations"]
        try:
            same = int(given) == args.tv_iterations
        except ValueError:
            same = False
        if not same:
            raise ValueError(
                f"--reg-opt iterations={given} and --tv-iterations {args.tv_iterations} both set the "
                "regularizer's inner iterations, to different values; give one of them"
            )
    regularizer_from(args)


def iterations_arg(text: str):
    """``--iterations``: an integer in [1, :data:`~rsocl.solver.problem.MAX_ITERATIONS`] or ``auto``."""
    from rsocl.solver.problem import MAX_ITERATIONS

    if text.strip() == "auto":
        return "auto"
    value = int(text) if re.fullmatch(r"\s*\+?\d+\s*", text) else 0
    if not 1 <= value <= MAX_ITERATIONS:
        raise argparse.ArgumentTypeError(f"must be an integer in [1, {MAX_ITERATIONS}] or 'auto', got {text!r}")
    return value


def quality_of(args) -> str:
    """The rung ``--quality`` and ``--fast`` name (default :data:`rsocl.solver.ladder.DEFAULT_QUALITY`)."""
    from rsocl.solver.ladder import DEFAULT_QUALITY

    return "fast" if args.fast else (args.quality or DEFAULT_QUALITY)


def reg_options(pairs):
    """``["KEY=VALUE", ...]`` of ``--reg-opt`` -> ``{KEY: VALUE}`` (strings; the regularizer parses them)."""
    options = {}
    for pair in pairs:
        if "=" not in pair:
            raise ValueError(f"--reg-opt must be KEY=VALUE, got {pair!r}")
        key, value = pair.split("=", 1)
        options[key.strip()] = value.strip()
    return options


def progress_bar(args) -> bool:
    """Whether to draw a progress bar: not with ``--quiet``, and only on a terminal (stderr, where the
    bars go, redirected to a file or a pipe would collect every redraw)."""
    import sys

    if getattr(args, "quiet", False):
        return False
    try:
        return bool(sys.stderr.isatty())
    except (AttributeError, ValueError):  # a closed or replaced stream
        return False


def regularizer_from(args):
    """The configured regularizer of ``--regularizer``, ``--reg-opt`` and ``--tv-iterations`` (where the
    command has it): the instance whose options the memory counts and the run use."""
    from rsocl.solver.request import make_regularizer

    return make_regularizer(args.regularizer, reg_options(args.reg_opt), getattr(args, "tv_iterations", None))


def solver_options(args) -> dict:
    """The solver and device arguments as the keyword arguments of :func:`rsocl.reconstruct`,
    :func:`rsocl.solver.sets.reconstruct_sets` and :func:`rsocl.scale.reconstruct_tiled` (the one map
    of the command line onto the API)."""
    return {
        "regularizer": args.regularizer,
        "regularizer_options": reg_options(args.reg_opt),
        "iterations": args.iterations,
        "lam": args.lam,
        "eta": args.eta,
        "tv_iterations": args.tv_iterations,
        "projection": args.projection,
        "device": args.device,
        "dtype": args.dtype,
        "tune": not args.fixed,
        "quality": quality_of(args),
        "blend": args.blend,
        "saturation": args.saturation,
        "progress": not args.quiet,
    }


def say(args, *text):
    """Print ``text`` unless ``--quiet``."""
    if not getattr(args, "quiet", False):
        print(*text, flush=True)


def tuning_plot_path(gif):
    """Where the search's plot goes: ``NAME-tuning.png`` next to the GIF ``NAME.gif``."""
    from pathlib import Path

    gif = Path(gif)
    return gif.with_name(gif.stem + "-tuning.png")


def tuning_plot_files(args, params, gif) -> list:
    """Say the values chosen from the snapshots and plot the criterion next to ``gif`` (as
    ``NAME-tuning.png``); the files written. With no search to plot, an earlier run's plot there is moved to
    ``NAME-tuning.earlier-<UTC time>.png`` (:func:`rsocl.cli.outputs.set_aside_plot`) and said."""
    tuning = params.get("tuning")
    if tuning:
        chosen = ", ".join(f"{k} = {v:.3g}" for k, v in tuning["chosen"].items())
        if params.get("blend") is not None and params["blend"] < 1:
            chosen += f", blend with the interpolation {params['blend']:.2f}"
        say(args, f"chosen from the snapshots: {chosen}")
    if not tuning or not tuning.get("candidates"):  # no search (one snapshot per pixel: no criterion)
        from rsocl.cli.outputs import set_aside_plot

        kept = set_aside_plot(tuning_plot_path(gif))
        if kept is not None:
            say(args, f"moved an earlier run's search plot {tuning_plot_path(gif)} to {kept}")
        return []
    from rsocl.analysis.tuning_plot import tuning_plot

    return [tuning_plot(tuning_plot_path(gif), tuning)]


def run_reconstruction(args, g, rig, truth=None):
    """:func:`rsocl.reconstruct` of snapshots ``g`` with the solver and device arguments."""
    from rsocl.solver.reconstruct import reconstruct

    return reconstruct(g, rig, truth=truth, **solver_options(args))
