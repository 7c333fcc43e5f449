"""A run stopped anywhere and continued with --resume gives the bits of a run never stopped.

Each test runs the command line in fresh processes: a run straight through, and the same run
killed (SIGKILL: no handler runs, whatever was being written is cut) and resumed. The CSV
tables must be the same bytes, the GSD files the same chunks in every frame, and the last
checkpoint (the state at the run's end: positions, velocities, each circle's counts and
virial) the same arrays.
"""
import random
import signal

import gsd.fl
import numpy as np
import pytest
from process_util import run_cli, stop_with_ctrl_c


def rows(path):
    """Whole rows of a stats table written so far (0 before it exists)."""
    try:
        return max(path.read_bytes().count(b"\n") - 1, 0)
    except FileNotFoundError:
        return 0


def assert_same_gsd(a, b):
    """Two GSD files hold the same frames: every chunk of every frame, bit for bit."""
    with gsd.fl.open(str(a), "r") as x, gsd.fl.open(str(b), "r") as y:
        assert x.nframes == y.nframes
        names = x.find_matching_chunk_names("")
        assert names == y.find_matching_chunk_names("")
        for frame in range(x.nframes):
            for name in names:
                assert x.chunk_exists(frame, name) == y.chunk_exists(frame, name), (frame, name)
                if x.chunk_exists(frame, name):
                    u, v = x.read_chunk(frame, name), y.read_chunk(frame, name)
                    assert u.dtype == v.dtype and np.array_equal(u, v, equal_nan=True), (frame, name)


def scene_flags(scheme, boundary, precision, frames=40):
    # 600 circles at area fraction 0.4: some 30 collisions a circle over the run.
    return ["--n", "600", "--area-fraction", "0.4", "--radius", "0.01", "--speed", "0.5", "1.5", "--seed", "5",
            "--scheme", scheme, "--boundary", boundary, "--precision", precision, "--duration", str(frames / 10),
            "--fps", "10", "--out", "none", "--threads", "1"]


def straight_and_resumed(tmp_path, flags, data, stop_at, sig=signal.SIGKILL, says="continuing from frame"):
    """Run `flags` + `data` (file names, in tmp_path/straight and tmp_path/stopped) straight
    through, and again stopped with `sig` once its table holds `stop_at` rows, then resumed
    (saying `says` on stderr). Returns the two folders."""
    straight, stopped = tmp_path / "straight", tmp_path / "stopped"
    straight.mkdir()
    stopped.mkdir()
    done = run_cli(["run", *flags, *data], straight)
    assert done.returncode == 0, done.stderr
    code, _, err = stop_with_ctrl_c(["run", *flags, *data], stopped, lambda: rows(stopped / "run.csv") >= stop_at,
                                    poll=0.02, sig=sig)
    assert code == (-signal.SIGKILL if sig == signal.SIGKILL else 130), err
    resumed = run_cli(["run", *flags, *data, "--resume"], stopped)
    assert resumed.returncode == 0, resumed.stderr
    assert says in resumed.stderr
    return straight, stopped


def assert_same_checkpoints(a, b):
    from circles import checkpoint

    x, px = checkpoint.read(a)
    y, py = checkpoint.read(b)
    assert px == py
    fx, fy = x._fields(), y._fields()
    for name in ("pos", "vel", "pair_count", "wall_count", "virial", "wall_impulse", "time", "steps", "dt"):
        assert np.array_equal(fx[name], fy[name]), name
    assert x.stats()["pair_collisions"] > 5_000  # the run did collide


# Every pair of a scheme, a boundary and a precision in the default suite (the four cases of an
# orthogonal array); the other four in the slow one.
@pytest.mark.parametrize("scheme,boundary,precision", [
    ("event", "walls", "f64"), ("event", "periodic", "f32"), ("discrete", "walls", "f32"), ("discrete", "periodic", "f64"),
    *(pytest.param(*case, marks=pytest.mark.slow) for case in (("event", "walls", "f32"), ("event", "periodic", "f64"),
                                                               ("discrete", "walls", "f64"), ("discrete", "periodic", "f32")))])
def test_a_run_killed_at_a_random_moment_and_resumed_gives_the_same_bits(circles_cpu, tmp_path, scheme, boundary,
                                                                          precision):
    """SIGKILL once the table holds a random number of rows (the process is then simulating or
    writing), then --resume: the same table, trajectory and final state as a run never stopped."""
    stop_at = random.Random(f"{scheme}{boundary}{precision}").randrange(3, 30)
    data = ["--stats", "run.csv", "--trajectory", "run.gsd", "--checkpoint-every", "0.35"]
    straight, stopped = straight_and_resumed(tmp_path, scene_flags(scheme, boundary, precision), data, stop_at)
    assert (straight / "run.csv").read_bytes() == (stopped / "run.csv").read_bytes()
    assert_same_gsd(straight / "run.gsd", stopped / "run.gsd")
    assert_same_checkpoints(straight / "run.checkpoint.gsd", stopped / "run.checkpoint.gsd")


