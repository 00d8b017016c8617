"""``rsocl plugins``: the regularizer and camera plugins found through entry points, and their status."""

from __future__ import annotations

__all__ = ["add_parser", "cmd_plugins"]


def add_parser(subparsers):
    """Add ``plugins`` to the ``rsocl`` sub-parsers; returns its parser."""
    p = subparsers.add_parser("plugins", help="list regularizer and camera plugins and their status")
    p.set_defaults(func=cmd_plugins)
    return p


def cmd_plugins(args) -> int:
    """Print each entry-point group with its plugins (name, distribution, version, target, status); returns 0.

    A distribution whose entry points cannot be read is a ``?`` row that names it."""
    from rsocl.common.registry import GROUPS, status

    for group in GROUPS:
        print(group)
        rows = status(group)
        if not rows:
            print("  (none)")
        for info, name, state in rows:
            if info is None:
                print(f"  {name:<12} {state}")
            else:
                print(f"  {name:<12} {info.distribution} {info.version:<10} {info.value:<42} {state}")
    return 0
