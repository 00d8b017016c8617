"""Batches of sets: every set of a batch equals its single-set reconstruction, and bad batches are named."""

import numpy as np
import pytest

import rsocl
import rsocl.solver.memory
import rsocl.solver.request
from rsocl.model import reference as ref
from rsocl.model.interpolation import interp3d
from rsocl.model.scenes import builtin_scene
from rsocl.solver.sets import batch_size, reconstruct_sets
from rsocl_plugins.tv import STEP

from conftest import SMALL

SHAPE = (7, 9) if SMALL else (11, 13)


@pytest.fixture(scope="module")
def sets():
    """Three sets of one rig (odd sizes), with their ground truths."""
    rig = rsocl.Rig.paper_array(4, SHAPE, t_e=1e-4, t_r=3e-5)
    rng = np.random.default_rng(7)
    truth = rng.random((3, rig.T) + rig.shape)
    truth[1] *= 0.5  # the sets differ in scale, so a mix-up shows
    return rig, truth, np.stack([ref.forward(rig, t) for t in truth])


def _tol(dtype):
    return 2e-6 if dtype == "float32" else 1e-12


# projection="paper" at small eta is unstable on these random cubes (the run warns): the test
# compares the maths, not the result
@pytest.mark.filterwarnings("ignore:ADMM ended unstable:RuntimeWarning")
@pytest.mark.parametrize("projection", ["exact", "paper"])
def test_each_set_equals_its_single_set_reconstruction(sets, dtype, projection):
    rig, truth, g = sets
    lam, eta = [0.05, 0.1, 0.02], [0.3, 0.0, 0.5]  # per set; the second set is GAP
    kw = dict(iterations=4 if SMALL else 7, tv_iterations=4, projection=projection, dtype=dtype, tune=False)
    batch = rsocl.reconstruct(g, rig, lam=lam, eta=eta, truth=truth, **kw)
    assert batch.datacube.shape == (3, rig.T) + rig.shape and batch.batch == 3
    assert batch.history["residual"].shape == batch.history["psnr"].shape == (kw["iterations"], 3)
    assert batch.params["lam"] == lam and batch.params["eta"] == eta and batch.params["sets"] == 3
    for i in range(3):
        one = rsocl.reconstruct(g[i], rig, lam=lam[i], eta=eta[i], truth=truth[i], **kw)
        scale = np.abs(one.datacube).max()
        np.testing.assert_allclose(batch.datacube[i], one.datacube, atol=_tol(dtype) * scale)
        np.testing.assert_allclose(batch.history["residual"][:, i], one.history["residual"], rtol=1e-5)
        np.testing.assert_allclose(batch.history["psnr"][:, i], one.history["psnr"], atol=1e-4)
        alone = batch.set(i)
        assert alone.batch is None and alone.params["lam"] == lam[i] and alone.datacube.shape == one.datacube.shape


def test_each_set_of_a_batch_stops_at_its_own_tol(sets):
    # every set stops where it would alone: its estimate kept from that iteration, NaN records after it
    rig, truth, g = sets
    lam, eta = [0.05, 0.1, 0.02], [0.3, 0.0, 0.5]
    kw = dict(iterations=60, tol=1e-2, tv_iterations=4, tune=False)
    batch = rsocl.reconstruct(g, rig, lam=lam, eta=eta, truth=truth, **kw)
    runs = []
    for i in range(3):
        one = rsocl.reconstruct(g[i], rig, lam=lam[i], eta=eta[i], truth=truth[i], **kw)
        alone = batch.set(i)
        runs.append(one.params["iterations_run"])
        assert alone.params["iterations_run"] == runs[-1] < kw["iterations"]
        np.testing.assert_allclose(alone.datacube, one.datacube, atol=_tol("float32") * np.abs(one.datacube).max())
        np.testing.assert_allclose(alone.history["residual"], one.history["residual"], rtol=1e-5)
        np.testing.assert_allclose(alone.history["psnr"], one.history["psnr"], atol=1e-4)
        assert np.isnan(batch.history["residual"][runs[-1] :, i]).all()
    assert len(set(runs)) > 1 and batch.params["iterations_run"] == max(runs)


