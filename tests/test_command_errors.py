"""Every command keeps its promise on bad input and unwritable destinations: exit status 2 and
one line on stderr, before any work (no simulation, no Dask cluster), and no file or folder
left behind. `/proc` stands for a folder where nothing can be created, whoever runs the tests;
a read-only mount, where the machine allows one, for the real case."""

import subprocess
import textwrap

import pytest

from circles import cli
from circles.kernel_cache import MESSAGE
from process_util import run_cli

SWEEP = textwrap.dedent("""
    [scene]
    n = 40
    radius = 0.5
    mass = "equal"
    boundary = "periodic"

    [vary]
    area_fraction = [0.2]

    [sweep]
    repeats = 1
    equilibrate = 0.5
    measure = 1.0
    blocks = 2
""")
SCENE = "n = 40\nradius = 0.1\n"
STATS = "time,kinetic_energy\n"  # a header that is not a stats table's: never read that far


def _one_line(result, starts="circles"):
    """The single line of stderr (the compile notice, a courtesy, aside)."""
    lines = [line for line in result.stderr.strip().splitlines() if line != MESSAGE]
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith(starts) and "Traceback" not in result.stderr
    return lines[0]


@pytest.fixture
def read_only(tmp_path):
    """A read-only folder (a tmpfs mounted read-only) holding a stats table, or a skip where this
    machine mounts nothing."""
    folder = tmp_path / "ro"
    folder.mkdir()
    staging = tmp_path / "staging"
    staging.mkdir()
    mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", "ro", "tmpfs", str(folder)], capture_output=True)
    if mounted.returncode != 0:
        pytest.skip("this machine mounts no read-only folder here")
    try:
        yield folder
    finally:
        subprocess.run(["umount", str(folder)], capture_output=True)


@pytest.fixture
def stats_table(tmp_path):
    """A real stats table, from a short measuring run."""
    done = run_cli(["run", "--n", "20", "--box", "3", "3", "--radius", "0.1", "--duration", "0.5", "--fps", "4",
                    "--out", "none", "--stats", "run.csv", "--arch", "cpu"], tmp_path)
    assert done.returncode == 0, done.stderr
    return tmp_path / "run.csv"


def test_plot_into_a_folder_that_cannot_be_written(stats_table, tmp_path):
    result = run_cli(["plot", str(stats_table), "--out", "/proc/run.png"], tmp_path)
    assert result.returncode == 2
    line = _one_line(result, "circles plot: error:")
    assert "--out /proc/run.png" in line and "cannot write in the folder /proc" in line


def test_plot_into_a_read_only_folder(stats_table, tmp_path, read_only):
    result = run_cli(["plot", str(stats_table), "--out", str(read_only / "run.png")], tmp_path)
    assert result.returncode == 2
    assert "Read-only file system" in _one_line(result, "circles plot: error:")


def test_plot_out_under_a_file_names_the_file(stats_table, tmp_path):
    (tmp_path / "a_file").write_text("x")
    result = run_cli(["plot", str(stats_table), "--out", "a_file/x.png"], tmp_path)
    assert result.returncode == 2
    assert "a_file is a file, not a folder" in _one_line(result, "circles plot: error:")


def test_plot_makes_the_folders_of_out_as_run_does(stats_table, tmp_path):
    result = run_cli(["plot", str(stats_table), "--out", "new/deeper/run.png"], tmp_path)
    assert result.returncode == 0, result.stderr
    assert (tmp_path / "new" / "deeper" / "run.png").stat().st_size > 1000


def test_a_refused_plot_leaves_no_folder(tmp_path):
    (tmp_path / "run.csv").write_text(STATS)
    result = run_cli(["plot", "run.csv", "--out", "new/run.png"], tmp_path)
    assert result.returncode == 2
    assert "not a stats table" in _one_line(result, "circles plot: error:")
    assert not (tmp_path / "new").exists()


def test_sweep_into_an_unwritable_folder_starts_no_cluster(tmp_path):
    (tmp_path / "small.toml").write_text(SWEEP)
    result = run_cli(["sweep", "small.toml", "--out", "/proc/sweep"], tmp_path, timeout=60)
    assert result.returncode == 2
    line = _one_line(result, "circles: error:")
    assert "--out /proc/sweep" in line and "cannot make the folder" in line
    assert result.stdout == ""  # no "sweep ... on a local cluster" line: nothing started


def test_sweep_into_a_read_only_folder(tmp_path, read_only):
    (tmp_path / "small.toml").write_text(SWEEP)
    result = run_cli(["sweep", "small.toml", "--out", str(read_only / "sweep")], tmp_path, timeout=60)
    assert result.returncode == 2 and result.stdout == ""
    assert "Read-only file system" in _one_line(result, "circles: error:")


@pytest.mark.parametrize("flag, name", [("--trajectory", "run.gsd"), ("--stats", "run.csv"), ("--out", "run.gif")])
def test_run_into_an_unwritable_folder_is_bad_input(flag, name, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert cli.main(["run", "--n", "20", flag, f"/proc/{name}"]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    line = captured.err.strip()
    assert "\n" not in line and line.startswith("circles: error:") and f"/proc/{name}" in line


def test_dt_zero_says_how_on_the_command_line(capsys):
    assert cli.main(["run", "--dt", "0"]) == 2
    line = capsys.readouterr().err.strip()
    assert "dt = 0 must be > 0" in line and "leave dt out" in line and "None" not in line


def test_a_sweep_file_given_to_run_is_named_as_one(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "small.toml").write_text(SWEEP)
    assert cli.main(["run", "small.toml"]) == 2
    line = capsys.readouterr().err.strip()
    assert "small.toml is a sweep file" in line and "circles sweep small.toml" in line


def test_a_scene_file_given_to_sweep_is_named_as_one(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "scene.toml").write_text(SCENE)
    assert cli.main(["sweep", "scene.toml"]) == 2
    line = capsys.readouterr().err.strip()
    assert "scene.toml is a scene file" in line and "circles run" in line


def test_a_first_run_says_once_on_stderr_that_kernels_compile(tmp_path):
    """Not a terminal (a pipe), an empty Taichi cache: the notice comes once, then not again."""
    args = ["run", "--n", "20", "--box", "3", "3", "--radius", "0.1", "--duration", "0.2", "--out", "none",
            "--arch", "cpu"]
    cache = {"TI_OFFLINE_CACHE_FILE_PATH": str(tmp_path / "cache")}
    first = run_cli(args, tmp_path, extra_env=cache, timeout=300)
    assert first.returncode == 0, first.stderr
    assert first.stderr.splitlines().count(MESSAGE) == 1
    again = run_cli(args, tmp_path, extra_env=cache, timeout=300)
    assert again.returncode == 0 and MESSAGE not in again.stderr
