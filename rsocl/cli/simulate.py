"""``rsocl simulate``: a scene (built-in or a video file) through a rig -> a capture file (HDF5)."""

from __future__ import annotations

from rsocl.cli.options import (
    RIG_BYTES_PER_PIXEL,
    US,
    add_device_args,
    add_rig_args,
    check_datacube_memory,
    check_host_memory,
    progress_bar,
    rig_from,
)

__all__ = [
    "add_parser",
    "check_noise_args",
    "run_bytes",
    "check_run_memory",
    "multi_frame_rig",
    "scene_datacube",
    "cmd_simulate",
    "RUN_MEMORY_FACTOR",
    "STEPS",
]

# Peak resident memory of a run over run_bytes() (the rig, the float32 truth and the float64
# snapshots), per --dtype: the forward model's temporaries (the truth and the snapshots in the device
# dtype, on the host and in device buffers, which a CPU OpenCL device keeps in host memory; the
# operator's geometry per channel and pixel; the float64 copy of its result) and the file's writer.
# Measured with /usr/bin/time -v on `rsocl simulate builtin --shape 16 16` on PoCL (CPU), 1 / 2000 /
# 5000 / 10000 frames (run_bytes 0.0 / 90.1 / 225.3 / 450.6 MB; 20000 frames 901.1 MB):
#   float32: peak RSS 143.6 / 349.4 / 629.7 / 1014.0 MB: 2.07x then 1.71x run_bytes per added frame,
#            2.25x in all at 10000 frames;
#   float64: peak RSS 143.5 / 421.4 / 853.7 / 1495.5 MB (2851.7 MB at 20000): 3.20x, 2.85x, 3.01x
#            per added frame, 3.32x in all at 10000 frames.
# Each factor is above every ratio measured for its dtype (float32 by 11 %, float64 by 5 %); the
# in-all ratios include the ~140 MB of a one-frame run, so larger runs sit further below it.
RUN_MEMORY_FACTOR = {"float32": 2.5, "float64": 3.5}


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
    add_device_args(p, dtype=None)  # rsocl.simulate's own default
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


def run_bytes(rig, frames: int, subframes: float) -> int:
    """Bytes of the arrays of a run of ``rig`` (one frame per camera) with ``frames`` frames per camera
    and ``subframes`` sub-frames: the rig's row maps and exposure windows
    (:data:`~rsocl.cli.options.RIG_BYTES_PER_PIXEL` per channel and pixel), the float32 truth
    ``(subframes, m, n)`` and the float64 snapshots ``(cameras * frames, m, n)``."""
    m, n = rig.shape
    channels = len(rig.cameras) * frames
    return int(channels * m * n * (RIG_BYTES_PER_PIXEL + 8) + 4 * subframes * m * n)


