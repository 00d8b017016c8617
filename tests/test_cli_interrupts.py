"""``rsocl reconstruct`` (in one piece, in tiles, as a stream of windows) and ``rsocl demo``: an interrupt ends
in one line saying what was written and kept, and no picture is written over ``--out``."""

import os
import signal

import h5py
import pytest

from rsocl.cli.main import main
from rsocl.files.hdf5 import load_reconstruction


@pytest.fixture(scope="module")
def captures(tmp_path_factory):
    """A capture of one frame per camera and one of 3 frames (a stream), both 12x12 with their truth."""
    folder = tmp_path_factory.mktemp("captures")
    cap, stream = folder / "cap.h5", folder / "mf.h5"
    assert main(["simulate", "builtin", "--out", str(cap), "--shape", "12", "12", "--quiet"]) == 0
    assert main(["simulate", "builtin", "--out", str(stream), "--shape", "12", "12", "--frames", "3", "--quiet"]) == 0
    return cap, stream


@pytest.fixture(autouse=True)
def _sigint_raises():
    """SIGINT raises KeyboardInterrupt in these tests, as in an interactive run, even where the suite was started
    with SIGINT ignored (a background job of a non-interactive shell: Python then keeps it ignored)."""
    before = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, before)


#: A stream of windows and a run in tiles: the runs whose result is written once every piece is solved.
IN_PIECES = [pytest.param(["--window", "1"], id="stream"), pytest.param(["--tile", "6", "6"], id="tiles")]


def _in_pieces(captures, out, run):
    """``rsocl reconstruct``'s arguments for ``run`` (of :data:`IN_PIECES`) into ``out``, 2 fixed iterations."""
    cap, stream = captures
    argv = ["reconstruct", str(stream if "--window" in run else cap), "--out", str(out), *run]
    return argv + ["--iterations", "2", "--fixed", "--quiet"]


def _signal_in_the_gif(monkeypatch, signum=signal.SIGINT):
    """Send the process ``signum`` as the comparison GIF starts to be drawn (after the result file is written)."""
    import rsocl.analysis.visual as visual

    real = visual.comparison_gif

    def gif(*args, **kwargs):
        os.kill(os.getpid(), signum)
        return real(*args, **kwargs)

    monkeypatch.setattr(visual, "comparison_gif", gif)


def _earlier(out):
    """The one earlier file kept beside ``out``."""
    (kept,) = sorted(out.parent.glob(f"{out.stem}.earlier-*{out.suffix}"))
    return kept


@pytest.mark.parametrize("run", IN_PIECES)
def test_an_interrupt_after_an_hdf5_result_is_written_names_it_and_the_earlier_file(
    captures, tmp_path, capsys, monkeypatch, run
):
    out = tmp_path / "rec.h5"
    argv = _in_pieces(captures, out, run)
    assert main(argv) == 0  # an earlier result at --out
    _signal_in_the_gif(monkeypatch)
    capsys.readouterr()
    assert main(argv) == 130
    kept = _earlier(out)
    assert capsys.readouterr().err == (
        f"rsocl reconstruct: interrupted: {out} written, the earlier file there is kept as {kept}; "
        "the pictures are not all drawn\n"
    )
    assert load_reconstruction(out).datacube.shape[1:] == (12, 12)


def test_an_interrupt_after_a_zarr_store_is_complete_names_it(captures, tmp_path, capsys, monkeypatch):
    pytest.importorskip("zarr")
    cap, _ = captures
    out = tmp_path / "rec.zarr"
    _signal_in_the_gif(monkeypatch)
    argv = ["reconstruct", str(cap), "--out", str(out), "--tile", "6", "6", "--iterations", "2", "--fixed", "--quiet"]
    assert main(argv) == 130
    assert capsys.readouterr().err == f"rsocl reconstruct: interrupted: {out} written; the pictures are not all drawn\n"
    assert out.is_dir() and not out.with_suffix(".gif").exists()


def test_an_interrupt_while_a_streams_windows_are_solved_says_nothing_is_written(
    captures, tmp_path, capsys, monkeypatch
):
    import rsocl.scale.stream as stream_module

    _, stream = captures
    out = tmp_path / "rec.h5"
    argv = ["reconstruct", str(stream), "--out", str(out), "--window", "1", "--iterations", "2", "--fixed", "--quiet"]
    real = stream_module.reconstruct_stream

    def interrupted(*args, **kwargs):
        os.kill(os.getpid(), signal.SIGINT)
        return real(*args, **kwargs)

    monkeypatch.setattr(stream_module, "reconstruct_stream", interrupted)
    assert main(argv) == 130
    assert capsys.readouterr().err == "rsocl reconstruct: interrupted: nothing written\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == []
    monkeypatch.setattr(stream_module, "reconstruct_stream", real)
    assert main(argv) == 0
    before = out.read_bytes()
    monkeypatch.setattr(stream_module, "reconstruct_stream", interrupted)
    capsys.readouterr()
    assert main([*argv, "--lam", "0.5"]) == 130
    assert capsys.readouterr().err == f"rsocl reconstruct: interrupted: nothing written, {out} unchanged\n"
    assert out.read_bytes() == before and not list(tmp_path.glob("rec.earlier-*"))


