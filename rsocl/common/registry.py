"""Plugin registry: regularizers and camera backends found through entry points.

Groups ``rsocl.regularizers`` and ``rsocl.cameras`` are read with
:mod:`importlib.metadata`. Listing never imports a plugin; a plugin is imported
on first use. rsocl's own plugins are declared in its ``pyproject.toml`` the
same way a third party declares its own. One rule tells them apart: a name that rsocl and another
distribution both declare is rsocl's (with a warning naming the other distribution).
"""

from __future__ import annotations

import os
import re
import sys
import warnings
from dataclasses import dataclass
from importlib import metadata

__all__ = ["GROUPS", "BASES", "REQUIRED", "PluginInfo", "available", "load", "status", "origin", "PluginError"]

GROUPS = ("rsocl.regularizers", "rsocl.cameras")


class PluginError(ValueError):
    """A plugin name is unknown or ambiguous, its module failed to import, its class breaks its group's
    contract, or the plugin failed where it ran (the message names it and its distribution)."""


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
        """Import the plugin and check its class: a subclass of its group's base (:data:`BASES`) that
        implements the hooks :data:`REQUIRED` names, and whose declared options (a class with
        ``check_options()``, as a regularizer) are valid."""
        try:
            obj = self.entry_point.load()
        except (Exception, SystemExit) as exc:  # a broken plugin must never break the others
            raise self._broken(exc) from exc
        base = _base(self.group)
        if not (isinstance(obj, type) and issubclass(obj, base)):
            wrong = TypeError(f"{self.value} is {obj!r}, not a subclass of {base.__module__}.{base.__name__}")
            raise self._broken(wrong) from wrong
        missing = [hook for hook in REQUIRED[self.group] if getattr(obj, hook, None) is getattr(base, hook)]
        if missing:
            wrong = TypeError(f"{self.value} does not implement {', '.join(missing)} (every {base.__name__} must)")
            raise self._broken(wrong) from wrong
        declared = getattr(obj, "check_options", None)
        try:
            if callable(declared):
                declared()
        except ValueError as exc:
            raise self._broken(exc) from exc
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


#: The hooks a plugin class of each group must implement itself (its base's only raise NotImplementedError).
REQUIRED = {
    "rsocl.regularizers": ("_denoise",),
    "rsocl.cameras": (
        "_open_device",
        "_close_device",
        "_set_exposure",
        "_set_roi",
        "_set_pixel_format",
        "_set_trigger",
        "_start",
        "_stop",
        "_trigger",
        "_read",
    ),
}

#: The distribution whose plugins are rsocl's built-ins: a name it declares is its own, whoever else does.
BUILTIN = "rsocl"


def _base(group: str) -> type:
    import importlib

    module, name = BASES[group].split(":")
    return getattr(importlib.import_module(module), name)


def _claimed(group: str, name: str, by_dist: dict) -> str:
    dists = " and ".join(f"{d} {i.version}" for d, i in sorted(by_dist.items()))
    return (
        f"plugin name {name!r} in group {group} is claimed by two distributions: {dists}; uninstall one of "
        "them or have one rename its entry point"
    )


def _normal(distribution: str) -> str:
    """A distribution name as packaging compares them (case, and runs of ``-_.``, ignored)."""
    return re.sub(r"[-_.]+", "-", distribution).lower()


def _winner(by_dist: dict):
    """The :class:`PluginInfo` a name stands for (``by_dist``: its claimants by distribution): the only one,
    else rsocl's built-in; None when two distributions other than rsocl claim it."""
    if len(by_dist) == 1:
        return next(iter(by_dist.values()))
    return next((info for d, info in by_dist.items() if _normal(d) == BUILTIN), None)


def _shadowed(group: str, name: str, info) -> str:
    """Why ``info``'s entry point for ``name`` is ignored: rsocl's built-in of that name is used instead."""
    return (
        f"distribution {info.distribution} {info.version} declares {name!r} in {group}, the name of rsocl's "
        f"built-in; rsocl's built-in is used and {info.distribution}'s {info.value} is ignored (it needs an "
        "entry point of another name)"
    )


def _check_group(group):
    if group not in GROUPS:
        raise ValueError(f"group must be one of {list(GROUPS)}, got {group!r}")


#: ``{group: (fingerprint, entries, unreadable)}``: the last :func:`_entries` of each group, the
#: distributions whose entry points could not be read then (:func:`_unreadable`), and the
#: :func:`_fingerprint` it was read under.
_READ: dict = {}
#: The warnings already given (an unreadable distribution, a built-in's name claimed), each once per process.
_WARNED: set = set()


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
    return _read(group)[0]


