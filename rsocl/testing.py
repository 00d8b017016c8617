"""Checks for operator and plugin authors, to call from their own tests.

- :func:`dottest`: the dot test ``<A x, y> = <x, Aᵀ y>`` of a linear operator and its adjoint.
- :func:`check_regularizer`: the regularizer contract of a plugin.
- :func:`no_host_transfers`: a block inside which reading device data back to the host fails.

Example, in a plugin's test suite::

    from rsocl.testing import check_regularizer
    from my_package import MyRegularizer

    def test_conforms():
        check_regularizer(MyRegularizer)

Every failed property raises an ``AssertionError`` that says which one.
"""

from __future__ import annotations

import contextlib
import numbers

import numpy as np

from rsocl.common import validation as check
from rsocl.common.registry import PluginError
from rsocl.device.context import get_device
from rsocl.solver.regularizer import Option, Regularizer

__all__ = ["check_regularizer", "dottest", "no_host_transfers"]

#: :func:`dottest`'s relative tolerance by the dtype the operator computes in.
DOTTEST_RTOL = {"float32": 1e-4, "float64": 1e-10}


def _shape(name: str, shape) -> tuple:
    try:
        shape = tuple(int(s) for s in shape)
    except TypeError:
        shape = ()
    if not shape or min(shape) < 1:
        raise ValueError(f"{name} must be a tuple of sizes >= 1, got {shape!r}")
    return shape


def dottest(op, domain_shape=None, range_shape=None, *, rtol=None, seed=0, raiseerror=True) -> bool:
    """Dot test of a linear operator: ``<A x, y> = <x, Aᵀ y>`` for random ``x`` and ``y``.

    The check every operator author runs first: an adjoint that is not the transpose of the
    forward map makes an iterative solver converge to the wrong answer or diverge.

    Parameters
    ----------
    op : object
        The operator: ``op.forward(x)`` computes ``A x`` and ``op.adjoint(y)`` computes ``Aᵀ y``,
        on NumPy arrays (a :class:`~rsocl.model.operator.RollingShutterOperator`, or your own).
    domain_shape, range_shape : tuple of int, optional
        Shapes of ``x`` and ``y``; default ``op.domain_shape`` and ``op.range_shape``.
    rtol : float, optional
        Relative tolerance on ``|<A x, y> - <x, Aᵀ y>|`` (> 0). Default by the dtype that
        ``op.forward`` returns: ``1e-4`` for float32, ``1e-10`` otherwise (:data:`DOTTEST_RTOL`).
    seed : int
        Seed of the random ``x`` and ``y`` (standard normal: zero mean, as PyLops' ``dottest``, so
        an adjoint wrong at a few entries changes ``<x, Aᵀ y>`` beyond ``rtol``).
    raiseerror : bool
        Raise ``AssertionError`` when the test fails (default); else return False.

    Returns
    -------
    bool
        True when ``|<A x, y> - <x, Aᵀ y>| <= rtol * max(|<A x, y>|, |<x, Aᵀ y>|)``.

    Raises
    ------
    ValueError
        If ``op`` lacks ``forward``/``adjoint``, a shape is missing or not sizes >= 1, or ``rtol``
        is not > 0.
    AssertionError
        If the test fails and ``raiseerror`` is True, or ``A x`` / ``Aᵀ y`` has the wrong shape.

    Examples
    --------
    >>> import numpy as np
    >>> from rsocl.testing import dottest
    >>> class Scale:                       # A = diag(d): its own transpose
    ...     domain_shape = range_shape = (3, 4)
    ...     d = np.arange(12.0).reshape(3, 4)
    ...     def forward(self, x): return self.d * x
    ...     def adjoint(self, y): return self.d * y
    >>> dottest(Scale())
    True
    >>> class Wrong(Scale):
    ...     def adjoint(self, y): return 2 * self.d * y
    >>> dottest(Wrong(), raiseerror=False)
    False
    """
    if not (callable(getattr(op, "forward", None)) and callable(getattr(op, "adjoint", None))):
        raise ValueError(f"op must have forward(x) and adjoint(y) methods, got {type(op).__name__}")
    domain = _shape("domain_shape", domain_shape if domain_shape is not None else getattr(op, "domain_shape", None))
    image = _shape("range_shape", range_shape if range_shape is not None else getattr(op, "range_shape", None))
    if rtol is not None:
        rtol = check.positive("rtol", rtol)
    rng = np.random.default_rng(seed)
    x, y = rng.standard_normal(domain), rng.standard_normal(image)
    dtype = getattr(op, "dtype", None)
    if dtype is not None:  # the operator's own precision on both sides
        x, y = x.astype(dtype), y.astype(dtype)
    ax, aty = np.asarray(op.forward(x)), np.asarray(op.adjoint(y))
    assert ax.shape == image, f"op.forward(x) has shape {ax.shape}, expected range_shape {image}"
    assert aty.shape == domain, f"op.adjoint(y) has shape {aty.shape}, expected domain_shape {domain}"
    if rtol is None:
        rtol = DOTTEST_RTOL.get(np.result_type(ax, aty).name, DOTTEST_RTOL["float64"])
    lhs = float(np.vdot(ax.astype(np.float64), y.astype(np.float64)))
    rhs = float(np.vdot(x.astype(np.float64), aty.astype(np.float64)))
    passed = abs(lhs - rhs) <= rtol * max(abs(lhs), abs(rhs))
    if not passed and raiseerror:
        raise AssertionError(
            f"dot test failed: <A x, y> = {lhs:.10g}, <x, Aᵀ y> = {rhs:.10g}, relative "
            f"difference {abs(lhs - rhs) / max(abs(lhs), abs(rhs), 1e-300):.3g} > rtol = {rtol:g}"
        )
    return passed


