"""The data term's scale (rsocl.model.curvature) and the defaults it scales."""

import numpy as np
import pytest

import rsocl
from rsocl.model import reference as ref
from rsocl.model.curvature import REFERENCE_PSI, default_scale, psi_values

TR = 35e-6


def _rigs():
    yield rsocl.Rig.paper_array(4, (9, 7))
    yield rsocl.Rig.paper_array(8, (9, 7), t_e=20e-6)
    yield rsocl.Rig.paper_array(4, (9, 7), t_e=2e-6, dt=80e-6)  # windows inside one sub-frame
    yield rsocl.Rig.paper_array(4, (9, 7), mask="binary", dt=80e-6)
    yield rsocl.Rig([rsocl.Camera(a, t_e=0.3 * TR, t_r=TR, gain=g) for a, g in ((0, 1), (30, 2), (60, 0.5))], (10, 12))
    yield rsocl.Rig([rsocl.Camera(0, t_e=3e-4, t_r=TR, frames=2, t_d=2e-3)], (6, 5))


@pytest.mark.parametrize("rig", list(_rigs()), ids=lambda r: f"{r.n_channels}ch-{r.mask}")
def test_psi_values_are_the_diagonal_of_h_ht(rig):
    w = ref.weights(rig) * rig.windows.gain[:, None, None, None]
    np.testing.assert_allclose(psi_values(rig), (w**2).sum(axis=1), rtol=0, atol=1e-12)


def test_the_paper_configuration_keeps_the_defaults_and_gains_scale_them_squared():
    assert REFERENCE_PSI == pytest.approx(5 + 1 / 49)
    for k, shape in ((1, (1, 1)), (4, (64, 64)), (4, (50, 50)), (3, (17, 29))):
        assert default_scale(rsocl.Rig.paper_array(k, shape, t_e=180e-6, t_r=TR)) == 1.0
    gained = rsocl.Rig([rsocl.Camera(a, t_e=180e-6, t_r=TR, gain=3.0) for a in (0, 90, 180, 270)], (8, 8))
    assert default_scale(gained) == pytest.approx(9.0)
    short = rsocl.Rig.paper_array(4, (8, 8), t_e=0.25 * TR, t_r=TR)  # one weight of 1/4
    assert default_scale(short) == pytest.approx((1 / 16) / REFERENCE_PSI)


def test_reconstruct_scales_the_default_lam_and_eta_but_not_given_ones():
    rig = rsocl.Rig([rsocl.Camera(a, t_e=180e-6, t_r=TR, gain=2.0) for a in (0, 90, 180, 270)], (8, 8))
    truth = np.random.default_rng(0).random((rig.T,) + rig.shape)
    g = ref.forward(rig, truth)
    res = rsocl.reconstruct(g, rig, iterations=3, tune=False)
    assert (res.params["lam"], res.params["eta"]) == (pytest.approx(0.4), pytest.approx(0.8))
    res = rsocl.reconstruct(g, rig, iterations=3, tune=False, lam=0.1, eta=0.2)
    assert (res.params["lam"], res.params["eta"]) == (0.1, 0.2)
    res = rsocl.reconstruct(g, rig, iterations=3, tune=False, eta=0.0)  # GAP: lam is the weight
    assert res.params["lam"] == 0.1
    # the scaled defaults make the run blind to the gains' units: g / 2 with gain 1 gives the same cube
    unit = rsocl.Rig([rsocl.Camera(a, t_e=180e-6, t_r=TR) for a in (0, 90, 180, 270)], (8, 8))
    for tune in (False, True):
        a = rsocl.reconstruct(g, rig, iterations=20, tune=tune, dtype="float64").datacube
        b = rsocl.reconstruct(g / 2.0, unit, iterations=20, tune=tune, dtype="float64").datacube
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-9)


def test_a_rig_whose_windows_hold_no_sub_frame_is_refused():
    rig = rsocl.Rig([rsocl.Camera(0, t_e=1e-6, t_r=TR, t_a=10e-6)], (1, 1), dt=80e-6, mask="binary")
    assert not psi_values(rig).any()
    with pytest.raises(ValueError, match="hold no sub-frame"):
        default_scale(rig)