def test_batch_matches_the_numpy_reference(sets, dtype):
    rig, truth, g = sets
    kw = dict(iterations=5, lam=0.05, eta=0.3, tv_iterations=3)
    got = rsocl.reconstruct(
        g, rig, dtype=dtype, regularizer_options={"temporal_weight": 2.0}, tune=False, **kw
    ).datacube
    for i in range(3):
        want = ref.admm(rig, g[i], temporal_weight=2.0, step=STEP, **kw)
        np.testing.assert_allclose(got[i], want, atol=(2e-4 if dtype == "float32" else 1e-10) * np.abs(want).max())


def test_saturation_x0_and_a_shared_truth_per_set(sets):
    rig, truth, g = sets
    level = float(np.quantile(g, 0.9))
    x0 = np.random.default_rng(3).random((3, rig.T) + rig.shape)
    kw = dict(iterations=4, lam=0.05, eta=0.3, tv_iterations=3, saturation=level, tune=False)
    batch = rsocl.reconstruct(g, rig, x0=x0, truth=truth[0], **kw)
    for i in range(3):
        one = rsocl.reconstruct(g[i], rig, x0=x0[i], truth=truth[0], **kw)
        np.testing.assert_allclose(batch.datacube[i], one.datacube, atol=2e-6 * np.abs(one.datacube).max())
        assert batch.params["saturated_pixels"][i] == one.params["saturated_pixels"] == int((g[i] >= level).sum())
    # one x0 for every set is every set's start
    shared = rsocl.reconstruct(g, rig, x0=x0[0], **kw)
    one = rsocl.reconstruct(g[2], rig, x0=x0[0], **kw)
    np.testing.assert_allclose(shared.datacube[2], one.datacube, atol=2e-6 * np.abs(one.datacube).max())


def test_a_batch_of_one_set_and_a_regularizer_without_batches(sets):
    rig, truth, g = sets
    kw = dict(iterations=3, lam=0.05, eta=0.3, tune=False)
    one = rsocl.reconstruct(g[:1], rig, **kw)
    assert one.datacube.shape == (1, rig.T) + rig.shape
    np.testing.assert_array_equal(one.datacube[0], rsocl.reconstruct(g[0], rig, **kw).datacube)
    # the DCT takes one set at a time (batched = False): the batch still equals each set alone
    batch = rsocl.reconstruct(g[:2], rig, regularizer="dct", **kw)
    for i in range(2):
        alone = rsocl.reconstruct(g[i], rig, regularizer="dct", **kw).datacube
        np.testing.assert_allclose(batch.datacube[i], alone, atol=2e-6 * np.abs(alone).max())


def test_operator_and_tv_take_a_batch_in_one_call(device, dtype, rng):
    import pyopencl.array as cla

    from rsocl_plugins.tv import TV

    rig = rsocl.Rig.paper_array(4, SHAPE, t_e=1e-4, t_r=3e-5)
    op = rsocl.RollingShutterOperator(rig, device=device, dtype=dtype)
    f = rng.random((2,) + op.domain_shape)
    g = op.forward(f)
    assert g.shape == (2,) + op.range_shape
    tol = 1e-5 if dtype == "float32" else 1e-12
    for i in range(2):
        np.testing.assert_allclose(g[i], op.forward(f[i]), rtol=tol, atol=tol)
        np.testing.assert_allclose(op.adjoint(g)[i], op.adjoint(g[i]), rtol=tol, atol=tol)
    # TV: one weight per set; no temporal difference across the set boundary (a constant set stays constant)
    x = np.stack([rng.random(op.domain_shape), np.full(op.domain_shape, 0.25)]).astype(dtype)
    x[1, 0] = 0.75  # an edge in time inside the second set
    tv = TV(iterations=6, temporal_weight=1.5)
    out = tv.denoise(cla.to_device(device.queue, x), [0.2, 0.0]).get()
    want = ref.tv_chambolle(x[0], 0.2, 6, 1.5, STEP)
    np.testing.assert_allclose(out[0], want, atol=1e-4 if dtype == "float32" else 1e-10)
    np.testing.assert_array_equal(out[1], x[1])  # weight 0: the set is copied
    both = tv.denoise(cla.to_device(device.queue, x), 0.3).get()
    for i in range(2):
        np.testing.assert_allclose(
            both[i], ref.tv_chambolle(x[i], 0.3, 6, 1.5, STEP), atol=1e-4 if dtype == "float32" else 1e-10
        )


