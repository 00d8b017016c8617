"""The ``rsocl`` command: demo, simulate, reconstruct, capture, calibrate, plan, bench, info, devices, plugins."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

__all__ = ["main"]

US = 1e-6


# ---------------------------------------------------------------------- arguments
def _add_rig_args(p, cameras=4, shape=(64, 64)):
    g = p.add_argument_group("rig (the paper's array: angles 0, 90, 180, 270, 45, 135, 225, 315)")
    g.add_argument("--cameras", type=int, default=cameras, help=f"number of cameras, 1..8 (default {cameras})")
    g.add_argument("--shape", type=int, nargs=2, default=list(shape), metavar=("M", "N"),
                   help=f"ROI rows and columns, pixels (default {shape[0]} {shape[1]})")
    g.add_argument("--t-e-us", type=float, default=180.0, help="exposure time, µs (default 180)")
    g.add_argument("--t-r-us", type=float, default=35.0, help="row readout time, µs (default 35)")
    g.add_argument("--dt-us", type=float, default=None, help="sub-frame duration, µs (default t_r)")
    g.add_argument("--mask", choices=["exact", "binary"], default="exact", help="shutter weights (default exact)")


def _rig_from(args):
    from rsocl.model.rig import Rig

    dt = None if args.dt_us is None else args.dt_us * US
    return Rig.paper_array(args.cameras, tuple(args.shape), t_e=args.t_e_us * US, t_r=args.t_r_us * US,
                           dt=dt, mask=args.mask)


def _add_device_args(p):
    p.add_argument("--device", default=None,
                   help="OpenCL device: 'P:D' indices from 'rsocl devices', or a name substring "
                        "(default: RSOCL_DEVICE, PYOPENCL_CTX, else first GPU, else CPU)")
    p.add_argument("--dtype", choices=["float32", "float64"], default="float32", help="device precision")
    p.add_argument("--quiet", action="store_true", help="no progress bar, only errors and the result line")


def _add_solver_args(p):
    from rsocl.solver.reconstruct import DEFAULTS

    g = p.add_argument_group("solver (defaults for scenes in [0, 1])")
    g.add_argument("--iterations", type=int, default=DEFAULTS["iterations"])
    g.add_argument("--lam", type=float, default=None,
                   help=f"regularization weight (default: the regularizer's recommendation, else {DEFAULTS['lam']})")
    g.add_argument("--eta", type=float, default=None,
                   help=f"ADMM penalty; 0 runs GAP (default: the regularizer's recommendation, else {DEFAULTS['eta']})")
    g.add_argument("--tv-iterations", type=int, default=None, help="inner denoiser iterations (TV default 10)")
    g.add_argument("--projection", choices=["exact", "paper"], default="exact")
    g.add_argument("--regularizer", default="tv", help="regularizer name (see 'rsocl plugins')")
    g.add_argument("--reg-opt", action="append", default=[], metavar="KEY=VALUE",
                   help="regularizer option, repeatable")


def _reg_options(pairs):
    options = {}
    for pair in pairs:
        if "=" not in pair:
            raise ValueError(f"--reg-opt must be KEY=VALUE, got {pair!r}")
        key, value = pair.split("=", 1)
        options[key.strip()] = value.strip()
    return options


def _say(args, *text):
    if not args.quiet:
        print(*text, flush=True)


def _run_reconstruction(args, g, rig, truth=None):
    from rsocl.solver.reconstruct import reconstruct

    return reconstruct(g, rig, regularizer=args.regularizer, regularizer_options=_reg_options(args.reg_opt),
                       iterations=args.iterations, lam=args.lam, eta=args.eta, tv_iterations=args.tv_iterations,
                       projection=args.projection, device=args.device, dtype=args.dtype, truth=truth,
                       progress=not args.quiet)


def _quality_line(result, truth):
    from rsocl.analysis.metrics import psnr, ssim

    seconds = result.history["time"][-1]
    text = f"{result.iterations} iterations in {seconds:.2f} s ({seconds / result.iterations * 1e3:.1f} ms/iteration)"
    if truth is not None:
        mean_ssim, _ = ssim(result.datacube, truth)
        text = f"PSNR {psnr(result.datacube, truth):.2f} dB, SSIM {mean_ssim:.3f}, " + text
    return text


# ---------------------------------------------------------------------- commands
def cmd_demo(args):
    from rsocl.files.hdf5 import save_reconstruction
    from rsocl.model.operator import RollingShutterOperator
    from rsocl.model.scenes import builtin_scene
    from rsocl.analysis.visual import comparison_gif, datacube_montage, snapshot_montage

    rig = _rig_from(args)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    truth = builtin_scene(rig.shape, rig.T)
    op = RollingShutterOperator(rig, device=args.device, dtype=args.dtype)
    g = op.forward(truth)
    _say(args, f"rig: {rig!r}\ndevice: {op.device.name}\ncompression: {rig.T} sub-frames from "
               f"{rig.n_channels} snapshots (CR {rig.compression_ratio:.1f}x)")
    result = _run_reconstruction(args, g, rig, truth)
    print(_quality_line(result, truth))
    files = [save_reconstruction(out / "demo.h5", result.datacube, rig, params=result.params,
                                 history=result.history, truth=truth),
             comparison_gif(out / "demo.gif", truth, result.datacube),
             snapshot_montage(out / "snapshots.png", g, rig=rig),
             datacube_montage(out / "subframes.png", result.datacube, truth=truth)]
    _say(args, "wrote " + ", ".join(str(f) for f in files))
    return 0


def cmd_simulate(args):
    from rsocl.files.hdf5 import save_capture
    from rsocl.model.scenes import load_scene
    from rsocl.model.simulate import simulate

    rig = _rig_from(args)
    truth = load_scene(args.scene, rig.shape, rig.T)
    g = simulate(truth, rig, noise=args.noise, sigma=args.sigma, photons=args.photons, bit_depth=args.bit_depth,
                 seed=args.seed, device=args.device)
    meta = {"scene": str(args.scene), "noise": args.noise, "sigma": args.sigma, "photons": args.photons,
            "bit_depth": args.bit_depth, "seed": args.seed}
    path = save_capture(args.out, g, rig, truth=truth, attrs=meta)
    _say(args, f"wrote {path}: {rig.n_channels} snapshots of {rig.shape[0]}x{rig.shape[1]}, T = {rig.T}")
    return 0


def cmd_reconstruct(args):
    from rsocl.files.hdf5 import load_capture, save_reconstruction
    from rsocl.analysis.visual import comparison_gif
    from rsocl.cli.tiling import check_outputs, reconstruct_tiled_if_needed

    check_outputs(args)
    code = reconstruct_tiled_if_needed(args, lambda *text: _say(args, *text), _reg_options(args.reg_opt))
    if code is not None:
        return code
    capture = load_capture(args.capture)
    truth = capture.truth if not args.no_truth else None
    result = _run_reconstruction(args, capture.snapshots, capture.rig, truth)
    print(_quality_line(result, truth))
    out = Path(args.out)
    save_reconstruction(out, result.datacube, capture.rig, params=result.params, history=result.history,
                        truth=capture.truth)
    gif = Path(args.gif) if args.gif else out.with_suffix(".gif")
    comparison_gif(gif, truth, result.datacube)
    _say(args, f"wrote {out} and {gif}")
    return 0


def cmd_info(args):
    from rsocl.files.hdf5 import load_capture

    rig = load_capture(args.capture).rig if args.capture else _rig_from(args)
    m, n = rig.shape
    rows = [
        ("cameras", f"{rig.C} ({rig.n_channels} snapshots)"),
        ("ROI", f"{m} x {n} pixels"),
        ("sub-frame dt", f"{rig.dt / US:g} µs ({rig.subframe_rate:,.0f} sub-frames/s)"),
        ("mask", rig.mask),
        ("T (sub-frames)", f"{rig.T}"),
        ("N_s = ceil(t_e/t_r)", f"{rig.N_s}"),
        ("t_e/dt (exact rule)", f"{rig.exposure_subframes:.2f}"),
        ("T_se (trimmed)", f"{rig.T_se} (sub-frames {rig.kept_subframes().start}..{rig.kept_subframes().stop - 1}, "
                           f"each seen by >= {rig.min_cameras} cameras)"),
        ("compression ratio", f"{rig.compression_ratio:.2f}x (T_se / snapshots)"),
        (f"effective fps at {args.camera_fps:g} fps", f"{rig.effective_fps(args.camera_fps):,.0f}"),
        ("datacube", f"{rig.datacube_bytes(4) / 2**20:.2f} MiB in float32"),
    ]
    width = max(len(k) for k, _ in rows)
    for key, value in rows:
        print(f"{key:<{width}}  {value}")
    return 0


def cmd_plan(args):
    from rsocl.solver.plan import format_plan, plan

    rig = _rig_from(args)
    p = plan(rig, roi=args.roi, speed=args.speed, fps=args.fps, blur_pixels=args.blur, iterations=args.iterations,
             regularizer=args.regularizer, dtype=args.dtype, device=args.device, measure=not args.no_measure)
    print(format_plan(p))
    from rsocl.cli.tiling import print_plan_tiling

    print_plan_tiling(args, p)
    return 0


def cmd_devices(args):
    from rsocl.device.context import INSTALL_HINT, get_device, list_devices

    found = list_devices()
    if not found:
        print(f"no OpenCL device found; {INSTALL_HINT}")
        return 1
    import pyopencl as cl

    default = get_device(None).device
    for pi, di, platform, dev in found:
        mark = "*" if dev == default else " "
        fp64 = "fp64" if "cl_khr_fp64" in dev.extensions else "no fp64"
        print(f"{mark} {pi}:{di}  {platform.name.strip()} / {dev.name.strip()}  "
              f"[{cl.device_type.to_string(dev.type)}, {dev.max_compute_units} units, "
              f"{dev.global_mem_size / 2**30:.1f} GiB, max buffer {dev.max_mem_alloc_size / 2**30:.1f} GiB, {fp64}]")
    print("* = default choice")
    return 0


def cmd_plugins(args):
    from rsocl.common.registry import GROUPS, status

    broken = 0
    for group in GROUPS:
        print(group)
        rows = status(group)
        if not rows:
            print("  (none)")
        for info, name, state in rows:
            broken += state != "ok"
            print(f"  {name:<12} {info.distribution} {info.version:<10} {info.value:<42} {state}")
    return 0


# ---------------------------------------------------------------------- parser
def build_parser():
    parser = argparse.ArgumentParser(prog="rsocl", description="High-speed video from rotated rolling-shutter "
                                                               "cameras, reconstructed on OpenCL.")
    from rsocl import __version__

    parser.add_argument("--version", action="version", version=f"rsocl {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("demo", help="simulate the paper's array on the built-in scene and reconstruct it")
    _add_rig_args(p)
    _add_solver_args(p)
    _add_device_args(p)
    p.add_argument("--out", default="rsocl-demo", help="output folder (default ./rsocl-demo)")
    p.set_defaults(func=cmd_demo)

    p = sub.add_parser("simulate", help="scene file -> capture file (HDF5)")
    p.add_argument("scene", help="'builtin' or a video: .npz (key 'video'), multi-page .tif, .gif")
    p.add_argument("--out", required=True, help="capture file to write (.h5)")
    _add_rig_args(p)
    p.add_argument("--noise", choices=["none", "gaussian", "poisson"], default="none")
    p.add_argument("--sigma", type=float, default=0.0, help="gaussian noise, fraction of full scale")
    p.add_argument("--photons", type=float, default=None, help="photo-electrons at full scale (poisson)")
    p.add_argument("--bit-depth", type=int, default=None, help="quantise to this many bits")
    p.add_argument("--seed", type=int, default=0)
    _add_device_args(p)
    p.set_defaults(func=cmd_simulate)

    p = sub.add_parser("reconstruct", help="capture file -> reconstruction file and GIF")
    p.add_argument("capture", help="capture file (.h5) from 'rsocl simulate' or 'rsocl capture'")
    p.add_argument("--out", required=True, help="reconstruction file to write (.h5), or a Zarr store (.zarr)")
    p.add_argument("--gif", default=None, help="GIF to write (default: next to an .h5 --out)")
    p.add_argument("--no-truth", action="store_true", help="ignore a ground truth stored in the capture")
    _add_solver_args(p)
    _add_device_args(p)
    from rsocl.cli.tiling import add_reconstruct_tiling_args

    add_reconstruct_tiling_args(p)
    p.set_defaults(func=cmd_reconstruct)

    p = sub.add_parser("info", help="T, N_s, T_se, compression ratio and effective fps of a rig")
    _add_rig_args(p, shape=(50, 50))
    p.add_argument("--capture", default=None, help="read the rig from this capture file instead")
    p.add_argument("--camera-fps", type=float, default=67.0, help="camera frame rate, Hz (default 67)")
    p.set_defaults(func=cmd_info)

    p = sub.add_parser("plan", help="propose dt, ROI and T_se for a scene, with memory and time, before running")
    _add_rig_args(p, shape=(256, 256))
    p.add_argument("--roi", type=int, nargs=4, metavar=("Y", "X", "H", "W"), default=None,
                   help="where the motion is, reference pixels (default: whole grid)")
    p.add_argument("--speed", type=float, default=None, help="largest image speed, pixels/s")
    p.add_argument("--fps", type=float, default=None, help="sub-frame rate wanted, Hz")
    p.add_argument("--blur", type=float, default=1.0, help="motion allowed within a sub-frame, pixels (default 1)")
    p.add_argument("--iterations", type=int, default=200)
    p.add_argument("--regularizer", default="tv")
    p.add_argument("--no-measure", action="store_true", help="memory only; do not time 3 iterations")
    _add_device_args(p)
    from rsocl.cli.tiling import add_plan_tiling_args

    add_plan_tiling_args(p)
    p.set_defaults(func=cmd_plan)

    from rsocl.bench.run import add_bench_parser
    from rsocl.cli.calibrate import add_calibrate_parser
    from rsocl.hardware.capture import add_capture_parser

    add_bench_parser(sub)
    add_capture_parser(sub)
    add_calibrate_parser(sub)

    p = sub.add_parser("devices", help="list OpenCL platforms and devices")
    p.set_defaults(func=cmd_devices)

    p = sub.add_parser("plugins", help="list regularizer and camera plugins and their status")
    p.set_defaults(func=cmd_plugins)
    return parser


def main(argv=None) -> int:
    from rsocl.device.context import NoOpenCLError

    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except (ValueError, FileNotFoundError, NoOpenCLError, FloatingPointError) as exc:
        print(f"rsocl {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"rsocl {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
