"""``rsocl simulate``: a scene (built-in or a video file) through a rig -> a capture file (HDF5)."""

from __future__ import annotations

from rsocl.cli.options import US, add_device_args, add_rig_args, check_datacube_memory, check_rig_memory, rig_from, say

__all__ = ["add_parser", "check_noise_args", "multi_frame_rig", "scene_datacube", "cmd_simulate"]


def add_parser(subparsers):
    """Add ``simulate`` to the ``rsocl`` sub-parsers; returns its parser."""
    p = subparsers.add_parser("simulate", help="scene file -> capture file (HDF5)")
    p.add_argument("scene", help="'builtin' or a video: .npz (key 'video'), multi-page .tif, .gif")
    p.add_argument(
        "--out",
        required=True,
        help="capture file to write (.h5); never one that holds frames from cameras; a file there other than a "
        "simulated capture is kept as STEM.earlier-<UTC time>.h5",
    )
    add_rig_args(p)
    p.add_argument(
        "--frames",
        type=int,
        default=1,
        help="frames every camera captures per trigger, >= 1 (default 1); a multi-frame capture is what "
        "'rsocl reconstruct --window F' reconstructs",
    )
    p.add_argument(
        "--t-d-us",
        type=float,
        default=None,
        help="with --frames > 1: frame period, µs (default: the readout of the camera reading the most "
        "rows, t_r x rows, so consecutive frames follow each other)",
    )
    p.add_argument(
        "--noise",
        choices=["none", "gaussian", "poisson"],
        default="none",
        help="noise model (default none); gaussian needs --sigma, poisson --photons",
    )
    p.add_argument(
        "--sigma",
        type=float,
        default=None,
        help="gaussian noise standard deviation, fraction of full scale, >= 0 (no default)",
    )
    p.add_argument(
        "--photons",
        type=float,
        default=None,
        help="photo-electrons at full scale, > 0 and <= 1e18 (poisson noise; no default)",
    )
    p.add_argument("--bit-depth", type=int, default=None, help="quantise to this many bits, 1..32")
    p.add_argument("--seed", type=int, default=0, help="seed of the noise generator, >= 0 (default 0)")
    add_device_args(p)
    p.set_defaults(func=cmd_simulate)
    return p


def check_noise_args(args) -> None:
    """The noise options, before anything is computed: ``--noise gaussian`` needs ``--sigma`` and
    ``--noise poisson`` needs ``--photons`` (neither has a default), each only with its model (given
    with another they would be ignored), ``--photons`` is at most
    :data:`~rsocl.model.simulate.MAX_PHOTONS`, ``--bit-depth`` is 1..32 and ``--seed`` >= 0."""
    from rsocl.common import validation as check
    from rsocl.model.simulate import check_photons, check_seed

    needs = {
        "gaussian": ("--sigma", args.sigma, "the standard deviation as a fraction of full scale, >= 0"),
        "poisson": ("--photons", args.photons, "photo-electrons at full scale, > 0"),
    }
    for model, (option, value, meaning) in needs.items():
        if args.noise == model and value is None:
            raise ValueError(f"--noise {model} needs {option} ({meaning}); it has no default")
        if args.noise != model and value is not None:
            raise ValueError(f"{option} applies to --noise {model} only; with --noise {args.noise} it would be ignored")
    if args.sigma is not None:
        check.non_negative("--sigma", args.sigma, "(fraction of full scale)")
    if args.photons is not None:
        check_photons("--photons", args.photons)
    if args.bit_depth is not None:
        check.positive_int("--bit-depth", args.bit_depth, maximum=32)
    check_seed("--seed", args.seed)


