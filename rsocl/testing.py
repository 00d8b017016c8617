"""Conformance checks for third-party plugins, to call from their own tests.

Example, in a plugin's test suite::

    from rsocl.testing import check_regularizer
    from my_package import MyRegularizer

    def test_conforms():
        check_regularizer(MyRegularizer)

Every failed property raises an ``AssertionError`` that says which one.
"""

from __future__ import annotations

import contextlib

import numpy as np

from rsocl.common import validation as check
from rsocl.device.context import get_device
from rsocl.solver.regularizer import Option, Regularizer

__all__ = ["check_regularizer", "no_host_transfers"]


@contextlib.contextmanager
def no_host_transfers():
    """Inside this block, reading a device array back to the host raises ``AssertionError``.

    Catches ``pyopencl.array.Array.get`` and ``pyopencl.enqueue_copy`` into a
    NumPy array: the ways a regularizer could round-trip through the host.
    """
    import pyopencl as cl
    import pyopencl.array as cla

    original_get, original_copy = cla.Array.get, cl.enqueue_copy

    def get(self, *args, **kwargs):
        raise AssertionError("the regularizer read a device array back to the host (Array.get)")

    def enqueue_copy(queue, dest, src, *args, **kwargs):
        if isinstance(dest, np.ndarray):
            raise AssertionError("the regularizer copied device data to the host (enqueue_copy)")
        return original_copy(queue, dest, src, *args, **kwargs)

    cla.Array.get, cl.enqueue_copy = get, enqueue_copy
    try:
        yield
    finally:
        cla.Array.get, cl.enqueue_copy = original_get, original_copy


def _instance(regularizer, options):
    if isinstance(regularizer, Regularizer):
        return regularizer
    if isinstance(regularizer, type) and issubclass(regularizer, Regularizer):
        return regularizer(**(options or {}))
    raise AssertionError(f"{regularizer!r} is not an rsocl.solver.regularizer.Regularizer subclass or instance")


def _weights(weights) -> tuple:
    """``weights`` as a tuple of floats ``>= 0``, at least one; ValueError naming ``weights``."""
    if isinstance(weights, (str, bytes)) or np.ndim(weights) != 1 or len(weights) == 0:
        raise ValueError(f"weights must be a sequence of at least one denoising weight >= 0, got {weights!r}")
    return tuple(check.non_negative(f"weights[{i}]", w) for i, w in enumerate(weights))


def check_regularizer(regularizer, *, options=None, device=None, shape=(5, 12, 10), weights=(0.05, 0.5),
                      pairs=4, seed=0):
    """Check the regularizer contract on ``device`` in every dtype it and the device support.

    Properties checked: options declared as :class:`~rsocl.solver.regularizer.Option` with a
    default; ``name`` set; the output is a device array of the input's shape and dtype
    with finite values; the input is not modified; ``out=`` is honoured; weight 0 is the
    identity; the map is non-expansive (``‖D(x) - D(y)‖ <= ‖x - y‖``) on random pairs;
    no device-to-host transfer happens inside ``denoise``. ``weights`` are the denoising
    weights tried (at least one, each ``>= 0``; the last one serves the non-expansiveness pairs).
    Returns the dtypes checked.
    """
    import pyopencl.array as cla

    weights = _weights(weights)
    reg = _instance(regularizer, options)
    assert isinstance(reg.name, str) and reg.name and reg.name != "base", "the regularizer needs a name"
    for key, opt in type(reg).options.items():
        assert isinstance(opt, Option), f"option {key!r} must be declared as rsocl.solver.regularizer.Option"
    dev = get_device(device)
    rng = np.random.default_rng(seed)
    checked = []
    for dtype in reg.dtypes:
        if dtype == "float64" and not dev.has_fp64:
            continue
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
            np.testing.assert_allclose(target.get(), values, rtol=0, atol=tol * max(1.0, np.abs(values).max()),
                                       err_msg=f"{dtype}: out= result differs from the allocated one")
        np.testing.assert_array_equal(reg.denoise(x, 0.0).get(), x_host, err_msg=f"{dtype}: weight 0 must be "
                                                                                     "the identity")
        for _ in range(pairs):
            a = rng.random(shape).astype(dtype)
            b = (a + rng.normal(0, 0.2, shape)).astype(dtype)
            da = reg.denoise(cla.to_device(dev.queue, a), weights[-1]).get().astype(np.float64)
            db = reg.denoise(cla.to_device(dev.queue, b), weights[-1]).get().astype(np.float64)
            before = np.linalg.norm(a.astype(np.float64) - b)
            after = np.linalg.norm(da - db)
            assert after <= before * (1 + 100 * tol), (f"{dtype}: not non-expansive: ‖D(x)-D(y)‖ = {after:.6g} > "
                                                       f"‖x-y‖ = {before:.6g}")
        checked.append(dtype)
    assert checked, f"no dtype of {reg.dtypes} is supported on {dev.name}"
    return checked