#: pyopencl's functions through which every ``enqueue_copy`` to host memory goes (looked up on
#: ``pyopencl._cl`` when ``enqueue_copy`` runs, so a reference to ``enqueue_copy`` bound before the
#: check is caught too)
_READS = ("_enqueue_read_buffer", "_enqueue_read_buffer_rect", "_enqueue_read_image")
#: the functions that map device memory into host memory, patched in ``pyopencl`` and ``pyopencl._cl``
_MAPS = ("enqueue_map_buffer", "enqueue_map_image")


@contextlib.contextmanager
def no_host_transfers():
    """Inside this block, reading device data back to the host raises ``AssertionError``.

    Catches ``pyopencl.array.Array.get``, every ``pyopencl.enqueue_copy`` into host memory
    (however ``enqueue_copy`` was imported: the read functions of ``pyopencl._cl`` it calls are
    patched) and ``enqueue_map_buffer`` / ``enqueue_map_image`` called through ``pyopencl`` or
    ``pyopencl._cl`` (and so ``Array.map_to_host``): the ways a regularizer could round-trip through
    the host. Not caught: a reference to a map function bound before the block, and copies
    between shared virtual memory allocations.
    """
    import pyopencl as cl
    import pyopencl._cl as _cl
    import pyopencl.array as cla

    def get(self, *args, **kwargs):
        raise AssertionError("the regularizer read a device array back to the host (Array.get)")

    def refuse(what):
        def refused(*args, **kwargs):
            raise AssertionError(f"the regularizer copied device data to the host ({what})")

        return refused

    patches = [(cla.Array, "get", get)]
    patches += [(_cl, name, refuse("enqueue_copy")) for name in _READS if hasattr(_cl, name)]
    patches += [(module, name, refuse(name)) for module in (cl, _cl) for name in _MAPS if hasattr(module, name)]
    originals = [(owner, name, owner.__dict__[name]) for owner, name, _ in patches]
    try:
        for owner, name, replacement in patches:
            setattr(owner, name, replacement)
        yield
    finally:
        for owner, name, original in originals:
            setattr(owner, name, original)


def _instance(regularizer, options):
    cls = regularizer if isinstance(regularizer, type) else type(regularizer)
    if not issubclass(cls, Regularizer):
        raise AssertionError(f"{regularizer!r} is not an rsocl.solver.regularizer.Regularizer subclass or instance")
    for key, opt in cls.options.items():  # the declarations first: building an instance reads them
        assert isinstance(opt, Option), f"option {key!r} must be declared as rsocl.solver.regularizer.Option"
        assert isinstance(opt.default, (bool, np.bool_, numbers.Real, str)), (
            f"option {key!r}: the default must be a bool, int, float or str, got {opt.default!r}"
        )
    try:
        cls.check_options()
    except ValueError as exc:
        raise AssertionError(str(exc)) from exc
    assert cls._denoise is not Regularizer._denoise, f"{cls.__qualname__} must implement _denoise(x, weight, out)"
    return regularizer if isinstance(regularizer, Regularizer) else regularizer(**(options or {}))


def _batch(reg, dev, dtype, shape, weights, tol, rng):
    """A batch of two sets with their own weights equals each set denoised alone (the contract's "as if
    alone"), for a ``batched`` regularizer as for the set-by-set path."""
    import pyopencl.array as cla

    low, high = min(weights[-1], 0.05), max(weights[-1], 0.5)
    sets = rng.random((2, *shape)).astype(dtype)
    with no_host_transfers():
        both = reg.denoise(cla.to_device(dev.queue, sets), [high, low])
    assert both.shape == sets.shape, f"{dtype}: a batch's output has shape {both.shape}, not {sets.shape}"
    both_host = both.get()
    for i, w in enumerate((high, low)):
        alone = reg.denoise(cla.to_device(dev.queue, sets[i]), w).get()
        np.testing.assert_allclose(
            both_host[i],
            alone,
            rtol=0,
            atol=tol * max(1.0, np.abs(alone).max()),
            err_msg=f"{dtype}: set {i} of a batch (weights {[high, low]}) differs from that set denoised alone",
        )


def _weights(weights) -> tuple:
    """``weights`` as a tuple of floats ``>= 0``, at least one; ValueError naming ``weights``."""
    if isinstance(weights, (str, bytes)) or np.ndim(weights) != 1 or len(weights) == 0:
        raise ValueError(f"weights must be a sequence of at least one denoising weight >= 0, got {weights!r}")
    return tuple(check.non_negative(f"weights[{i}]", w) for i, w in enumerate(weights))