def test_sums_per_set(device, rng):
    import pyopencl.array as cla

    from rsocl.device.reduction import sum_sq_diff

    a, b = rng.random((5, 3, 7)), rng.random((5, 3, 7))
    got = sum_sq_diff(cla.to_device(device.queue, a), cla.to_device(device.queue, b), sets=5)
    np.testing.assert_allclose(got, ((a - b) ** 2).sum(axis=(1, 2)), rtol=1e-12)
    with pytest.raises(ValueError, match="sets must be >= 1 and divide"):
        sum_sq_diff(cla.to_device(device.queue, a), sets=4)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(lam=[0.1, 0.2]), r"lam must have one value per set: 3 for this batch, got 2"),
        (dict(eta=[0.1, 0.2, 0.3, 0.4]), r"eta must have one value per set: 3 for this batch, got 4"),
        (dict(lam=[0.1, -1, 0.2]), r"lam\[1\] must be >= 0"),
        (dict(eta=[[0.1]]), r"eta must be a number >= 0 or a sequence"),
        (dict(x0=np.zeros((2, 1, 1, 1))), r"x0 must have shape \(T, m, n\)"),
    ],
)
def test_bad_batch_arguments_are_named(sets, kwargs, match):
    rig, truth, g = sets
    with pytest.raises(ValueError, match=match):
        rsocl.reconstruct(g, rig, iterations=1, **kwargs)


def test_bad_batch_shapes_are_named(sets):
    rig, truth, g = sets
    with pytest.raises(ValueError, match=r"g must have shape \(K, m, n\).*or \(B, K, m, n\)"):
        rsocl.reconstruct(g[:, :3], rig)
    with pytest.raises(ValueError, match=r"g must have shape.*B >= 1"):
        rsocl.reconstruct(g[:0], rig)
    with pytest.raises(ValueError, match=r"truth must have shape .*for this batch"):
        rsocl.reconstruct(g, rig, truth=truth[:2])
    with pytest.raises(ValueError, match=r"lam has 3 values \(one per set\), but g holds one set"):
        rsocl.reconstruct(g[0], rig, lam=[0.1, 0.1, 0.1])
    with pytest.raises(ValueError, match=r"set\(s\) \[1\]"):
        rsocl.reconstruct(g * np.array([1.0, 1e9, 1.0])[:, None, None, None], rig, saturation=1e3)
    op = rsocl.RollingShutterOperator(rig)
    with pytest.raises(ValueError, match=r"f must have shape .* or \(B, "):
        op.forward(np.zeros((2, 3) + op.domain_shape))
    with pytest.raises(ValueError, match=r"weight must be a number or one per set \(3 values\)"):
        import pyopencl.array as cla

        from rsocl_plugins.tv import TV

        TV().denoise(cla.zeros(op.queue, (3,) + op.domain_shape, np.float32), [0.1, 0.2])


