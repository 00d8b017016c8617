"""``rsocl devices``: the OpenCL platforms and devices, and which one is the default."""

from __future__ import annotations

__all__ = ["add_parser", "cmd_devices"]


def add_parser(subparsers):
    """Add ``devices`` to the ``rsocl`` sub-parsers; returns its parser."""
    p = subparsers.add_parser("devices", help="list OpenCL platforms and devices")
    p.set_defaults(func=cmd_devices)
    return p


def cmd_devices(args) -> int:
    """Print one line per device (``*`` marks the default); returns 1 when there is none."""
    from rsocl.device.context import INSTALL_HINT, get_device, list_devices

    found = list_devices()
    if not found:
        print(f"no OpenCL device found; {INSTALL_HINT}")
        return 1
    import pyopencl as cl

    try:
        default, why = get_device(None).device, None
    except ValueError as exc:  # RSOCL_DEVICE or PYOPENCL_CTX names none of them: the list still helps choose
        default, why = None, str(exc)
    for pi, di, platform, dev in found:
        mark = "*" if dev == default else " "
        fp64 = "fp64" if "cl_khr_fp64" in dev.extensions else "no fp64"
        # the ignore: pyopencl's stub declares device_type.to_string in an IntEnum body, so it types as a member
        print(
            f"{mark} {pi}:{di}  {platform.name.strip()} / {dev.name.strip()}  "
            f"[{cl.device_type.to_string(dev.type)}, {dev.max_compute_units} units, "  # type: ignore[operator]
            f"{dev.global_mem_size / 2**30:.1f} GiB, max buffer {dev.max_mem_alloc_size / 2**30:.1f} GiB, {fp64}]"
        )
    if why is not None:
        raise ValueError(why)
    print("* = default choice")
    return 0