def test_a_table_without_a_trajectory_resumes_from_its_checkpoint(circles_cpu, tmp_path):
    """With --stats alone the checkpoint is the only restart point: rows after it are cut off
    and made again, the same."""
    data = ["--stats", "run.csv", "--checkpoint-every", "0.5"]
    straight, stopped = straight_and_resumed(tmp_path, scene_flags("event", "periodic", "f64"), data, 17)
    assert (straight / "run.csv").read_bytes() == (stopped / "run.csv").read_bytes()
    assert_same_checkpoints(straight / "run.checkpoint.gsd", stopped / "run.checkpoint.gsd")


def test_a_table_without_restart_points_starts_again_and_gives_the_same_rows(circles_cpu, tmp_path):
    data = ["--stats", "run.csv"]
    straight, stopped = straight_and_resumed(tmp_path, scene_flags("event", "walls", "f64", frames=15), data, 6,
                                             says="the run starts again from the beginning")
    assert (straight / "run.csv").read_bytes() == (stopped / "run.csv").read_bytes()


def test_a_run_stopped_by_ctrl_c_keeps_a_checkpoint_where_it_stopped(circles_cpu, tmp_path):
    """Ctrl-C stops between two frames and leaves a checkpoint there: --resume goes on from it,
    not from the last periodic one, and gives the same bits."""
    data = ["--stats", "run.csv", "--checkpoint-every", "100"]  # no checkpoint but at the stop and the end
    straight, stopped = straight_and_resumed(tmp_path, scene_flags("event", "walls", "f64"), data, 9,
                                             sig=signal.SIGINT)
    assert (straight / "run.csv").read_bytes() == (stopped / "run.csv").read_bytes()
    assert_same_checkpoints(straight / "run.checkpoint.gsd", stopped / "run.checkpoint.gsd")


KILL_WHILE_WRITING = """
import os, signal, sys
import circles.cli, circles.trajectory, circles.writers
what, at = sys.argv[1], int(sys.argv[2])
if what == "frame":
    write = circles.trajectory.GSDWriter.write
    def cut(self, sim, row=None, stats=None):
        if self.frames == at:  # the first chunks of this frame written, flushed, then the kill
            self._file.write_chunk("configuration/step", __import__("numpy").array([sim.steps], "uint64"))
            self._file.flush()
            os.kill(os.getpid(), signal.SIGKILL)
        write(self, sim, row, stats)
    circles.trajectory.GSDWriter.write = cut
else:
    write = circles.writers.StatsWriter.write
    def cut(self, row):
        if self.rows == at:  # half a row on disk, then the kill
            self._file.write("0.5,12"); self._file.flush()
            os.kill(os.getpid(), signal.SIGKILL)
        write(self, row)
    circles.writers.StatsWriter.write = cut
sys.exit(circles.cli.main(sys.argv[3:]))
"""


@pytest.mark.parametrize("what", ["frame", "row"])
def test_a_run_killed_while_writing_leaves_files_that_resume_accepts(circles_cpu, tmp_path, what):
    """Killed halfway through a GSD frame, or through a table's row: --resume drops the part
    written and gives the same files as a run never stopped."""
    flags = [*scene_flags("event", "periodic", "f64", frames=20), "--stats", "run.csv", "--trajectory", "run.gsd"]
    straight, stopped = tmp_path / "straight", tmp_path / "stopped"
    straight.mkdir()
    stopped.mkdir()
    assert run_cli(["run", *flags], straight).returncode == 0
    killed = run_cli([what, "11", "run", *flags], stopped, python=("-c", KILL_WHILE_WRITING))
    assert killed.returncode == -signal.SIGKILL
    resumed = run_cli(["run", *flags, "--resume"], stopped)
    assert resumed.returncode == 0, resumed.stderr
    assert (straight / "run.csv").read_bytes() == (stopped / "run.csv").read_bytes()
    assert_same_gsd(straight / "run.gsd", stopped / "run.gsd")