def test_batch_size_follows_the_device_memory(sets, monkeypatch):
    rig, truth, g = sets
    device = rsocl.device.get_device()
    assert batch_size(rig, sets=5, device=device) == 5
    assert batch_size(rig, device=device, limit=7) == 7
    reg = rsocl.solver.request.make_regularizer("tv")

    def total(b, start=False):
        return rsocl.solver.memory.batch_memory(
            (rig.T,) + rig.shape, rig.n_channels, np.float32, reg, "exact", b, start=start
        )[1]

    memory = (total(4) + total(5)) / 2 / 0.8  # four sets fit in 80 % of it, five do not
    monkeypatch.setattr(type(device), "global_mem_bytes", property(lambda self: int(memory)))
    assert batch_size(rig, device=device) == 4
    assert batch_size(rig, device=device, memory_fraction=(total(2) + total(3)) / 2 / memory) == 2
    memory = (total(3, True) + total(4, True)) / 2 / 0.8  # a start cube per set: three sets, not four
    monkeypatch.setattr(type(device), "global_mem_bytes", property(lambda self: int(memory)))
    assert batch_size(rig, device=device, start=True) == 3
    monkeypatch.setattr(type(device), "global_mem_bytes", property(lambda self: total(1) // 2))
    with pytest.raises(ValueError, match="device memory"):
        batch_size(rig, device=device)
    for kwargs, match in [
        (dict(limit=0), "limit"),
        (dict(sets=0), "sets"),
        (dict(memory_fraction=2), "memory_fraction"),
        (dict(projection="diag"), "projection"),
    ]:
        with pytest.raises(ValueError, match=match):
            batch_size(rig, device=device, **kwargs)


def test_batch_size_on_a_cpu_keeps_the_batch_in_its_cache(sets, monkeypatch):
    rig, truth, g = sets
    device = rsocl.device.get_device()
    reg = rsocl.solver.request.make_regularizer("tv")
    cube = (rig.T,) + rig.shape

    def total(b):
        return rsocl.solver.memory.batch_memory(cube, rig.n_channels, np.float32, reg, "exact", b)[1]

    monkeypatch.setattr(type(device), "is_cpu", property(lambda self: True))
    cache = (total(3) + total(4)) / 2 / 0.75  # three sets fit in three quarters of it, four do not
    monkeypatch.setattr(type(device), "cache_bytes", property(lambda self: int(cache)))
    assert batch_size(rig, sets=8, device=device) == 3
    assert batch_size(rig, sets=8, device=device, start=True) == 3  # the start cube, read once: not cached
    assert batch_size(rig, sets=8, device=device, cache_fraction=(total(2) + total(3)) / 2 / cache) == 2
    assert batch_size(rig, sets=8, device=device, cache_fraction=None) == 8
    monkeypatch.setattr(type(device), "cache_bytes", property(lambda self: 16))
    assert batch_size(rig, sets=8, device=device) == 1  # at least one set
    monkeypatch.setattr(type(device), "is_cpu", property(lambda self: False))
    assert batch_size(rig, sets=8, device=device) == 8  # a GPU fills its memory instead
    with pytest.raises(ValueError, match="cache_fraction"):
        batch_size(rig, device=device, cache_fraction=0)


def test_reconstruct_sets_runs_batches_and_joins_them(sets):
    rig, truth, g = sets
    kw = dict(iterations=3, eta=0.3, tv_iterations=3, tune=False)
    lam = [0.05, 0.1, 0.02]
    joined = reconstruct_sets(g, rig, batch=2, lam=lam, truth=truth, **kw)
    whole = rsocl.reconstruct(g, rig, lam=lam, truth=truth, **kw)
    np.testing.assert_allclose(joined.datacube, whole.datacube, atol=2e-6 * np.abs(whole.datacube).max())
    assert joined.params["lam"] == lam and joined.params["batch"] == 2 and joined.params["sets"] == 3
    assert joined.history["psnr"].shape == (3, 3)
    np.testing.assert_allclose(joined.history["psnr"], whole.history["psnr"], atol=1e-4)
    with pytest.raises(ValueError, match="lam must have one value per set: 3 sets, got 2"):
        reconstruct_sets(g, rig, lam=[0.1, 0.2])
    with pytest.raises(ValueError, match=r"g must hold S >= 1 sets"):
        reconstruct_sets(g[0], rig)
    with pytest.raises(ValueError, match="batch"):
        reconstruct_sets(g, rig, batch=0)


def test_every_set_is_checked_and_warned_of_once_before_the_first_batch_runs(sets, monkeypatch, recwarn):
    import rsocl.solver.sets as sets_module

    rig, _, g = sets
    ran = []
    monkeypatch.setattr(sets_module, "tune_and_run", lambda *a, **k: ran.append(1))
    bad = np.array(g, dtype=np.float64)
    bad[2, 0, 3, 3] = np.nan  # the last set: refused before the batches of the others run, naming it
    with pytest.raises(ValueError, match=r"^g: set\(s\) \[2\] of 3 hold NaN or inf values"):
        reconstruct_sets(bad, rig, batch=1, iterations=2, tune=False)
    assert not ran
    monkeypatch.undo()
    off = np.array(g) * np.array([100.0, 200.0, 300.0])[:, None, None, None]  # off-scale, more in each batch
    result = reconstruct_sets(off, rig, batch=1, iterations=2, tune=False, lam=0.1)
    said = [w for w in recwarn if "times its full scale" in str(w.message)]
    assert len(said) == 1 and "reach" in str(said[0].message), [str(w.message) for w in recwarn]
    assert result.params["batch"] == 1
    assert reconstruct_sets(g, rig, batch=10, iterations=2, tune=False).params["batch"] == 3  # no batch held more


def test_a_tuned_batch_applies_its_first_sets_choice_to_every_set(sets):
    """Self-tuning a batch: the choice made on set 0 serves every set, each started from its own interp3d."""
    rig, _, g = sets
    kw = dict(iterations=4, tv_iterations=3, eta=0.3)
    batch = rsocl.reconstruct(g[:2], rig, **kw)
    chosen = batch.params["tuning"]["chosen"]
    assert batch.params["start"] == "interp3d" and set(chosen) >= {"lam", "temporal_weight"}
    first = rsocl.reconstruct(g[0], rig, **kw)
    assert first.params["tuning"]["chosen"] == chosen
    np.testing.assert_allclose(batch.datacube[0], first.datacube, atol=2e-6 * np.abs(first.datacube).max())
    fixed = dict(
        kw,
        lam=chosen["lam"],
        regularizer_options={"temporal_weight": chosen["temporal_weight"]},
        blend=batch.params["blend"],
    )  # the search's blend too, towards the set's own start
    second = rsocl.reconstruct(g[1], rig, x0=interp3d(g[1], rig), tune=False, **fixed)
    np.testing.assert_allclose(batch.datacube[1], second.datacube, atol=2e-6 * np.abs(second.datacube).max())


def test_tuned_sets_in_several_batches_share_the_first_batchs_choice(sets):
    rig, _, g = sets
    kw = dict(iterations=4, tv_iterations=3, eta=0.3)
    joined = reconstruct_sets(g, rig, batch=2, **kw)
    chosen = joined.params["tuning"]["chosen"]
    fixed = dict(
        kw,
        lam=chosen["lam"],
        regularizer_options={"temporal_weight": chosen["temporal_weight"]},
        blend=joined.params["blend"],
    )
    last = rsocl.reconstruct(g[2], rig, x0=interp3d(g[2], rig), tune=False, **fixed).datacube
    np.testing.assert_allclose(joined.datacube[2], last, atol=2e-6 * np.abs(last).max())


def test_own_inverses_rule():
    from rsocl.solver.inverse import own_inverses

    same = np.ones((3, 4, 2, 2), bool)
    differ = same.copy()
    differ[1, 0, 0, 0] = False
    assert not own_inverses("exact", [0.2, 0.3], None, 1)  # one set: nothing to share
    assert own_inverses("exact", [0.2, 0.3, 0.2], None, 3)  # the exact blocks hold eta
    assert not own_inverses("paper", [0.2, 0.3, 0.2], None, 3)  # the paper's do not
    assert not own_inverses("exact", 0.2, same, 3)
    assert own_inverses("paper", 0.2, differ, 3)  # different pixels left out


@pytest.mark.parametrize("projection", ["exact", "paper"])
@pytest.mark.parametrize("case", ["shared", "eta per set", "saturation per set"])
def test_the_memory_count_and_the_solver_agree_on_per_set_inverses(sets, monkeypatch, projection, case):
    """stage_on_device counts per-set inverse blocks exactly when ADMM allocates them."""
    import rsocl.solver.admm as admm
    import rsocl.solver.problem as problem

    rig, truth, g = sets
    kwargs = {}
    if case == "eta per set":
        kwargs["eta"] = [0.1, 0.2, 0.3]
    elif case == "saturation per set":
        kwargs["saturation"] = float(np.quantile(g[0], 0.9))  # set 1 (half the scale) loses fewer pixels
    counted, allocated = [], []
    memory_bytes, inverses = problem.memory_bytes, admm.inverse_blocks

    def count(*args, **kw):
        counted.append(kw["own_inverse"])
        return memory_bytes(*args, **kw)

    def allocate(*args, **kw):
        own, blocks = inverses(*args, **kw)
        allocated.append(bool(own))
        return own, blocks

    monkeypatch.setattr(problem, "memory_bytes", count)
    monkeypatch.setattr(admm, "inverse_blocks", allocate)
    rsocl.reconstruct(g, rig, iterations=2, projection=projection, tune=False, **kwargs)
    assert counted == allocated
    # saturated pixels stay in the blocks (one-sided in the data step): saturation never makes them per set
    assert allocated == [case == "eta per set" and projection == "exact"]


def test_batch_size_on_a_gpu_goes_past_max_batch_up_to_its_voxels(sets, monkeypatch):
    from rsocl.solver.sets import GPU_BATCH_VOXELS, MAX_BATCH

    rig, truth, g = sets
    device = rsocl.device.get_device()
    voxels = rig.T * rig.shape[0] * rig.shape[1]
    monkeypatch.setattr(type(device), "is_cpu", property(lambda self: True))
    assert batch_size(rig, device=device) == MAX_BATCH
    monkeypatch.setattr(type(device), "is_cpu", property(lambda self: False))
    monkeypatch.setattr(type(device), "global_mem_bytes", property(lambda self: 2**40))
    monkeypatch.setattr(type(device), "max_alloc_bytes", property(lambda self: 2**40))
    most = GPU_BATCH_VOXELS // voxels
    assert most > MAX_BATCH
    assert batch_size(rig, device=device) == most
    assert batch_size(rig, device=device, sets=40) == 40
    assert batch_size(rig, device=device, limit=7) == 7
    # memory still bounds it: the largest batch within 80 % of the device, found by bisection
    reg = rsocl.solver.request.make_regularizer("tv")

    def total(b):
        return rsocl.solver.memory.batch_memory((rig.T,) + rig.shape, rig.n_channels, np.float32, reg, "exact", b)[1]

    memory = (total(57) + total(58)) / 2 / 0.8
    monkeypatch.setattr(type(device), "global_mem_bytes", property(lambda self: int(memory)))
    assert batch_size(rig, device=device) == 57


def test_a_gap_set_in_a_batch_gets_the_default_lam_it_gets_alone():
    # the default lam is scaled by the rig's curvature for ADMM sets but not for GAP (eta = 0) sets,
    # whose denoiser weight is lam itself: in a batch mixing both, each set keeps its own default
    rig = rsocl.Rig([rsocl.Camera(a, t_e=9 * 35e-6, t_r=35e-6) for a in (0, 120, 240)], (7, 31))
    g = np.stack([ref.forward(rig, builtin_scene(rig.shape, rig.T, seed=s, dtype=np.float64)) for s in range(2)])
    kw = dict(iterations=3, tune=False, dtype="float64")
    batch = rsocl.reconstruct(g, rig, eta=[0.2, 0.0], **kw)
    alone = [rsocl.reconstruct(g[i], rig, eta=eta, **kw) for i, eta in enumerate((0.2, 0.0))]
    assert alone[0].params["lam"] != pytest.approx(alone[1].params["lam"])  # scaled, unscaled
    assert batch.params["lam"] == pytest.approx([one.params["lam"] for one in alone])
    for i, one in enumerate(alone):
        np.testing.assert_allclose(batch.datacube[i], one.datacube, atol=1e-12)


def test_a_set_that_never_moves_is_refused_in_a_batch_as_alone(sets):
    # under tol it stops at its second iteration; its own two records decide, as in its single-set run
    rig, _, g = sets
    kw = dict(iterations=30, tol=1e-2, tv_iterations=4, tune=False, lam=0.1)
    with pytest.raises(FloatingPointError, match=r"^ADMM never moved: .* over 2 iterations"):
        rsocl.reconstruct(g[1], rig, eta=1e30, **kw)
    with pytest.raises(FloatingPointError, match=r"^ADMM never moved in set\(s\) \[1\]: .* over 2 iterations"):
        rsocl.reconstruct(g[:2], rig, eta=[0.2, 1e30], **kw)
