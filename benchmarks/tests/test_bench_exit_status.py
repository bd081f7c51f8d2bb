"""The timing scripts that measure in child processes: a failed child fails the script and leaves the table."""

import pytest

import bench_deconvolve
import bench_forward
import bench_infinity_disparity
import bench_rotation

# each runs one child (two for the rotation's pair) on arguments that the child refuses
FAILING = {
    "deconvolve": (bench_deconvolve, ["--quick", "--devices", "nodevice", "--cases", "tv"]),
    "forward": (bench_forward, ["--shape", "3", "3", "--variants", "grid_sample", "--device", "cpu"]),
    "infinity": (bench_infinity_disparity, ["--shape", "3", "3", "--n-times", "4", "--infinity-disparity", "0",
                                            "--engine", "torch", "--device", "cpu"]),
    "rotation": (bench_rotation, ["--shape", "3", "3", "--n-times", "4", "--infinity-disparity", "0",
                                  "--device", "cpu"]),
}


@pytest.mark.parametrize("name", FAILING)
def test_a_failed_run_exits_1_and_keeps_the_table(name, tmp_path, capsys):
    script, argv = FAILING[name]
    table = tmp_path / "table.md"
    table.write_text("the last complete table\n")
    assert script.main([*argv, "--out", str(table)]) == 1
    assert table.read_text() == "the last complete table\n"
    assert "failed" in capsys.readouterr().err


def test_runs_that_all_succeed_exit_0_and_write_the_table(tmp_path, monkeypatch):
    monkeypatch.setenv("NAPARI_LFDEBLUR_NUMBA", "0")  # the torch version: no compilation in the children
    table = tmp_path / "table.md"
    argv = ["--shape", "3", "3", "12", "12", "1", "--n-times", "4", "--infinity-disparity", "0", "--repeats", "1",
            "--device", "cpu", "--out", str(table)]
    assert bench_rotation.main(argv) == 0
    assert "| 4 | +0.0 | 3-DOF |" in table.read_text() and "| 4 | +0.0 | 6-DOF |" in table.read_text()
