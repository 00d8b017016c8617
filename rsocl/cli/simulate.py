"""``rsocl simulate``: a scene (built-in or a video file) through a rig -> a capture file (HDF5)."""

from __future__ import annotations

from rsocl.cli.options import add_device_args, add_rig_args, check_datacube_memory, rig_from, say

__all__ = ["add_parser", "cmd_simulate"]


def add_parser(subparsers):
    """Add ``simulate`` to the ``rsocl`` sub-parsers; returns its parser."""
    p = subparsers.add_parser("simulate", help="scene file -> capture file (HDF5)")
    p.add_argument("scene", help="'builtin' or a video: .npz (key 'video'), multi-page .tif, .gif")
    p.add_argument("--out", required=True, help="capture file to write (.h5)")
    add_rig_args(p)
    p.add_argument("--noise", choices=["none", "gaussian", "poisson"], default="none")
    p.add_argument("--sigma", type=float, default=0.0, help="gaussian noise, fraction of full scale")
    p.add_argument("--photons", type=float, default=None, help="photo-electrons at full scale (poisson)")
    p.add_argument("--bit-depth", type=int, default=None, help="quantise to this many bits")
    p.add_argument("--seed", type=int, default=0)
    add_device_args(p)
    p.set_defaults(func=cmd_simulate)
    return p


def cmd_simulate(args) -> int:
    """Simulate the snapshots of ``args.scene`` and write them, the rig and the truth to ``--out``; returns 0."""
    from rsocl.files.atomic import output_path
    from rsocl.files.hdf5 import save_capture
    from rsocl.model.scenes import load_scene
    from rsocl.model.simulate import simulate

    output_path(args.out, "--out", inputs=(("scene", None if args.scene == "builtin" else args.scene),))
    rig = rig_from(args)
    check_datacube_memory(rig)
    truth = load_scene(args.scene, rig.shape, rig.T)
    g = simulate(truth, rig, noise=args.noise, sigma=args.sigma, photons=args.photons, bit_depth=args.bit_depth,
                 seed=args.seed, device=args.device)
    meta = {"scene": str(args.scene), "noise": args.noise, "sigma": args.sigma, "photons": args.photons,
            "bit_depth": args.bit_depth, "seed": args.seed}
    path = save_capture(args.out, g, rig, truth=truth, attrs=meta)
    say(args, f"wrote {path}: {rig.n_channels} snapshots of {rig.shape[0]}x{rig.shape[1]}, T = {rig.T}")
    return 0