def multi_frame_rig(args, rig):
    """``rig`` with every camera capturing ``--frames`` frames, ``--t-d-us`` apart (default: the longest
    readout, ``t_r`` times the most rows a camera reads); ``rig`` itself for one frame."""
    from rsocl.common import validation as check
    from rsocl.model.rig import MAX_T, Camera, Rig

    frames = check.positive_int("--frames", args.frames)
    if frames == 1:
        if args.t_d_us is not None:
            raise ValueError(
                "--t-d-us is the period between the frames of --frames N > 1; with one frame it would be ignored"
            )
        return rig
    if args.t_d_us is None:
        t_d = max((float(rig.row_map(i).max()) + 1.0) * cam.t_r for i, cam in enumerate(rig.cameras))
    else:
        t_d = check.positive("--t-d-us", args.t_d_us, "µs") * US
    # refused before the rig's per-frame exposure windows are allocated
    span = (frames - 1) * t_d + max(
        cam.t_e + float(rig.row_map(i).max()) * cam.t_r for i, cam in enumerate(rig.cameras)
    )
    if span / rig.dt > MAX_T:
        raise ValueError(
            f"--frames {frames} frames {t_d / US:g} µs apart span {span / rig.dt:,.0f} sub-frames of "
            f"{rig.dt / US:g} µs, above the {MAX_T:,} a rig may span; give fewer --frames"
        )
    check_rig_memory(rig.C * frames, rig.shape, f"--frames {frames}", hint="give fewer --frames or a smaller --shape")
    cameras = [Camera(cam.angle, t_e=cam.t_e, t_r=cam.t_r, t_d=t_d, frames=frames) for cam in rig.cameras]
    try:
        return Rig(cameras, rig.shape, dt=rig.dt, mask=rig.mask)
    except ValueError as exc:
        raise ValueError(f"--frames {frames} --t-d-us {t_d / US:g}: {exc}") from None


def scene_datacube(args, rig):
    """The ``(T, m, n)`` datacube of ``args.scene`` for ``rig``; a video of another size is resized
    (and resampled in time) with a one-line warning saying from what to what and how to keep its size."""
    import warnings

    from rsocl.model.scenes import benchmark_protocol, load_scene
    from rsocl.model.video import load_video

    if args.scene == "builtin":
        return load_scene(args.scene, rig.shape, rig.T)
    video = load_video(args.scene)
    F, h, w = video.shape
    m, n = rig.shape
    if (h, w) != (m, n) or F != rig.T:
        keep = f"give --shape {h} {w} to keep its size" if (h, w) != (m, n) else "its size is kept"
        warnings.warn(
            f"scene {args.scene}: {F} frames of {h}x{w} resized to T = {rig.T} sub-frames of {m}x{n} "
            f"({keep}; T follows from --t-e-us, --t-r-us, --dt-us, --frames and the shape)",
            stacklevel=2,
        )
    return benchmark_protocol(video, rig.shape, rig.T)


def cmd_simulate(args) -> int:
    """Simulate the snapshots of ``args.scene`` and write them, the rig and the truth to ``--out``; returns 0.

    A capture from cameras at ``--out`` is refused first; a file there other than a simulated capture (a
    reconstruction, say) is kept as ``<stem>.earlier-<UTC time><suffix>``.
    """
    from rsocl.cli.outputs import kept_note
    from rsocl.files.atomic import output_path
    from rsocl.files.hdf5 import keeping_unless_simulated, refuse_camera_capture, save_capture
    from rsocl.model.simulate import simulate

    check_noise_args(args)
    output_path(args.out, "--out", inputs=(("scene", None if args.scene == "builtin" else args.scene),))
    refuse_camera_capture(args.out, "--out")
    rig = multi_frame_rig(args, rig_from(args))
    check_datacube_memory(rig)
    truth = scene_datacube(args, rig)
    g = simulate(
        truth,
        rig,
        noise=args.noise,
        sigma=args.sigma or 0.0,
        photons=args.photons,
        bit_depth=args.bit_depth,
        seed=args.seed,
        device=args.device,
    )
    meta = {
        "scene": str(args.scene),
        "noise": args.noise,
        "sigma": args.sigma,
        "photons": args.photons,
        "bit_depth": args.bit_depth,
        "seed": args.seed,
    }
    with keeping_unless_simulated(args.out) as kept:
        path = save_capture(args.out, g, rig, truth=truth, attrs=meta)
    frames = f" ({rig.C} cameras x {rig.cameras[0].frames} frames)" if rig.cameras[0].frames > 1 else ""
    size = f"{rig.shape[0]}x{rig.shape[1]}, T = {rig.T}"
    say(args, f"wrote {path}: {rig.n_channels} snapshots{frames} of {size}" + kept_note([kept]))
    return 0
