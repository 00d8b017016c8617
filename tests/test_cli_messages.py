"""Messages of the command line: a time in µs that no sensor has is said once, in µs, naming the option;
each warning once per command; an option of a regularizer named as typed; the result line under --quiet;
the formats --out names."""

import pytest

from rsocl.cli.main import main


@pytest.mark.parametrize(
    "argv, said",
    [
        (["info", "--t-r-us", "5000"], "--t-r-us 5000 µs is 5 ms per row, longer than 1 ms"),
        (["info", "--t-e-us", "2e6"], "--t-e-us 2e+06 µs is 2 s, longer than 1 s"),
        (["plan", "--shape", "8", "8", "--t-r-us", "5000", "--no-measure"], "--t-r-us 5000 µs is 5 ms per row"),
    ],
)
def test_an_unlikely_time_in_us_is_said_once_in_us_naming_the_option(capsys, argv, said):
    assert main(argv) == 0
    warned = [line for line in capsys.readouterr().err.splitlines() if "warning" in line]
    assert len(warned) == 1 and said in warned[0], warned
    assert "did you mean" not in warned[0] and "t_r=" not in warned[0]


def test_a_rig_files_unlikely_time_is_said_once_however_often_the_rig_is_built(tmp_path, capsys):
    rig = tmp_path / "rig.toml"
    camera = '[[camera]]\nbackend = "simulated"\nt_e = 1.0e-04\nt_r = 5\n'
    rig.write_text("[rig]\nshape = [8, 8]\n" + camera, encoding="utf-8")
    assert main(["capture", "--rig", str(rig), "--out", str(tmp_path / "c.h5"), "--sets", "1", "--quiet"]) == 0
    warned = [line for line in capsys.readouterr().err.splitlines() if "warning" in line]
    assert len(warned) == 1 and "camera t_r = 5 s" in warned[0], warned


def test_an_option_of_the_regularizer_is_named_as_typed(tmp_path, capsys):
    assert main(["simulate", "builtin", "--out", str(tmp_path / "c.h5"), "--shape", "8", "8", "--quiet"]) == 0
    argv = ["reconstruct", str(tmp_path / "c.h5"), "--out", str(tmp_path / "r.h5"), "--tv-iterations", "0"]
    assert main(argv) == 2
    assert capsys.readouterr().err.endswith("error: --tv-iterations must be in [1, 100000], got 0\n")


def test_simulate_says_its_result_line_under_quiet(tmp_path, capsys):
    assert main(["simulate", "builtin", "--out", str(tmp_path / "c.h5"), "--shape", "8", "8", "--quiet"]) == 0
    assert capsys.readouterr().out == f"wrote {tmp_path / 'c.h5'}: 4 snapshots of 8x8, T = 13\n"


@pytest.mark.parametrize("name, ok", [("r.txt", False), ("r", False), ("r.hdf5", True), ("r.H5", True)])
def test_reconstruct_out_names_an_hdf5_file_or_a_zarr_store(tmp_path, capsys, name, ok):
    assert main(["simulate", "builtin", "--out", str(tmp_path / "c.h5"), "--shape", "8", "8", "--quiet"]) == 0
    argv = ["reconstruct", str(tmp_path / "c.h5"), "--out", str(tmp_path / name), "--iterations", "2", "--fixed"]
    assert main(argv + ["--quiet"]) == (0 if ok else 2)
    err = capsys.readouterr().err
    assert ok or "--out must name an HDF5 file (.h5, .hdf5, .hdf, .he5) or a Zarr store (.zarr)" in err, err
    assert (tmp_path / name).exists() == ok