def _read(group) -> tuple[dict, list]:
    """``(entries, unreadable)``: :func:`_entries` and the distributions whose entry points cannot be
    read (:func:`_unreadable`), each warned about once (a malformed ``entry_points.txt`` of any
    distribution, whatever its groups, must not stop rsocl)."""
    stamp = _fingerprint()
    last = _READ.get(group)
    if last is not None and last[0] == stamp:
        return last[1], last[2]
    found: dict = {}
    unreadable = []
    for dist in metadata.distributions():
        try:
            mine = [ep for ep in dist.entry_points if ep.group == group]
            if not mine:
                continue
            dist_name, version = dist.metadata["Name"] or "?", dist.version or "?"
        except Exception as exc:  # noqa: BLE001 - whatever the parse raises, that distribution alone is skipped
            unreadable.append(_unreadable(dist, exc))
            continue
        for ep in mine:
            found.setdefault(ep.name, {})[dist_name] = PluginInfo(group, ep.name, ep.value, dist_name, version, ep)
    for why in unreadable:
        if why not in _WARNED:
            _WARNED.add(why)
            warnings.warn(f"{why}; rsocl ignores its plugins", UserWarning, stacklevel=2)
    _READ[group] = (stamp, found, unreadable)
    return found, unreadable


def _unreadable(dist, exc) -> str:
    """What is wrong with ``dist``'s entry points: its name (or folder) and ``exc``, on one line."""
    folder = getattr(dist, "_path", None)  # a PathDistribution's .dist-info / .egg-info folder
    try:
        name = f"distribution {dist.metadata['Name'] or '?'} {dist.version or '?'}"
    except Exception:  # noqa: BLE001 - its metadata may be as broken as its entry points
        name = "a distribution"
    where = f" ({folder}/entry_points.txt)" if folder is not None else ""
    cause = " ".join(f"{type(exc).__name__}: {exc}".split())
    return f"{name}: its entry points{where} cannot be read: {cause}"


def available(group: str = "rsocl.regularizers") -> dict:
    """Plugin names of ``group`` -> :class:`PluginInfo`, without importing any plugin.

    A name that rsocl and another distribution declare is rsocl's built-in. A name two other
    distributions claim is left out (:func:`load` of it raises, naming both; the other names stay
    usable). A distribution whose entry points cannot be read is skipped with a warning naming it.
    """
    _check_group(group)
    return _unclaimed(_entries(group))


def _unclaimed(entries: dict) -> dict:
    """``{name: PluginInfo}`` of the names in ``entries`` (:func:`_entries`) that stand for one plugin."""
    found = {name: _winner(by_dist) for name, by_dist in sorted(entries.items())}
    return {name: info for name, info in found.items() if info is not None}


def load(group: str, name: str):
    """Import and return the class registered as ``name`` in ``group``; a :class:`PluginError` when
    the name is unknown, claimed by two distributions other than rsocl, fails to import or breaks its
    group's contract (:meth:`PluginInfo.load`). A name that rsocl and another distribution declare
    gives rsocl's built-in, with a warning naming the other distribution."""
    _check_group(group)
    entries = _entries(group)
    claimants = entries.get(name, {})
    if len(claimants) > 1:
        chosen = _winner(claimants)
        if chosen is None:
            raise PluginError(_claimed(group, name, claimants))
        for info in claimants.values():
            why = _shadowed(group, name, info)
            if info is not chosen and why not in _WARNED:
                _WARNED.add(why)
                warnings.warn(why, UserWarning, stacklevel=2)
    plugins = _unclaimed(entries)
    if name not in plugins:
        raise PluginError(f"unknown {group.split('.')[-1][:-1]} {name!r}; available: {sorted(plugins) or 'none'}")
    return plugins[name].load()


def status(group: str):
    """``[(PluginInfo or None, name, state)]`` for every plugin, importing each (and, for a class with
    ``check_dependencies()``, what it needs); ``state`` is ``"ok"``, ``"broken: cause"``,
    ``"missing dependency: cause"`` or ``"ignored: cause"``.

    Name collisions are reported as broken rows instead of raising; another distribution's entry point
    of a built-in's name is ``ignored``. A distribution whose entry points cannot be read is a row
    ``(None, "?", "broken: ...")`` naming it.
    """
    _check_group(group)
    entries, unreadable = _read(group)
    rows: list = [(None, "?", f"broken: {why}") for why in unreadable]
    for name, by_dist in sorted(entries.items()):
        info = _winner(by_dist)
        if info is None:
            dists = " and ".join(sorted(by_dist))
            for claimant in by_dist.values():
                rows.append((claimant, name, f"broken: name claimed by {dists}"))
            continue
        rows += [
            (other, name, f"ignored: {_shadowed(group, name, other)}")
            for other in by_dist.values()
            if other is not info
        ]
        try:
            cls = info.load()
        except PluginError as exc:
            cause = exc.__cause__
            rows.append((info, name, f"broken: {type(cause).__name__}: {cause}"))
            continue
        rows.append((info, name, _dependencies(cls)))
    return rows


def origin(group: str, cls: type) -> str:
    """``"distribution version"`` of the entry point of ``group`` whose target is ``cls``; ``""`` when none
    is (a class used without the registry)."""
    _check_group(group)
    target = f"{cls.__module__}:{cls.__qualname__}"
    for by_dist in _entries(group).values():
        for info in by_dist.values():
            if info.value.replace(" ", "") == target:
                return f"{info.distribution} {info.version}"
    return ""


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