def check_regularizer(
    regularizer, *, options=None, device=None, shape=(5, 12, 10), weights=(0.05, 0.5), pairs=4, seed=0
):
    """Check the regularizer contract on ``device`` in every dtype it and the device support.

    Properties checked: options declared as :class:`~rsocl.solver.regularizer.Option` with a
    default inside a valid range (:meth:`~rsocl.solver.regularizer.Option.check`); ``_denoise``
    implemented; ``name`` set; the output is a device array of the input's shape and dtype
    with finite values; ``_denoise`` raises nothing; the input is not modified; ``out=`` is
    honoured; weight 0 is the identity; each set of a batch ``(2, T, m, n)`` with its own weight
    is denoised as if alone; the map is non-expansive (``‖D(x) - D(y)‖ <= ‖x - y‖``) on random
    pairs; no device-to-host transfer happens inside ``denoise``.

    Parameters
    ----------
    regularizer : Regularizer subclass or instance
        The plugin's class (built with ``options``) or an instance.
    options : dict, optional
        Options for the class, ``{name: value}``.
    device : str, Device or None
        OpenCL device (see :func:`rsocl.get_device`).
    shape : tuple of int
        ``(T, m, n)`` of the random test arrays, voxels.
    weights : sequence of float
        Denoising weights tried, at least one, each ``>= 0``; the last one serves the
        non-expansiveness pairs.
    pairs : int
        Random pairs of the non-expansiveness check.
    seed : int
        Seed of the random arrays.

    Returns
    -------
    list of str
        The dtypes checked (``"float64"`` only where the device has ``cl_khr_fp64``).

    Raises
    ------
    AssertionError
        Naming the first property that fails.
    ValueError
        If ``weights`` is not a sequence of at least one weight ``>= 0``.

    Examples
    --------
    >>> from rsocl.testing import check_regularizer
    >>> from rsocl_plugins.tv import TV
    >>> "float32" in check_regularizer(TV, options={"iterations": 3})
    True
    """
    weights = _weights(weights)
    reg = _instance(regularizer, options)
    assert isinstance(reg.name, str) and reg.name and reg.name != "base", "the regularizer needs a name"
    dev = get_device(device)
    rng = np.random.default_rng(seed)
    checked = []
    for dtype in reg.dtypes:
        if dtype == "float64" and not dev.has_fp64:
            continue
        try:
            _properties(reg, dev, dtype, shape, weights, pairs, rng)
        except PluginError as exc:  # its _denoise raised (Regularizer.denoise names it)
            raise AssertionError(f"{dtype}: {exc}") from exc
        checked.append(dtype)
    assert checked, f"no dtype of {reg.dtypes} is supported on {dev.name}"
    return checked


def _properties(reg, dev, dtype, shape, weights, pairs, rng):
    """:func:`check_regularizer`'s properties of ``reg`` in ``dtype`` on ``dev``."""
    import pyopencl.array as cla

    tol = 1e-5 if dtype == "float32" else 1e-12
    x_host = rng.random(shape).astype(dtype)
    x = cla.to_device(dev.queue, x_host)
    for weight in weights:
        with no_host_transfers():
            out = reg.denoise(x, weight)
        assert isinstance(out, cla.Array), f"{dtype}: denoise must return a pyopencl.array.Array"
        assert out.shape == x.shape, f"{dtype}: shape {out.shape} != input {x.shape}"
        assert out.dtype == x.dtype, f"{dtype}: dtype {out.dtype} != input {x.dtype}"
        values = out.get()
        assert np.all(np.isfinite(values)), f"{dtype}: non-finite output at weight {weight}"
        np.testing.assert_array_equal(x.get(), x_host, err_msg=f"{dtype}: denoise modified its input")
        target = cla.empty_like(x)
        with no_host_transfers():
            returned = reg.denoise(x, weight, out=target)
        assert returned is target, f"{dtype}: denoise(out=...) must write and return out"
        np.testing.assert_allclose(
            target.get(),
            values,
            rtol=0,
            atol=tol * max(1.0, np.abs(values).max()),
            err_msg=f"{dtype}: out= result differs from the allocated one",
        )
    np.testing.assert_array_equal(reg.denoise(x, 0.0).get(), x_host, err_msg=f"{dtype}: weight 0 must be the identity")
    for _ in range(pairs):
        a = rng.random(shape).astype(dtype)
        b = (a + rng.normal(0, 0.2, shape)).astype(dtype)
        da = reg.denoise(cla.to_device(dev.queue, a), weights[-1]).get().astype(np.float64)
        db = reg.denoise(cla.to_device(dev.queue, b), weights[-1]).get().astype(np.float64)
        before = np.linalg.norm(a.astype(np.float64) - b)
        after = np.linalg.norm(da - db)
        assert after <= before * (1 + 100 * tol), (
            f"{dtype}: not non-expansive: ‖D(x)-D(y)‖ = {after:.6g} > ‖x-y‖ = {before:.6g}"
        )
    _batch(reg, dev, dtype, shape, weights, tol, rng)
