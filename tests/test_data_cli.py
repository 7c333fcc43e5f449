"""`circles run --stats --trajectory --out none --force` and `circles plot`, end to end in a
subprocess: files read back with gsd.hoomd, bad paths refused before any simulating, a run
stopped by Ctrl-C leaves whole rows and frames."""

import gsd.hoomd
import numpy as np
import pytest

from circles import observables
from circles.writers import read_stats
from process_util import run_cli, stop_with_ctrl_c

SMALL = ["--n", "30", "--box", "4", "3", "--radius", "0.1", "--speed", "0.5", "1", "--arch", "cpu"]


def test_a_measuring_run_writes_rows_and_frames_and_no_video(tmp_path):
    result = run_cli(["run", *SMALL, "--boundary", "periodic", "--duration", "1", "--fps", "4", "--out", "none",
                      "--stats", "data/run.csv", "--trajectory", "data/run.gsd"], tmp_path)
    assert result.returncode == 0, result.stderr
    assert sorted(p.name for p in tmp_path.rglob("*") if p.is_file()) == ["run.csv", "run.gsd"]
    columns = read_stats(tmp_path / "data" / "run.csv")
    assert list(columns) == list(observables.COLUMNS)
    np.testing.assert_array_equal(columns["time"], [0.25, 0.5, 0.75, 1.0])
    assert np.all(np.isnan(columns["wall_pressure"])) and np.all(columns["compressibility"] > 1)
    with gsd.hoomd.open(str(tmp_path / "data" / "run.gsd")) as traj:
        assert len(traj) == 4
        times = [frame.log["circles/time"][0] for frame in traj]
        assert times == [0.0, 0.25, 0.5, 0.75]
        # Frame k carries the row of the interval that ends at its instant.
        assert traj[2].log["circles/pressure"][0] == columns["pressure"][1]
        assert np.isnan(traj[0].log["circles/pressure"][0])
    assert "wrote       data/run.gsd (4 GSD frames" in result.stdout
    assert "wrote       data/run.csv (4 rows)" in result.stdout
    assert "trajectory" in result.stdout.split("wall time")[1].splitlines()[0]


@pytest.mark.parametrize("args, words", [
    (["--stats", "run.txt"], ["--stats run.txt", ".csv"]),
    (["--trajectory", "run.xyz"], ["--trajectory run.xyz", ".gsd"]),
    (["--stats", "taken.csv"], ["taken.csv exists", "--force"]),
    (["--trajectory", "file/run.gsd"], ["file is a file"]),
    (["--stats", "folder.csv"], ["folder.csv is a folder"]),
])
def test_bad_data_paths_are_refused_before_simulating(tmp_path, args, words):
    (tmp_path / "taken.csv").write_text("kept\n")
    (tmp_path / "file").write_text("")
    (tmp_path / "folder.csv").mkdir()
    result = run_cli(["run", *SMALL, "--duration", "0.2", "--out", "none", *args], tmp_path)
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("circles: error:")
    for word in words:
        assert word in lines[0]
    assert (tmp_path / "taken.csv").read_text() == "kept\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file", "folder.csv", "taken.csv"]


def test_force_overwrites(tmp_path):
    (tmp_path / "run.csv").write_text("old\n")
    (tmp_path / "run.gsd").write_text("old\n")
    result = run_cli(["run", *SMALL, "--duration", "0.2", "--fps", "10", "--out", "none", "--stats", "run.csv",
                      "--trajectory", "run.gsd", "--force"], tmp_path)
    assert result.returncode == 0, result.stderr
    assert len(read_stats(tmp_path / "run.csv")["time"]) == 2
    with gsd.hoomd.open(str(tmp_path / "run.gsd")) as traj:
        assert len(traj) == 2


def test_ctrl_c_leaves_whole_rows_and_frames(tmp_path):
    table = tmp_path / "run.csv"
    returncode, stdout, stderr = stop_with_ctrl_c(
        ["run", *SMALL, "--boundary", "periodic", "--duration", "1000", "--fps", "50", "--out", "none",
         "--stats", "run.csv", "--trajectory", "run.gsd"], tmp_path,
        lambda: table.exists() and table.read_text().count("\n") > 4)
    assert returncode == 130, stderr
    assert "Traceback" not in stderr
    text = table.read_text()
    assert text.endswith("\n") and all(line.count(",") == len(observables.COLUMNS) - 1 for line in text.splitlines())
    rows = read_stats(table)
    with gsd.hoomd.open(str(tmp_path / "run.gsd")) as traj:
        frames = len(traj)
        last = traj[frames - 1]
        assert last.particles.position.shape == (30, 3)
    # Frame k is written before interval k is simulated, its row after: a stop between the two
    # leaves one frame more than rows.
    assert frames - 1 <= len(rows["time"]) <= frames
    assert last.log["circles/time"][0] == pytest.approx((frames - 1) / 50)


def test_plot_draws_a_png(tmp_path):
    result = run_cli(["run", *SMALL, "--duration", "0.5", "--fps", "10", "--out", "none", "--stats", "run.csv"],
                     tmp_path)
    assert result.returncode == 0, result.stderr
    result = run_cli(["plot", "run.csv", "--out", "fig.png"], tmp_path)
    assert result.returncode == 0, result.stderr
    import imageio.v3 as iio
    image = iio.imread(tmp_path / "fig.png")
    assert image.shape[0] > 500 and image.shape[1] > 500
    assert image[..., :3].std() > 10  # drawn, not blank
    result = run_cli(["plot", "missing.csv"], tmp_path)
    assert result.returncode == 2 and "missing.csv" in result.stderr and len(result.stderr.splitlines()) == 1
    result = run_cli(["plot", "run.csv", "--out", "fig.jpg"], tmp_path)
    assert result.returncode == 2 and ".png" in result.stderr


def test_plot_without_matplotlib_gives_a_hint(tmp_path):
    (tmp_path / "run.csv").write_text(",".join(observables.COLUMNS) + "\n")
    hide = ("-c", "import sys; sys.modules['matplotlib'] = None; from circles.cli import main; "
                  "sys.exit(main(sys.argv[1:]))")
    done = run_cli(["plot", "run.csv"], tmp_path, python=hide, timeout=60)
    assert done.returncode == 2
    assert done.stderr.strip().splitlines() == ["circles: error: circles plot needs matplotlib: pip install "
                                                "'circles-sim[plot]' (or pip install matplotlib)"]
