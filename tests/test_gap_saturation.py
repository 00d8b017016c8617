"""GAP (``eta = 0``) with saturated samples on a rig whose pixel blocks are singular: cameras whose windows
weight only the same binned sub-frame (``dt > t_r``, exposures shorter than a sub-frame). The one-sided
data step there is the limit ``eta → 0⁺`` (docs/model.md, saturated pixels): the NumPy reference by its
active sets, the device by ``gap_one_sided_step`` (kernels/admm.cl)."""

import warnings

import numpy as np
import pytest

import rsocl
from rsocl.model import reference as ref


@pytest.fixture(scope="module")
def clipped():
    """The rig, its snapshots of a random scene clipped at their 80th percentile, the level and a start."""
    C = rsocl.Camera
    cameras = [C(0, 20e-6, 35e-6), C(90, 50e-6, 35e-6), C(180, 10e-6, 35e-6, t_a=3e-6)]
    rig = rsocl.Rig(cameras, (10, 10), dt=70e-6)
    rng = np.random.default_rng(1)
    g = ref.forward(rig, rng.uniform(0, 1, (rig.T,) + rig.shape))
    level = float(np.percentile(g, 80))
    return rig, np.minimum(g, level), level, rng.uniform(0, 1, (rig.T,) + rig.shape)


def test_the_rig_has_singular_blocks_where_samples_are_saturated(clipped):
    rig, g, level, _ = clipped
    rank = np.linalg.matrix_rank(ref.gram(rig), hermitian=True)
    saturated = (g >= level).any(axis=0)
    assert np.any((rank < rig.n_channels) & saturated)


def test_the_reference_step_meets_every_sample_when_the_scene_can(clipped):
    # the clipped snapshots of a real scene: some f meets every unsaturated sample exactly and every
    # saturated one at or above its level, so the GAP step (the nearest such f) does too
    rig, g, level, x0 = clipped
    saturated = g >= level
    after = ref.forward(rig, ref.project(rig, x0, g, 0.0, "exact", saturated)) - g
    assert np.abs(np.where(saturated, 0.0, after)).max() < 1e-12
    assert (-np.where(saturated, after, 0.0)).max() < 1e-12


def test_the_reference_step_at_eta_0_is_the_limit_of_small_eta(clipped):
    rig, g, level, x0 = clipped
    at = {eta: ref.project(rig, x0, g, eta, "exact", g >= level) for eta in (0.0, 1e-6, 1e-7)}
    gaps = [np.abs(at[0.0] - at[eta]).max() for eta in (1e-6, 1e-7)]
    assert 0 < gaps[1] < gaps[0] / 5 and gaps[1] < 1e-4


@pytest.mark.parametrize("gpu", [False, True])
def test_the_device_takes_the_reference_step(clipped, device, dtype, monkeypatch, gpu):
    from rsocl.device.context import Device

    if gpu:  # the projection's GPU launch path
        monkeypatch.setattr(Device, "is_cpu", property(lambda self: False))
    rig, g, level, x0 = clipped
    kw = dict(iterations=3, lam=0.0, eta=0.0, x0=x0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # lam = 0: the identity denoiser
        got = rsocl.reconstruct(g, rig, tune=False, dtype=dtype, device=device, saturation=level, **kw)
    want = ref.admm(rig, g, tv_iterations=1, saturated=g >= level, **kw)
    tol = 1e-5 if dtype == "float32" else 1e-12
    np.testing.assert_allclose(got.datacube, want, atol=tol * np.abs(want).max())


def test_a_gap_set_beside_an_eta_set_in_one_batch_equals_each_alone(clipped, device, has_fp64):
    rig, g, level, x0 = clipped
    dtype = "float64" if has_fp64 else "float32"
    kw = dict(iterations=3, lam=0.05, tune=False, dtype=dtype, device=device, saturation=level, x0=x0)
    batch = rsocl.reconstruct(np.stack([g, g]), rig, eta=[0.0, 0.3], **kw)
    for i, eta in enumerate((0.0, 0.3)):
        alone = rsocl.reconstruct(g, rig, eta=eta, **kw)
        tol = 1e-5 if dtype == "float32" else 1e-11
        np.testing.assert_allclose(batch.datacube[i], alone.datacube, atol=tol * np.abs(alone.datacube).max())


def test_the_device_step_where_switching_samples_cycles(device, dtype):
    # at pixel (1, 3) switching the samples that break the tests returns to its first active set every 3
    # rounds; the step then tries every active set, as the reference does
    C = rsocl.Camera
    spec = [(90, 98, 59, 2.0), (0, 96, 31, 1.0), (180, 98, 16, 0.7), (90, 68, 64, 1.9)]  # angle, t_e, t_a (µs), gain
    rig = rsocl.Rig([C(a, te * 1e-6, 35e-6, t_a=ta * 1e-6, gain=gn) for a, te, ta, gn in spec], (4, 4), dt=70e-6)
    rng = np.random.default_rng(564)
    g = ref.forward(rig, rng.uniform(0, 1, (rig.T,) + rig.shape))
    level = float(np.percentile(g, 60))
    g = np.minimum(g, level)
    x0 = rng.uniform(0, 1.5, (rig.T,) + rig.shape)
    want = ref.project(rig, x0, g, 0.0, "exact", g >= level)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # lam = 0: the identity denoiser
        got = rsocl.reconstruct(
            g, rig, iterations=1, lam=0.0, eta=0.0, tune=False, dtype=dtype, device=device, saturation=level, x0=x0
        )
    tol = 1e-4 if dtype == "float32" else 1e-12
    np.testing.assert_allclose(got.datacube, want, atol=tol * np.abs(want).max())


def test_a_set_without_saturated_samples_takes_in_a_batch_the_step_it_takes_alone(clipped, device, dtype):
    # 0.7 g stays below the level: alone its run has no one-sided step at all, and in a batch beside g its
    # pixels take the plain step too, to the last bit
    rig, g, level, x0 = clipped
    kw = dict(iterations=3, lam=0.05, eta=0.0, tune=False, dtype=dtype, device=device, saturation=level, x0=x0)
    batch = rsocl.reconstruct(np.stack([g, 0.7 * g]), rig, **kw)
    for i, one in enumerate((g, 0.7 * g)):
        np.testing.assert_array_equal(batch.datacube[i], rsocl.reconstruct(one, rig, **kw).datacube)
