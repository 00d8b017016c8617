"""The PyTorch peer of ``benchmarks/peer.py`` computes what rsocl computes (skipped without torch).

The peer's speed ratios mean something only if it runs the same arithmetic: the same TV (rsocl's
temporal weight, step and edge rules), the same projection, the same start. Tiny cases, few
iterations: CI does not install torch, and a developer's run stays fast.
"""

import sys
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

from numpy_admm_tv import psnr  # noqa: E402
from torch_admm_tv import Peer, tv_chambolle  # noqa: E402

import rsocl  # noqa: E402
from rsocl.model.scenes import builtin_scene  # noqa: E402
from rsocl_plugins.tv import TV  # noqa: E402


def _reconstruct_peer(g, rig, iterations, dtype, tv):
    peer = Peer(
        g,
        rig,
        lam=0.1,
        eta=0.2,
        tv_iterations=tv.iterations,
        dtype=dtype,
        temporal_weight=tv.temporal_weight,
        step=tv.step,
    )
    theta, b = peer.zeros(), peer.zeros()
    with torch.no_grad():
        for _ in range(iterations):
            theta, b = peer.step(theta, b)
    return theta.numpy()


@pytest.mark.parametrize("weight, step", [(3.0, 0.9), (0.0, 0.9), (10.0, 0.5)])
@pytest.mark.parametrize("iterations", [1, 2, 7])
def test_tv_matches_rsocl_tv(device, has_fp64, rng, weight, step, iterations):
    """Temporal weight, step, edges and batch independence equal rsocl's TV kernels."""
    import pyopencl.array as cla

    if not has_fp64:
        pytest.skip("needs float64 on the device")
    x = rng.random((2, 5, 6, 7))  # a batch of 2 sets
    tv = TV(temporal_weight=weight, step=step, iterations=iterations)
    ours = tv.denoise(cla.to_device(device.queue, x), 0.3).get()
    peer = tv_chambolle(torch.from_numpy(x), 0.3, iterations, temporal_weight=weight, step=step).numpy()
    np.testing.assert_allclose(peer, ours, rtol=0, atol=1e-12)


def test_tv_defaults_are_scikit_image():
    """``temporal_weight = step = 1`` (``bench_admm.py``'s peer) is scikit-image's 3-D TV."""
    from skimage.restoration import denoise_tv_chambolle

    x = np.random.default_rng(5).random((6, 7, 8))
    for iterations in (1, 3, 10):
        want = denoise_tv_chambolle(x, weight=0.2, eps=0, max_num_iter=iterations)
        np.testing.assert_allclose(tv_chambolle(torch.from_numpy(x), 0.2, iterations).numpy(), want, rtol=0, atol=1e-12)


def _case(device, sets):
    rig = rsocl.Rig.paper_array(4, (10, 12), 0.18e-3, 35e-6)
    op = rsocl.RollingShutterOperator(rig, device=device, dtype="float64" if device.has_fp64 else "float32")
    truth = [builtin_scene(rig.shape, rig.T, seed=s, dtype=np.float64) for s in range(sets)]
    return rig, truth, np.stack([op.forward(t) for t in truth])


def test_admm_matches_rsocl_float64(device, has_fp64):
    """A batch of 2 sets, rsocl's fixed settings from zeros: the same datacube to float64 rounding."""
    if not has_fp64:
        pytest.skip("needs float64 on the device")
    rig, truth, g = _case(device, 2)
    res = rsocl.reconstruct(g, rig, iterations=4, lam=0.1, eta=0.2, tune=False, device=device, dtype="float64")
    assert res.params["start"] == "zeros"
    peer = _reconstruct_peer(g, rig, 4, torch.float64, TV())
    np.testing.assert_allclose(peer, res.datacube, rtol=0, atol=1e-12)


def test_admm_matches_rsocl_float32(device):
    """float32, one set: the same PSNR to float rounding (the benchmark's check)."""
    rig, truth, g = _case(device, 1)
    res = rsocl.reconstruct(g[0], rig, iterations=4, lam=0.1, eta=0.2, tune=False, device=device)
    peer = _reconstruct_peer(g[0], rig, 4, torch.float32, TV())
    assert np.max(np.abs(peer - res.datacube)) < 1e-5
    assert abs(psnr(peer, truth[0]) - psnr(res.datacube, truth[0])) < 1e-4


def test_benchmark_page(device, tmp_path):
    """``peer.py`` on one tiny case writes a page with the times, the ratios and the equality check."""
    import peer

    out = tmp_path / "peer.md"
    peer.main(
        [
            "--cases",
            "size8",
            "--sizes",
            "8",
            "--size-iterations",
            "2",
            "--rounds",
            "1",
            "--modes",
            "eager",
            "--torch-device",
            "cpu",
            "--out",
            str(out),
        ]
    )
    text = out.read_text()
    assert "| one set 8×8 (T = 13), per ADMM iteration |" in text
    row = [line for line in text.splitlines() if line.startswith("| one set 8×8") and " dB, " in line]
    assert len(row) == 1 and "failed" not in row[0]
    delta = float(row[0].split("|")[3].split(" dB")[0])
    assert abs(delta) < 1e-4


def test_compiled_step_is_one_graph():
    """``torch.compile`` traces a whole ADMM iteration (one set and a batch) without a graph break:
    a break would leave most of the peer's compile mode eager."""
    dynamo = pytest.importorskip("torch._dynamo")
    rig = rsocl.Rig.paper_array(4, (6, 8), 0.18e-3, 35e-6)
    for shape in [(4, 6, 8), (2, 4, 6, 8)]:
        g = np.random.default_rng(3).random(shape).astype(np.float32)
        peer = Peer(g, rig, lam=0.1, eta=0.2, tv_iterations=3, temporal_weight=3.0, step=0.9)
        with torch.no_grad():
            explained = dynamo.explain(peer.step)(peer.zeros(), peer.zeros())
        assert explained.graph_break_count == 0, [b.reason for b in explained.break_reasons]
        assert explained.graph_count == 1