def check_run_memory(args, rig, frames: int = 1, t_d: float = 0.0) -> None:
    """Refuse, before anything is allocated, a run whose arrays (:func:`run_bytes`) times
    :data:`RUN_MEMORY_FACTOR` of ``--dtype`` (the forward model's temporaries) exceed the host memory
    (:func:`~rsocl.common.memory.check_host_memory`), naming ``--frames`` and the most frames that fit
    (``--shape`` when one frame does not fit).

    ``rig`` is the one-frame rig of the command line and ``t_d`` the period of its frames, seconds: a
    run of ``frames`` frames spans at most ``rig.T + 1 + (frames - 1) * t_d / dt`` sub-frames.
    """
    from rsocl.common import memory

    dtype = args.dtype or "float64"  # the device's choice: at most float64's
    factor = RUN_MEMORY_FACTOR[dtype]

    def span(count: int) -> float:
        return rig.T + 1 + (count - 1) * t_d / rig.dt

    def need(count: int) -> float:
        return factor * run_bytes(rig, count, span(count))

    limit, total = memory.host_memory_bytes(), need(frames)
    if limit is None or total <= limit:
        return
    m, n = rig.shape
    C = len(rig.cameras)
    most = 1 + int((limit - need(1)) // (need(2) - need(1))) if need(1) <= limit else 0
    if frames > 1 and most >= 1:
        option = f"--frames {frames}"
        hint = (
            f"--frames must be 1..{most:,} at --shape {m} {n}, --cameras {C}, --t-d-us {t_d / US:g} and "
            f"--dtype {dtype}; give fewer --frames or a smaller --shape"
        )
    else:
        option = f"--shape {m} {n}" + (f" --frames {frames}" if frames > 1 else "")
        hint = "not even one frame fits: choose a smaller --shape or a longer --dt-us (fewer sub-frames)"
    check_host_memory(
        total,
        option,
        f"simulating {C} x {frames} snapshots of {m} x {n} over about {span(frames):,.0f} sub-frames (the rig, "
        f"the float32 scene and the float64 snapshots, {factor:g}x for the {dtype} forward model)",
        hint,
    )


def multi_frame_rig(args, rig):
    """``rig`` with every camera capturing ``--frames`` frames, ``--t-d-us`` apart (default: the longest
    readout, ``t_r`` times the most rows a camera reads); ``rig`` itself for one frame. A run that
    would not fit the host memory (:func:`check_run_memory`) is refused first."""
    from rsocl.common import validation as check
    from rsocl.model.rig import MAX_T, Camera, Rig

    frames = check.positive_int("--frames", args.frames)
    if frames == 1:
        if args.t_d_us is not None:
            raise ValueError(
                "--t-d-us is the period between the frames of --frames N > 1; with one frame it would be ignored"
            )
        check_datacube_memory(rig)
        check_run_memory(args, rig)
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
    check_run_memory(args, rig, frames, t_d)
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


#: The steps of a run, as its progress bar names them.
STEPS = ("rig", "scene", "snapshots", "writing")


def _steps(args):
    """A progress bar (tqdm) over :data:`STEPS`, drawn where :func:`~rsocl.cli.options.progress_bar` says."""
    from tqdm.auto import tqdm

    return tqdm(
        total=len(STEPS),
        desc="simulate",
        unit="step",
        leave=False,
        disable=not progress_bar(args),
        bar_format="{desc}: {n_fmt}/{total_fmt} steps |{bar}| {elapsed}",
    )


def _step(bar, name: str) -> None:
    """Mark the steps before ``name`` done and show ``name`` as the one running."""
    bar.update(STEPS.index(name) - bar.n)
    bar.set_description_str(f"simulate ({name})")


def cmd_simulate(args) -> int:
    """Simulate the snapshots of ``args.scene`` and write them, the rig and the truth to ``--out``; returns 0.

    A capture from cameras at ``--out`` is refused first; a file there other than a simulated capture (a
    reconstruction, say) is kept as ``<stem>.earlier-<UTC time><suffix>``.
    """
    from rsocl.cli.outputs import interrupted, kept_note, nothing_written, require_hdf5_name
    from rsocl.files.atomic import output_path
    from rsocl.files.hdf5 import keeping_unless_simulated, refuse_camera_capture, save_capture
    from rsocl.model.simulate import simulate

    check_noise_args(args)
    output_path(args.out, "--out", inputs=(("scene", None if args.scene == "builtin" else args.scene),))
    require_hdf5_name(args.out)
    refuse_camera_capture(args.out, "--out")
    with interrupted(nothing_written(args.out)), _steps(args) as bar:  # --out is replaced by its last step
        _step(bar, "rig")
        rig = multi_frame_rig(args, rig_from(args))
        _step(bar, "scene")
        truth = scene_datacube(args, rig)
        _step(bar, "snapshots")
        g = simulate(
            truth,
            rig,
            noise=args.noise,
            sigma=args.sigma or 0.0,
            photons=args.photons,
            bit_depth=args.bit_depth,
            seed=args.seed,
            device=args.device,
            dtype=args.dtype,
        )
        meta = {
            "scene": str(args.scene),
            "noise": args.noise,
            "sigma": args.sigma,
            "photons": args.photons,
            "bit_depth": args.bit_depth,
            "seed": args.seed,
        }
        _step(bar, "writing")
        with keeping_unless_simulated(args.out) as kept:
            path = save_capture(args.out, g, rig, truth=truth, attrs=meta)
    frames = f" ({rig.C} cameras x {rig.cameras[0].frames} frames)" if rig.cameras[0].frames > 1 else ""
    size = f"{rig.shape[0]}x{rig.shape[1]}, T = {rig.T}"
    print(f"wrote {path}: {rig.n_channels} snapshots{frames} of {size}" + kept_note([kept]))  # --quiet too
    return 0