def test_a_finished_run_is_made_longer_with_a_longer_duration(circles_cpu, tmp_path):
    """A run that ended on a frame instant goes on from its last checkpoint to a longer
    --duration, as if it had been given that duration at the start."""
    flags = scene_flags("event", "walls", "f64", frames=12)
    data = ["--stats", "run.csv", "--trajectory", "run.gsd", "--checkpoint-every", "1"]
    longer = [*flags[:-8], "--duration", "2.4", *flags[-6:]]
    assert flags[-8] == "--duration"
    straight, stopped = tmp_path / "straight", tmp_path / "stopped"
    straight.mkdir()
    stopped.mkdir()
    assert run_cli(["run", *longer, *data], straight).returncode == 0
    assert run_cli(["run", *flags, *data], stopped).returncode == 0
    assert rows(stopped / "run.csv") == 12
    again = run_cli(["run", *longer, *data, "--resume"], stopped)
    assert again.returncode == 0, again.stderr
    assert "continuing from frame 12" in again.stderr
    assert (straight / "run.csv").read_bytes() == (stopped / "run.csv").read_bytes()
    assert_same_gsd(straight / "run.gsd", stopped / "run.gsd")


@pytest.fixture(scope="module")
def finished(tmp_path_factory):
    """A finished run's files, for the refusals."""
    where = tmp_path_factory.mktemp("finished")
    done = run_cli(["run", *scene_flags("event", "walls", "f64", frames=5), "--stats", "run.csv",
                    "--trajectory", "run.gsd", "--checkpoint-every", "0.2"], where)
    assert done.returncode == 0, done.stderr
    return where


@pytest.mark.parametrize("change,words", [
    (["--seed", "6"], "holds a run made with seed 5, and this run has 6"),
    (["--fps", "20"], "holds a run made with fps 10.0, and this run has 20.0"),
    (["--precision", "f32"], "holds a run made with precision \"f64\", and this run has \"f32\""),
    (["--order"], "holds a run made with order false, and this run has true"),
    (["--force"], "--resume continues the files of a run, and --force would overwrite them"),
    (["--out", "run.mp4"], "a video cannot be continued: drop --out run.mp4, or give --out none"),
    (["--duration", "0.3"], "beyond this --duration 0.3 s: give a --duration of at least 0.5"),
])
def test_resume_refuses_files_of_another_run(finished, change, words):
    """One line naming the difference, exit status 2, and the files as they were."""
    before = {p.name: p.read_bytes() for p in finished.iterdir()}
    flags = scene_flags("event", "walls", "f64", frames=5)
    for k in range(0, len(change), 2):  # a changed flag replaces the scene's
        if change[k] in flags and k + 1 < len(change) and not change[k + 1].startswith("--"):
            flags[flags.index(change[k]) + 1] = change[k + 1]
        else:
            flags += change[k:k + 2] if k + 1 < len(change) and not change[k + 1].startswith("--") else [change[k]]
    done = run_cli(["run", *flags, "--stats", "run.csv", "--trajectory", "run.gsd", "--resume"], finished)
    assert done.returncode == 2, done.stderr
    assert words in done.stderr
    assert done.stderr.count("\n") == 1
    assert {p.name: p.read_bytes() for p in finished.iterdir()} == before


def test_resume_refuses_when_there_is_nothing_to_resume(circles_cpu, tmp_path):
    flags = scene_flags("event", "walls", "f64", frames=5)
    done = run_cli(["run", *flags, "--stats", "run.csv", "--resume"], tmp_path)
    assert done.returncode == 2
    assert "--stats run.csv does not exist, so there is no run to continue: drop --resume" in done.stderr
    done = run_cli(["run", *flags, "--resume"], tmp_path)
    assert done.returncode == 2
    assert "--resume continues a run's --stats and --trajectory files: give those the run wrote" in done.stderr
    done = run_cli(["run", *flags, "--checkpoint-every", "0.5"], tmp_path)
    assert done.returncode == 2
    assert "--checkpoint-every keeps a restart point of a run's --stats and --trajectory files" in done.stderr
    done = run_cli(["run", *flags, "--stats", "run.csv", "--checkpoint-every", "0"], tmp_path)
    assert done.returncode == 2
    assert "--checkpoint-every 0.0 must be a positive number" in done.stderr
    assert list(tmp_path.iterdir()) == []


def test_a_new_run_refuses_an_earlier_runs_checkpoint_unless_forced(finished, tmp_path):
    (tmp_path / "run.checkpoint.gsd").write_bytes((finished / "run.checkpoint.gsd").read_bytes())
    flags = scene_flags("event", "walls", "f64", frames=5)
    done = run_cli(["run", *flags, "--stats", "run.csv"], tmp_path)
    assert done.returncode == 2
    assert "run.checkpoint.gsd exists, a checkpoint of an earlier run: give --resume" in done.stderr
    done = run_cli(["run", *flags, "--stats", "run.csv", "--force"], tmp_path)
    assert done.returncode == 0, done.stderr
    assert not (tmp_path / "run.checkpoint.gsd").exists()  # removed: it was not of this run