def test_demo_interrupted_or_terminated_after_writing_names_the_file_and_the_earlier_one(tmp_path, capsys, monkeypatch):
    out = tmp_path / "demo"
    argv = ["demo", "--shape", "12", "12", "--iterations", "2", "--fixed", "--out", str(out), "--quiet"]
    assert main(argv) == 0
    _signal_in_the_gif(monkeypatch, signal.SIGTERM)  # SIGTERM ends a command as Ctrl-C does
    capsys.readouterr()
    assert main(argv) == 143
    result = out / "demo.h5"
    kept = _earlier(result)
    assert capsys.readouterr().err == (
        f"rsocl demo: terminated: {result} written, the earlier file there is kept as {kept}; "
        "the pictures are not all drawn\n"
    )
    with h5py.File(result, "r") as h5:
        assert h5.attrs["rsocl_file"] == "reconstruction"


def test_demo_interrupted_before_writing_says_nothing_is_written(tmp_path, capsys, monkeypatch):
    import rsocl.cli.demo as demo

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(demo, "run_reconstruction", interrupted)
    out = tmp_path / "demo"
    assert main(["demo", "--shape", "12", "12", "--out", str(out), "--quiet"]) == 130
    assert capsys.readouterr().err == "rsocl demo: interrupted: nothing written\n"
    assert not (out / "demo.h5").exists()


@pytest.mark.parametrize(
    "run",
    [
        pytest.param([], id="one-piece"),
        pytest.param(["--tile", "6", "6"], id="tiles"),
        pytest.param(["--window", "1"], id="stream"),
    ],
)
def test_an_out_named_as_the_tuning_plot_is_refused_before_anything_runs(captures, tmp_path, capsys, monkeypatch, run):
    import rsocl.solver.reconstruct as solver

    def computed(*args, **kwargs):
        raise AssertionError("computed before the outputs were checked")

    monkeypatch.setattr(solver, "reconstruct", computed)
    cap, stream = captures
    out, gif = tmp_path / "tp-tuning.png", tmp_path / "tp.gif"
    argv = ["reconstruct", str(stream if "--window" in run else cap), "--out", str(out), "--gif", str(gif), *run]
    assert main([*argv, "--iterations", "2"]) == 2
    assert capsys.readouterr().err == (
        "rsocl reconstruct: error: --out must name an HDF5 file (.h5, .hdf5, .hdf, .he5) or a Zarr store (.zarr), "
        f"got {str(out)!r}\n"
    )
    assert list(tmp_path.iterdir()) == []


def test_with_fixed_parameters_no_plot_is_drawn(captures, tmp_path, capsys):
    cap, _ = captures
    out, gif = tmp_path / "tp.h5", tmp_path / "tp.gif"
    argv = ["reconstruct", str(cap), "--out", str(out), "--gif", str(gif), "--iterations", "2", "--fixed", "--quiet"]
    assert main(argv) == 0
    assert h5py.is_hdf5(out) and gif.is_file() and sorted(p.name for p in tmp_path.iterdir()) == ["tp.gif", "tp.h5"]


def _interrupt(monkeypatch, module, name):
    """``module.name`` raising a bare KeyboardInterrupt (Ctrl-C in that step)."""

    def stopped(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(module, name, stopped)


@pytest.mark.parametrize("step", ["check_outputs", "load_capture", "save_result"])
def test_reconstruct_interrupted_before_its_file_is_in_place_says_nothing_is_written(
    captures, tmp_path, capsys, monkeypatch, step
):
    import rsocl.cli.reconstruct as reconstruct
    import rsocl.files.hdf5 as hdf5

    cap, _ = captures
    out = tmp_path / "rec.h5"
    argv = ["reconstruct", str(cap), "--out", str(out), "--iterations", "2", "--fixed", "--quiet"]
    assert main(argv) == 0
    before = out.read_bytes()
    _interrupt(monkeypatch, hdf5 if step == "load_capture" else reconstruct, step)
    capsys.readouterr()
    assert main(argv) == 130
    assert capsys.readouterr().err == f"rsocl reconstruct: interrupted: nothing written, {out} unchanged\n"
    assert out.read_bytes() == before and not list(tmp_path.glob("rec.earlier-*"))


@pytest.mark.parametrize("run", IN_PIECES)
def test_a_tiled_or_streamed_run_interrupted_while_its_file_is_saved_says_nothing_is_written(
    captures, tmp_path, capsys, monkeypatch, run
):
    import rsocl.cli.tiled_run as tiled_run

    out = tmp_path / "rec.h5"
    argv = _in_pieces(captures, out, run)
    assert main(argv) == 0
    before = out.read_bytes()
    _interrupt(monkeypatch, tiled_run, "save_result")
    capsys.readouterr()
    assert main(argv) == 130
    assert capsys.readouterr().err == f"rsocl reconstruct: interrupted: nothing written, {out} unchanged\n"
    assert out.read_bytes() == before and not list(tmp_path.glob("rec.earlier-*"))


@pytest.mark.parametrize("step", ["scene_datacube", "save_capture"])
def test_simulate_interrupted_says_nothing_is_written(tmp_path, capsys, monkeypatch, step):
    import rsocl.cli.simulate as simulate
    import rsocl.files.hdf5 as hdf5

    out = tmp_path / "s.h5"
    argv = ["simulate", "builtin", "--out", str(out), "--shape", "12", "12", "--quiet"]
    assert main(argv) == 0
    before = out.read_bytes()
    _interrupt(monkeypatch, hdf5 if step == "save_capture" else simulate, step)
    capsys.readouterr()
    assert main(argv) == 130
    assert capsys.readouterr().err == f"rsocl simulate: interrupted: nothing written, {out} unchanged\n"
    assert out.read_bytes() == before
