"""``rsocl simulate``: a scene (built-in or a video file) through a rig -> a capture file (HDF5)."""

from __future__ import annotations

from rsocl.cli.options import add_device_args, add_rig_args, check_datacube_memory, rig_from, say

__all__ = ["add_parser", "check_noise_args", "cmd_simulate"]


def add_parser(subparsers):
    """Add ``simulate`` to the ``rsocl`` sub-parsers; returns its parser."""
    p = subparsers.add_parser("simulate", help="scene file -> capture file (HDF5)")
    p.add_argument("scene", help="'builtin' or a video: .npz (key 'video'), multi-page .tif, .gif")
    p.add_argument("--out", required=True, help="capture file to write (.h5)")
    add_rig_args(p)
    p.add_argument("--noise", choices=["none", "gaussian", "poisson"], default="none",
                   help="noise model (default none); gaussian needs --sigma, poisson --photons")
    p.add_argument("--sigma", type=float, default=None,
                   help="gaussian noise standard deviation, fraction of full scale, >= 0 (no default)")
    p.add_argument("--photons", type=float, default=None,
                   help="photo-electrons at full scale, > 0 and <= 1e18 (poisson noise; no default)")
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

    needs = {"gaussian": ("--sigma", args.sigma, "the standard deviation as a fraction of full scale, >= 0"),
             "poisson": ("--photons", args.photons, "photo-electrons at full scale, > 0")}
    for model, (option, value, meaning) in needs.items():
        if args.noise == model and value is None:
            raise ValueError(f"--noise {model} needs {option} ({meaning}); it has no default")
        if args.noise != model and value is not None:
            raise ValueError(f"{option} applies to --noise {model} only; with --noise {args.noise} it would be "
                             "ignored")
    if args.sigma is not None:
        check.non_negative("--sigma", args.sigma, "(fraction of full scale)")
    if args.photons is not None:
        check_photons("--photons", args.photons)
    if args.bit_depth is not None:
        check.positive_int("--bit-depth", args.bit_depth, maximum=32)
    check_seed("--seed", args.seed)


def cmd_simulate(args) -> int:
    """Simulate the snapshots of ``args.scene`` and write them, the rig and the truth to ``--out``; returns 0."""
    from rsocl.files.atomic import output_path
    from rsocl.files.hdf5 import save_capture
    from rsocl.model.scenes import load_scene
    from rsocl.model.simulate import simulate

    check_noise_args(args)
    output_path(args.out, "--out", inputs=(("scene", None if args.scene == "builtin" else args.scene),))
    rig = rig_from(args)
    check_datacube_memory(rig)
    truth = load_scene(args.scene, rig.shape, rig.T)
    g = simulate(truth, rig, noise=args.noise, sigma=args.sigma or 0.0, photons=args.photons,
                 bit_depth=args.bit_depth, seed=args.seed, device=args.device)
    meta = {"scene": str(args.scene), "noise": args.noise, "sigma": args.sigma, "photons": args.photons,
            "bit_depth": args.bit_depth, "seed": args.seed}
    path = save_capture(args.out, g, rig, truth=truth, attrs=meta)
    say(args, f"wrote {path}: {rig.n_channels} snapshots of {rig.shape[0]}x{rig.shape[1]}, T = {rig.T}")
    return 0
