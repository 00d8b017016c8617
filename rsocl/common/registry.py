"""Plugin registry: regularizers and camera backends found through entry points.

Groups ``rsocl.regularizers`` and ``rsocl.cameras`` are read with
:mod:`importlib.metadata`. Listing never imports a plugin; a plugin is imported
on first use. rsocl's own plugins are declared in its ``pyproject.toml`` the
same way a third party declares its own, so there is no special path for them.
"""

from __future__ import annotations

import os
import sys
from dataclasses import dataclass
from importlib import metadata

__all__ = ["GROUPS", "BASES", "PluginInfo", "available", "load", "status", "PluginError"]

GROUPS = ("rsocl.regularizers", "rsocl.cameras")


class PluginError(ValueError):
    """A plugin name is unknown, ambiguous, or its module failed to import."""


@dataclass(frozen=True)
class PluginInfo:
    """One entry point: its name, target (``module:attr``), distribution and version."""

    group: str
    name: str
    value: str
    distribution: str
    version: str
    entry_point: metadata.EntryPoint

    def load(self):
        """Import the plugin and check that it is a class of its group's base (:data:`BASES`)."""
        try:
            obj = self.entry_point.load()
        except (Exception, SystemExit) as exc:  # a broken plugin must never break the others
            raise self._broken(exc) from exc
        base = _base(self.group)
        if not (isinstance(obj, type) and issubclass(obj, base)):
            wrong = TypeError(f"{self.value} is {obj!r}, not a subclass of {base.__module__}.{base.__name__}")
            raise self._broken(wrong) from wrong
        return obj

    def _broken(self, exc) -> PluginError:
        return PluginError(
            f"plugin {self.name!r} ({self.group}) from distribution {self.distribution} "
            f"{self.version} failed to load: {type(exc).__name__}: {exc}"
        )


#: The class every plugin of a group must subclass, as ``module:name`` (imported on first use).
BASES = {
    "rsocl.regularizers": "rsocl.solver.regularizer:Regularizer",
    "rsocl.cameras": "rsocl.hardware.backend:CameraBackend",
}


def _base(group: str) -> type:
    import importlib

    module, name = BASES[group].split(":")
    return getattr(importlib.import_module(module), name)


def _claimed(group: str, name: str, by_dist: dict) -> str:
    dists = " and ".join(f"{d} {i.version}" for d, i in sorted(by_dist.items()))
    return f"plugin name {name!r} in group {group} is claimed by two distributions: {dists}; uninstall one of them"


def _check_group(group):
    if group not in GROUPS:
        raise ValueError(f"group must be one of {list(GROUPS)}, got {group!r}")


#: ``{group: (fingerprint, entries)}``: the last :func:`_entries` of each group and the :func:`_fingerprint`
#: it was read under.
_READ: dict = {}


def _fingerprint() -> tuple:
    """Each ``sys.path`` folder with its modification time (ns): installing or removing a distribution
    changes its folder's time, as adding a folder to ``sys.path`` changes the tuple."""
    stamps: list[tuple[str, int | None]] = []
    for entry in sys.path:
        try:
            stamps.append((entry, os.stat(entry or ".").st_mtime_ns))
        except OSError:
            stamps.append((entry, None))
    return tuple(stamps)


def _entries(group):
    """``{name: {distribution: PluginInfo}}`` of ``group``.

    Every ``reconstruct`` call (and every candidate of its search) looks a regularizer up, and reading
    every distribution's entry points takes milliseconds (``docs/implementation_notes.md``). So a
    group's entries are read again only when :func:`_fingerprint` changed since the last read, and then
    only the distributions that declare an entry point of ``group`` have their metadata parsed.
    """
    stamp = _fingerprint()
    last = _READ.get(group)
    if last is not None and last[0] == stamp:
        return last[1]
    found = {}
    for dist in metadata.distributions():
        mine = [ep for ep in dist.entry_points if ep.group == group]
        if not mine:
            continue
        dist_name, version = dist.metadata["Name"] or "?", dist.version or "?"
        for ep in mine:
            found.setdefault(ep.name, {})[dist_name] = PluginInfo(group, ep.name, ep.value, dist_name, version, ep)
    _READ[group] = (stamp, found)
    return found


def available(group: str = "rsocl.regularizers") -> dict:
    """Plugin names of ``group`` -> :class:`PluginInfo`, without importing any plugin.

    A name two distributions claim is left out (:func:`load` of it raises, naming both; the other
    names stay usable).
    """
    _check_group(group)
    return _unclaimed(_entries(group))


def _unclaimed(entries: dict) -> dict:
    """``{name: PluginInfo}`` of the names in ``entries`` (:func:`_entries`) one distribution claims."""
    return {name: next(iter(by_dist.values())) for name, by_dist in sorted(entries.items()) if len(by_dist) == 1}


def load(group: str, name: str):
    """Import and return the class registered as ``name`` in ``group``; a :class:`PluginError` when
    the name is unknown, claimed by two distributions, fails to import or is not a class of the
    group's base (:data:`BASES`)."""
    _check_group(group)
    entries = _entries(group)
    if len(entries.get(name, {})) > 1:
        raise PluginError(_claimed(group, name, entries[name]))
    plugins = _unclaimed(entries)
    if name not in plugins:
        raise PluginError(f"unknown {group.split('.')[-1][:-1]} {name!r}; available: {sorted(plugins) or 'none'}")
    return plugins[name].load()


def status(group: str):
    """``[(PluginInfo or None, name, "ok" | "broken: cause" | "missing dependency: cause")]`` for every
    plugin, importing each (and, for a class with ``check_dependencies()``, what it needs).

    Name collisions are reported as broken rows instead of raising.
    """
    _check_group(group)
    rows = []
    for name, by_dist in sorted(_entries(group).items()):
        if len(by_dist) > 1:
            dists = " and ".join(sorted(by_dist))
            for info in by_dist.values():
                rows.append((info, name, f"broken: name claimed by {dists}"))
            continue
        info = next(iter(by_dist.values()))
        try:
            cls = info.load()
        except PluginError as exc:
            cause = exc.__cause__
            rows.append((info, name, f"broken: {type(cause).__name__}: {cause}"))
            continue
        rows.append((info, name, _dependencies(cls)))
    return rows


def _dependencies(cls) -> str:
    """``"ok"``, or ``"missing dependency: cause"`` when the plugin's ``check_dependencies()``
    (a camera backend's: the library it opens cameras with) raises."""
    check = getattr(cls, "check_dependencies", None)
    if not callable(check):
        return "ok"
    try:
        check()
    except Exception as exc:  # noqa: BLE001 - any failure to import a dependency is reported, not raised
        return f"missing dependency: {exc}"
    return "ok"
