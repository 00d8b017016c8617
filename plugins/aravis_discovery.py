"""Aravis itself for the ``aravis`` camera backend: importing it, choosing its interfaces, finding devices.

Install
-------
Aravis and its GObject introspection data from the system, PyGObject from pip::

    apt-get install gir1.2-aravis-0.8                # Debian/Ubuntu; aravis-tools has the fake GigE camera
    apt-get install libgirepository1.0-dev libcairo2-dev pkg-config gcc python3-dev   # to build PyGObject
    pip install "rsocl[aravis]"                      # PyGObject<3.51 (built from source: no wheels)

``gi`` is imported when a camera is opened, or made with ``interfaces`` (to check their names against
this Aravis': :func:`aravis_interfaces`), so listing plugins never needs it.

Discovery
---------
Opening a camera makes Aravis discover devices on every enabled interface: the GigE
Vision interface *broadcasts* discovery packets on every network interface of the host.
``interfaces`` restricts that (Aravis' interface switches are process-wide: cameras of
one process should agree). :func:`discover` lists the devices Aravis sees.
"""

from __future__ import annotations

from rsocl.hardware.backend import CameraError

__all__ = ["INSTALL_HINT", "import_aravis", "aravis_interfaces", "check_interfaces", "select_interfaces", "discover"]

INSTALL_HINT = (
    "install Aravis' introspection data with 'apt-get install gir1.2-aravis-0.8' and PyGObject with "
    "'pip install \"rsocl[aravis]\"' (PyGObject<3.51, built from source: it needs "
    "'apt-get install libgirepository1.0-dev libcairo2-dev pkg-config gcc python3-dev')"
)


def import_aravis():
    """``(Aravis, GLib)`` from ``gi.repository``; :class:`CameraError` saying what to install when missing."""
    try:
        import gi
    except ImportError as exc:
        raise CameraError(f"the aravis camera backend needs PyGObject (module 'gi'): {INSTALL_HINT}") from exc
    try:
        gi.require_version("Aravis", "0.8")
        from gi.repository import Aravis, GLib
    except (ImportError, ValueError) as exc:
        raise CameraError(
            f"the aravis camera backend needs Aravis 0.8 for GObject introspection ({exc}): {INSTALL_HINT}"
        ) from exc
    return Aravis, GLib


def aravis_interfaces():
    """The interface ids of the Aravis installed (``["Fake", "USB3Vision", "GigEVision"]``), or None where Aravis
    does not import (opening a camera then says what to install). Asks no device: nothing is discovered."""
    try:
        Aravis, _ = import_aravis()
    except CameraError:
        return None
    return [Aravis.get_interface_id(i) for i in range(Aravis.get_n_interfaces())]


def select_interfaces(Aravis, interfaces, who="aravis"):
    """Enable exactly ``interfaces`` (a list of Aravis interface ids), disable the others."""
    if interfaces is None:
        return
    known = [Aravis.get_interface_id(i) for i in range(Aravis.get_n_interfaces())]
    unknown = sorted(set(interfaces) - set(known))
    if unknown:
        raise CameraError(f"{who}: unknown Aravis interface(s) {unknown}; this Aravis has {known}")
    for name in known:
        if name in interfaces:
            Aravis.enable_interface(name)
        else:
            Aravis.disable_interface(name)


def discover(interfaces=None) -> list:
    """Devices Aravis finds: ``[{"id", "address", "protocol", "serial", "vendor", "model", "physical_id"}]``.

    This runs Aravis' discovery: on the GigE Vision interface that is a **broadcast on every
    network interface of the host**. ``interfaces`` (e.g. ``["Fake"]``) enables only those
    Aravis interfaces first (process-wide).
    """
    Aravis, _ = import_aravis()
    select_interfaces(Aravis, check_interfaces("interfaces", interfaces))
    Aravis.update_device_list()
    out = []
    for i in range(Aravis.get_n_devices()):
        out.append(
            {
                "id": Aravis.get_device_id(i),
                "address": Aravis.get_device_address(i),
                "protocol": Aravis.get_device_protocol(i),
                "serial": Aravis.get_device_serial_nbr(i),
                "vendor": Aravis.get_device_vendor(i),
                "model": Aravis.get_device_model(i),
                "physical_id": Aravis.get_device_physical_id(i),
            }
        )
    return out


def check_interfaces(key, value, known=None):
    """``value`` as a list of Aravis interface names (None stays None); a ValueError naming ``key``, and
    ``known`` (the interface ids of this Aravis, :func:`aravis_interfaces`; None: any name) where it names
    another."""
    if value is None:
        return None
    if (
        isinstance(value, str)
        or not isinstance(value, (list, tuple))
        or not value
        or not all(isinstance(v, str) and v for v in value)
    ):
        raise ValueError(
            f"{key} must be a non-empty list of Aravis interface names such as ['GigEVision'], got {value!r}"
        )
    unknown = [v for v in value if known is not None and v not in known]
    if unknown:
        missing = ", ".join(repr(v) for v in unknown)
        raise ValueError(
            f"{key} must list interfaces this Aravis has, any of {known}; got {list(value)!r} (no {missing})"
        )
    return list(value)
