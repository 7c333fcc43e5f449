"""The command line: a run end to end in a subprocess, and bad input refused at once.

A run of duration T at F frames per second writes ceil(T * F) frames: t = 0 is the first,
t = T is simulated but not drawn (see circles.cli).
"""

import math
import subprocess
import sys
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest

import circles
from circles import cli
from conftest import TEST_ARCH
from process_util import run_cli, stop_with_ctrl_c

ROOT = Path(__file__).resolve().parents[1]
SMALL = ["--n", "30", "--box", "4", "3", "--radius", "0.1", "--speed", "0.5", "1",
         "--size", "80x60", "--arch", "cpu"]


def test_run_writes_a_gif_of_duration_times_fps_frames(tmp_path):
    result = run_cli(["run", *SMALL, "--duration", "0.5", "--fps", "10",
                      "--out", "out/run.gif"], tmp_path)
    assert result.returncode == 0, result.stderr
    gif = iio.imread(tmp_path / "out" / "run.gif", index=None)
    assert gif.shape[:3] == (5, 60, 80)
    summary = result.stdout
    for word in ("circles", "30", "steps", "circle-steps/s", "collisions", "energy",
                 "overlap", "run.gif"):
        assert word in summary
    assert "simulated   0.5 s" in summary
    assert "circle-steps/s (median of 5 frames' simulation)" in summary
    assert "Starting on arch" not in summary  # ti.init's line: the summary names the arch


def test_throughput_leaves_out_the_frames_of_first_calls():
    """The summary's speed: with MEDIAN_FRAMES frames that took steps or more, the median of
    their speeds, so that a frame that paid for a kernel's first call (a second or more) does
    not hide the speed of a short run; with fewer, all steps over all the time. The progress
    bar's: the median of the last RECENT_FRAMES frames'."""
    from circles.cli import MEDIAN_FRAMES, RECENT_FRAMES, Speeds

    frames = [(9, 1.5)] + [(9, 0.001)] * 4 + [(8, 0.002), (0, 0.0), (9, 0.4)]
    speeds = Speeds(1000)
    assert speeds.recent() == 0.0
    assert speeds.summary() == (0.0, "simulation only, the kernels' first calls included")
    for k, (steps, seconds) in enumerate(frames):
        speeds.add(steps, seconds)
        if k == 2:
            rate, covers = speeds.summary()
            assert rate == pytest.approx(27 * 1000 / 1.502, rel=1e-12) and "first calls included" in covers
            assert speeds.recent() == 9e6  # the median of 6000 and twice 9e6
    assert MEDIAN_FRAMES == 5 and speeds.summary() == (9e6, "median of 7 frames' simulation")
    for _ in range(RECENT_FRAMES):
        speeds.add(2, 0.001)
    assert speeds.recent() == 2e6 and speeds.summary()[0] == 2e6


def test_one_pixel_sides_make_png_frames_as_the_canvas_does(tmp_path):
    """PNG frames (and GIFs) take any size the canvas draws, 1 pixel a side included; an MP4
    refuses odd sides with its own message."""
    small = [a if a != "80x60" else "1x3" for a in SMALL]
    result = run_cli(["run", *small, "--duration", "0.2", "--fps", "10", "--out", "frames"], tmp_path)
    assert result.returncode == 0, result.stderr
    pngs = sorted((tmp_path / "frames").glob("frame_*.png"))
    assert len(pngs) == 2 and iio.imread(pngs[0]).shape == (3, 1, 3)
    result = run_cli(["run", *small, "--duration", "0.2", "--fps", "10", "--out", "one.mp4"], tmp_path)
    assert result.returncode == 2 and "even" in result.stderr


def test_scene_file_with_flags_overriding_it(tmp_path):
    (tmp_path / "scene.toml").write_text(
        'n = 20\nbox = [4.0, 3.0]\nradius = 0.1\nspeed = [0.5, 1.0]\nmass = "equal"\n'
        'boundary = "periodic"\n\n'
        '[run]\nduration = 0.4\nfps = 5\nsize = "64x48"\ncolor = "speed"\n'
        'out = "frames"\narch = "cpu"\nthreads = 1\n')
    result = run_cli(["run", "scene.toml", "--fps", "10"], tmp_path)
    assert result.returncode == 0, result.stderr
    pngs = sorted((tmp_path / "frames").glob("frame_*.png"))
    assert len(pngs) == 4  # 0.4 s at 10 (the flag), not 5 (the file), frames per second
    assert iio.imread(pngs[0]).shape == (48, 64, 3)
    assert "20 (event, f64, periodic, cpu, 1 thread)" in result.stdout


def test_ctrl_c_stops_and_keeps_a_playable_file(tmp_path):
    out = tmp_path / "long.gif"
    returncode, stdout, stderr = stop_with_ctrl_c(
        ["run", *SMALL, "--duration", "1000", "--fps", "10", "--out", str(out)], tmp_path,
        lambda: out.exists() and out.stat().st_size > 2000, poll=0.2)  # past a frame or two
    assert returncode == 130, stderr
    assert "Traceback" not in stderr
    assert "stopped by Ctrl-C" in stdout
    frames = iio.imread(out, index=None)
    assert frames.shape[0] >= 1 and frames.shape[1:3] == (60, 80)


@pytest.mark.parametrize("args, words", [
    (["run", "--n", "-5"], ["n = -5"]),
    (["run", "--n", "many"], ["--n", "many"]),
    (["run", "--mass", "heavy"], ["--mass", "heavy", "radius"]),
    (["run", "--radius", "1", "2", "3"], ["--radius", "3 values"]),
    (["run", "--radius", "0.5", "0.1"], ["radius", "below"]),
    (["run", "--n", "100000", "--radius", "0.5"], ["area fraction"]),
    (["run", "--size", "1280"], ["size", "1280", "WxH"]),
    (["run", "--size", "0x720"], ["size", "0x720"]),
    (["run", "--fps", "0"], ["fps", "0"]),
    (["run", "--duration", "-1"], ["duration", "-1"]),
    (["run", "--threads", "-1"], ["threads", "-1", ">= 0"]),
    (["run", "--threads", "two"], ["--threads", "two"]),
    (["run", "--threads", "100000"], ["threads", "100000", "at most"]),
    (["run", "--bogus"], ["--bogus"]),
    (["fly"], ["fly"]),
    (["run", "missing.toml"], ["missing.toml", "not found"]),
    (["run", "--out", "run.gif", "--fps", "60"], ["GIF", "50"]),
    # A GIF delay is two bytes of hundredths of a second: at most 655.35 s a frame.
    (["run", "--out", "run.gif", "--fps", "0.001"], ["GIF", "0.001", "100/65535", "--fps 0.00153"]),
    # ffmpeg takes the rate as a fraction of numbers up to 1001000, and the mp4 muxer a
    # frame's duration in 32 bits (see circles.video).
    (["run", "--out", "run.mp4", "--fps", "1e-9"], ["MP4", "1e-09", "0.0001", "--fps", "PNG"]),
    (["run", "--out", "run.mp4", "--fps", "2e6", "--duration", "1e-6"],
     ["MP4", "2e+06", "1000000", "--fps"]),
    (["run", "--out", "run.mp4", "--size", "65x37"], ["MP4", "even", "65x37", "64x36 or 66x38", ".gif"]),
    (["run", "--out", "run.mp4", "--size", "1x1"], ["MP4", "even", "1x1", "use --size 2x2, or"]),  # not 0x0
    (["run", "--out", "run.mp4", "--size", "16384x16384"], ["MP4", "16384x16384", "2**28", "--size"]),
    # A mistyped duration: 3e13 frames would fill the disk, and listing them the memory.
    (["run", "--duration", "1e12"], ["1e+12", "3e+13 frames", "1000000", "--duration", "--fps"]),
    (["run", "--duration", "1e300", "--fps", "1e300"], ["1e+300", "more frames than a float holds"]),
    # 5e30 steps would never end (checked once the scene is made, its default dt known).
    (["run", "--n", "20", "--dt", "1e-30", "--out", "q.gif"], ["5e+30 steps", "1e+10", "--dt", "--duration"]),
    (["run", "--n", "20", "--speed", "1e150", "--out", "q.gif"], ["steps", "1e+10", "--dt"]),
])
def test_bad_input_exits_2_with_one_line(args, words, capsys, monkeypatch, tmp_path):
    monkeypatch.chdir(tmp_path)
    assert cli.main(args) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("circles: error:"), captured.err
    for word in words:
        assert word in lines[0]


def test_bad_scene_file_values_exit_2(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    Path("bad.toml").write_text('n = 10\nscheme = "magic"\n')
    Path("broken.toml").write_text('n = = 3\n')
    Path("run_key.toml").write_text('n = 10\n[run]\nspeed = 3\n')
    Path("utf16.toml").write_bytes('n = 10\n'.encode("utf-16"))  # starts \xff\xfe
    for name, word in (("bad.toml", "magic"), ("broken.toml", "TOML"),
                       ("run_key.toml", "unknown [run] key"), ("utf16.toml", "not UTF-8")):
        assert cli.main(["run", name]) == 2
        error = capsys.readouterr().err.strip()
        assert len(error.splitlines()) == 1 and name in error and word in error


def test_unwritable_output_is_refused_before_simulating(tmp_path, capsys, monkeypatch):
    import circles

    def no_simulation(*args, **kwargs):
        raise AssertionError("the simulation started")

    monkeypatch.setattr(circles, "init", no_simulation)
    monkeypatch.setattr(circles, "Simulation", no_simulation)
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    # A GIF: the check must not depend on imageio-ffmpeg being installed (MP4 needs it).
    assert cli.main(["run", "--out", str(blocker / "run.gif")]) == 2
    error = capsys.readouterr().err.strip()
    assert len(error.splitlines()) == 1 and "cannot write" in error and "run.gif" in error


def test_help_exits_0(capsys):
    assert cli.main(["run", "--help"]) == 0
    assert "--radius" in capsys.readouterr().out


def test_version_prints_its_line_only(tmp_path):
    """Nothing but the version on stdout (no banner of Taichi's when it is imported)."""
    result = run_cli(["--version"], tmp_path)
    assert result.returncode == 0, result.stderr
    assert result.stdout.splitlines() == [cli.version_text()]


def test_version_names_the_package_and_what_it_runs_on(capsys):
    import platform
    import taichi

    assert cli.main(["--version"]) == 0
    out = capsys.readouterr().out.strip()
    assert out.startswith(f"circles {circles.__version__} (taichi ")
    assert ".".join(map(str, taichi.__version__)) in out and platform.python_version() in out, out


def test_frame_count_covers_the_duration():
    """One frame at each k / fps before the end: t = 0, 0.1, ..., 0.4 for 0.5 s at 10 fps."""
    assert cli.frame_count(0.5, 10) == 5
    assert cli.frame_count(5.0, 30) == 150
    assert cli.frame_count(1.05, 30) == 32  # a last, partial interval gets a frame
    assert cli.frame_count(1e-9, 30) == 1
    assert cli.check_frame_count(cli.MOST_FRAMES / 40, 40) == cli.MOST_FRAMES  # exact in binary
    with pytest.raises(cli.UsageError, match="1e\\+06 frames"):
        cli.check_frame_count(cli.MOST_FRAMES / 40 + 1, 40)


# ---- scene files that list their circles ([[circle]] tables) -------------------------
CRADLE = ROOT / "scenes" / "newtons_cradle.toml"
TWO_CIRCLES = ('box = [4.0, 3.0]\n'
               '[[circle]]\npos = [1.0, 1.5]\nvel = [1.0, 0.0]\nradius = 0.2\n'
               '[[circle]]\npos = [3.0, 1.5]\nvel = [0.0, 0.0]\nradius = 0.2\n')


def test_newtons_cradle_file_runs_end_to_end(tmp_path):
    """The cradle's hit is at t = 1: a run to t = 1.5 has the five collisions of one hit."""
    result = run_cli(["run", str(CRADLE), "--duration", "1.5", "--fps", "10",
                      "--size", "64x36", "--arch", "cpu", "--out", "cradle.gif"], tmp_path)
    assert result.returncode == 0, result.stderr
    gif = iio.imread(tmp_path / "cradle.gif", index=None)
    assert gif.shape[:3] == (15, 36, 64)
    assert "6 (event, f64, walls" in result.stdout
    assert "collisions  5 pair, 0 wall" in result.stdout


def test_read_circle_list_gives_an_exact_newtons_cradle(circles_cpu):
    """The cradle file read and simulated with from_arrays: the incoming circle (0) hits the
    row (1 to 5) at t = 1; at t = 2.5, before the last circle reaches the wall, only the
    last one moves, with exactly the incoming velocity, and the others rest."""
    from circles.scenefile import read_circle_list

    c = read_circle_list(CRADLE)
    assert c.n == 6 and c.box == (16.0, 9.0) and c.boundary == "walls"
    assert c.scheme == "event" and c.precision == "f64" and c.dt is None
    assert c.mass.tolist() == c.radius.tolist()  # mass model "radius"
    incoming = c.vel[0].copy()
    assert incoming.tolist() == [3.0, 0.0] and not c.vel[1:].any()
    sim = circles_cpu.Simulation.from_arrays(
        c.pos, c.vel, c.radius, mass=c.mass, box=c.box, boundary=c.boundary, scheme=c.scheme,
        precision=c.precision, dt=c.dt, color=c.color)
    sim.advance(2.5)
    s = sim.state()
    assert np.max(np.abs(s.vel[5] - incoming)) <= 1e-12
    assert np.max(np.abs(s.vel[:5])) <= 1e-12
    assert np.max(np.abs(s.pos[:, 0] - [5.0, 6.0, 7.0, 8.0, 9.0, 14.5])) <= 1e-12
    assert sim.stats()["pair_collisions"] == 5
    assert s.color[0].tolist() == [230, 80, 60]


@pytest.mark.parametrize("flag, value", [("--n", "10"), ("--radius", "0.1"),
                                         ("--speed", "1"), ("--seed", "3")])
def test_circle_file_refuses_random_scene_flags(flag, value, capsys):
    assert cli.main(["run", str(CRADLE), flag, value]) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert captured.out == "" and len(lines) == 1, captured.err
    assert flag in lines[0] and "newtons_cradle.toml" in lines[0] and "[[circle]]" in lines[0]


@pytest.mark.parametrize("entry, words", [
    ('pos = [2.8, 1.6]\nvel = [0.0, 0.0]\nradius = 0.2', ["circle 1", "circle 2", "overlap"]),
    ('vel = [0.0, 0.0]\nradius = 0.2', ["circle 2", "pos", "missing", "[x, y]"]),
    ('pos = [2.0]\nvel = [0.0, 0.0]\nradius = 0.2', ["circle 2", "pos", "[2.0]", "two numbers"]),
    ('pos = [2.0, 1.0]\nvel = [nan, 0.0]\nradius = 0.2', ["circle 2", "vel", "nan", "finite"]),
    ('pos = [2.0, 1.0]\nvel = [0.0, 0.0]\nradius = -0.2', ["circle 2", "radius", "-0.2", "> 0"]),
    ('pos = [3.9, 1.0]\nvel = [0.0, 0.0]\nradius = 0.2', ["circle 2", "[3.9, 1.0]", "walls",
                                                          "3.8"]),
    ('pos = [2.0, 1.0]\nvel = [0.0, 0.0]\nradius = 0.2\ncolor = [0, 0, 300]',
     ["circle 2", "color", "300", "255"]),
], ids=["overlap", "missing_pos", "pos_length", "non_finite", "radius", "outside", "color"])
def test_bad_circle_entry_exits_2_naming_the_circle(entry, words, tmp_path, capsys,
                                                    monkeypatch):
    import circles

    def no_simulation(*args, **kwargs):
        raise AssertionError("the simulation started")

    monkeypatch.setattr(circles, "init", no_simulation)
    monkeypatch.setattr(circles, "Simulation", no_simulation)
    monkeypatch.chdir(tmp_path)
    Path("bad.toml").write_text(TWO_CIRCLES + "[[circle]]\n" + entry + "\n")
    assert cli.main(["run", "bad.toml"]) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert captured.out == "" and len(lines) == 1, captured.err
    assert lines[0].startswith("circles: error: bad.toml: ")
    for word in words:
        assert word in lines[0]


def test_circle_file_mixed_with_random_scene_fields_is_refused(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    Path("mixed.toml").write_text("n = 10\nspeed = 1.0\n" + TWO_CIRCLES)
    assert cli.main(["run", "mixed.toml"]) == 2
    error = capsys.readouterr().err.strip()
    assert len(error.splitlines()) == 1 and "n, speed" in error and "[[circle]]" in error
    with pytest.raises(ValueError, match="read_circle_list"):
        circles.Scene.from_toml(CRADLE)


def test_circle_file_with_flags_overriding_it(tmp_path):
    """--box, --boundary and --dt still apply to a file that lists its circles."""
    (tmp_path / "two.toml").write_text(TWO_CIRCLES)
    result = run_cli(["run", "two.toml", "--box", "5", "3", "--boundary", "periodic",
                      "--dt", "0.01", "--duration", "0.2", "--fps", "10", "--size", "50x30",
                      "--arch", "cpu", "--out", "two.gif"], tmp_path)
    assert result.returncode == 0, result.stderr
    assert "2 (event, f64, periodic" in result.stdout and "dt <= 0.01 s" in result.stdout
    assert iio.imread(tmp_path / "two.gif", index=None).shape[:3] == (2, 30, 50)


FAILING_RUN = """
import sys
import circles.simulation as simulation
from circles import cli

advance = simulation.Simulation.advance
calls = []

def failing(self, duration):
    calls.append(1)
    if len(calls) == 3:
        raise ValueError("dt = 1e-12 is below the resolution of the simulated clock at time 1e+06")
    return advance(self, duration)

simulation.Simulation.advance = failing
sys.exit(cli.main(sys.argv[1:]))
"""


def test_a_run_that_fails_midway_exits_1_and_keeps_its_frames(tmp_path):
    """An error during the run (here a ValueError from the simulation, which escaped as a
    traceback before) ends it with status 1 and one line, and the frames made so far play."""
    result = run_cli(["run", *SMALL, "--duration", "1", "--fps", "10", "--out", "run.gif"], tmp_path,
                     python=("-c", FAILING_RUN))
    assert result.returncode == 1, result.stderr
    assert "Traceback" not in result.stderr
    assert "circles: the run failed: dt = 1e-12 is below the resolution" in result.stderr
    assert iio.imread(tmp_path / "run.gif", index=None).shape[0] == 3


CTRL_C_RUN = """
import os
import signal
import sys

from circles import cli, video

# As in a terminal: a shell that starts a job in the background leaves SIGINT ignored.
signal.signal(signal.SIGINT, signal.default_int_handler)


def ctrl_c(times):
    for _ in range(times):
        os.kill(os.getpid(), signal.SIGINT)  # handled before the next line runs


write, close = video.FrameWriter.write, video.FrameWriter.close


def write_with_ctrl_c(self, frame):
    if self.frames == {at_frame}:
        ctrl_c(2)  # twice, as the frame is written
    write(self, frame)


def close_with_ctrl_c(self):
    if {at_close}:
        ctrl_c(2)  # twice, as the file is finished
    close(self)


video.FrameWriter.write = write_with_ctrl_c
video.FrameWriter.close = close_with_ctrl_c
sys.exit(cli.main(sys.argv[1:]))
"""


def run_with_ctrl_c(args, cwd, at_frame=-1, at_close=False):
    return run_cli(args, cwd, python=("-c", CTRL_C_RUN.format(at_frame=at_frame, at_close=at_close)))


def frames_in(path):
    if path.is_dir():
        names = sorted(p.name for p in path.iterdir())
        assert names == [f"frame_{k:05d}.png" for k in range(len(names))]
        return np.stack([iio.imread(path / name) for name in names])
    return iio.imread(path, index=None)


@pytest.mark.parametrize("out", ["run.mp4", "frames"])
def test_ctrl_c_twice_while_a_frame_is_written_keeps_it_whole(tmp_path, out):
    """"Stop at once" stops the run, but not the writing of a frame (which, cut short, broke
    the MP4's encoder or left a truncated PNG): the third frame, during whose writing both
    Ctrl-Cs come, is the last, whole, and counted."""
    result = run_with_ctrl_c(["run", *SMALL, "--duration", "1", "--fps", "10", "--out", out],
                             tmp_path, at_frame=2)
    assert result.returncode == 130, result.stderr
    assert "Traceback" not in result.stderr
    assert "(stopped by Ctrl-C)" in result.stdout
    assert f"wrote       {out} (3 frames at 10 fps)" in result.stdout
    assert frames_in(tmp_path / out).shape[:3] == (3, 60, 80)


def test_ctrl_c_while_the_file_is_finished_waits_for_it(tmp_path):
    """Ctrl-C as the MP4 is finished (it killed ffmpeg, leaving a file that did not play, and
    lost the summary) waits for the file: the run was complete, so the status is 0."""
    result = run_with_ctrl_c(["run", *SMALL, "--duration", "0.5", "--fps", "10",
                              "--out", "run.mp4"], tmp_path, at_close=True)
    assert result.returncode == 0, result.stderr
    assert "Traceback" not in result.stderr and "finishing run.mp4" in result.stderr
    assert "simulated   0.5 s in" in result.stdout and "Ctrl-C" not in result.stdout
    assert "wrote       run.mp4 (5 frames at 10 fps)" in result.stdout
    assert frames_in(tmp_path / "run.mp4").shape[:3] == (5, 60, 80)


def test_an_encoder_that_fails_exits_1_with_one_line_and_no_broken_file(tmp_path):
    """ffmpeg killed for the size of its file (as by `ulimit -f`; it was reported as written,
    status 0) ends the run with status 1 and one line, and the unplayable file is removed."""
    import imageio_ffmpeg

    script = tmp_path / "limited_ffmpeg"
    script.write_text(f"#!{sys.executable}\n"
                      "import os, resource, signal, sys\n"
                      "resource.setrlimit(resource.RLIMIT_FSIZE, (1000, 1000))\n"
                      "signal.signal(signal.SIGXFSZ, signal.SIG_DFL)  # as a shell leaves it\n"
                      f"os.execv({imageio_ffmpeg.get_ffmpeg_exe()!r}, ['ffmpeg', *sys.argv[1:]])\n")
    script.chmod(0o755)
    result = run_cli(["run", *SMALL, "--duration", "0.5", "--fps", "10", "--out", "run.mp4"],
                     tmp_path, extra_env={"IMAGEIO_FFMPEG_EXE": str(script)})
    assert result.returncode == 1, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("circles: the run failed: ffmpeg failed to write run.mp4")
    assert "SIGXFSZ" in lines[0] and "removed the file" in lines[0]
    assert "wrote" not in result.stdout and not (tmp_path / "run.mp4").exists()


# J: the CLI's frame k is the state at t = k / fps.
@pytest.mark.skipif(TEST_ARCH != "cpu", reason="the command line runs on the CPU here, the test's simulation on the GPU")
def test_cli_frame_k_shows_the_state_at_k_over_fps(tmp_path, circles_cpu):
    (tmp_path / "scene.toml").write_text(
        'n = 30\nbox = [4.0, 3.0]\nradius = 0.1\nspeed = [1.0, 2.0]\nmass = "equal"\nseed = 5\n'
        '[run]\nduration = 0.5\nfps = 10\nsize = "80x60"\ncolor = "random"\nout = "frames"\narch = "cpu"\n'
        'threads = 1\n')
    done = run_cli(["run", "scene.toml"], tmp_path)
    assert done.returncode == 0, done.stderr
    pngs = sorted((tmp_path / "frames").glob("frame_*.png"))
    assert len(pngs) == 5
    sim = circles_cpu.Simulation(circles_cpu.Scene(n=30, box=(4.0, 3.0), radius=0.1, speed=(1.0, 2.0),
                                                   mass="equal", seed=5))
    for k, png in enumerate(pngs):
        sim.advance(k / 10 - sim.time)
        assert np.array_equal(iio.imread(png), sim.render(80, 60, "random")), k


# N: a circle file overlapping across the y seam is refused, naming the pair.
def test_circle_file_overlap_across_the_y_seam_is_refused(tmp_path):
    from circles import scenefile
    path = tmp_path / "c.toml"
    path.write_text('box = [4.0, 3.0]\nboundary = "periodic"\n'
                    '[[circle]]\npos = [2.0, 0.05]\nvel = [0.0, 0.0]\nradius = 0.2\n'
                    '[[circle]]\npos = [2.0, 2.95]\nvel = [0.0, 0.0]\nradius = 0.2\n')
    with pytest.raises(ValueError, match="circle 0 .* and circle 1 overlap"):
        scenefile.read_circle_list(path)


# U: the --seed flag places the scene with that seed.
@pytest.mark.skipif(TEST_ARCH != "cpu", reason="the command line runs on the CPU here, the test's simulation on the GPU")
def test_cli_seed_flag_places_with_that_seed(tmp_path, circles_cpu):
    done = run_cli(["run", "--n", "30", "--box", "4", "3", "--radius", "0.1", "--speed", "1", "2", "--seed", "7",
                    "--duration", "0.1", "--fps", "10", "--size", "80x60", "--out", "frames", "--arch", "cpu",
                    "--threads", "1"], tmp_path, timeout=300)
    assert done.returncode == 0, done.stderr
    sim = circles_cpu.Simulation(circles_cpu.Scene(n=30, box=(4.0, 3.0), radius=0.1, speed=(1.0, 2.0), seed=7))
    assert np.array_equal(iio.imread(tmp_path / "frames" / "frame_00000.png"), sim.render(80, 60))


EARLY_CTRL_C = """
import builtins, os, signal, sys
import circles.cli as cli
assert "taichi" not in sys.modules  # importing the command line loads no kernels
real_import = builtins.__import__
sent = []

def importing(name, *args, **kwargs):
    # Ctrl-C as Taichi starts to load, before a frame: it was lost in Taichi's decorators
    # (the run went on to its end) or raised a traceback.
    if name == "taichi" and not sent:
        sent.append(1)
        os.kill(os.getpid(), signal.SIGINT)
    return real_import(name, *args, **kwargs)

builtins.__import__ = importing
sys.exit(cli.main(sys.argv[1:]))
"""


def test_ctrl_c_while_the_engine_loads_stops_at_once_and_leaves_nothing(tmp_path):
    result = run_cli(["run", *SMALL, "--duration", "2", "--fps", "10", "--out", "new/run.gif"], tmp_path,
                     python=("-c", EARLY_CTRL_C), timeout=300)
    assert result.returncode == 130, result.stderr
    assert result.stderr.strip() == "circles: stopped by Ctrl-C" and result.stdout == ""
    assert list(tmp_path.iterdir()) == []


def test_a_refusal_after_the_output_check_leaves_no_folders(tmp_path):
    """The output's folders are made when it is checked, before the scene is placed; a scene
    that placement refuses (here too near jamming to place) exits 2 and takes them away."""
    radius = (0.88 * 16 * 9 / (2000 * math.pi)) ** 0.5  # area fraction 0.88: no lattice of 2000 fits
    result = run_cli(["run", "--n", "2000", "--box", "16", "9", "--radius", str(radius), "--scheme", "discrete",
                      "--arch", "cpu", "--out", "deep/er/run.gif"], tmp_path)
    assert result.returncode == 2 and "jamming" in result.stderr, result.stderr
    assert list(tmp_path.iterdir()) == []


def test_a_summary_that_cannot_be_printed_is_said_so_and_the_file_is_whole(tmp_path):
    """With standard output on a full device, the run itself succeeded: the message said the
    run failed, as for a full disk under the video."""
    with open("/dev/full", "w") as full:
        result = run_cli(["run", *SMALL, "--duration", "0.5", "--fps", "10", "--out", "run.gif"], tmp_path,
                         stdout=full, stderr=subprocess.PIPE)
    assert result.returncode == 1
    assert result.stderr.strip().endswith("run.gif is complete, but its summary could not be printed: [Errno 28] "
                                          "No space left on device"), result.stderr
    assert iio.imread(tmp_path / "run.gif", index=None).shape[0] == 5



def test_refused_values_of_a_scene_file_name_the_file(tmp_path, capsys, monkeypatch):
    """A [run] value from the file is refused with the file's name (a flag's without it), and a
    listed circle wider than the box is told to be smaller, not moved to an empty range of
    places (y in [0.5, 0.4])."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "run.toml").write_text('n = 10\nradius = 0.1\n[run]\nfps = "30"\n')
    (tmp_path / "wide.toml").write_text("box = [4.0, 0.9]\n[[circle]]\npos = [2.0, 0.45]\nvel = [1.0, 0.0]\n"
                                        "radius = 0.5\n")
    for args, said in ((["run", "run.toml"], "run.toml: [run] fps '30' must be a positive number"),
                       (["run", "run.toml", "--duration", "-1"], "error: duration -1.0 must be a positive number"),
                       (["run", "wide.toml"], "radius = 0.5 is too large for the box 4.0 x 0.9 (diameter 1 > "
                                              "side 0.9): use a smaller circle or a bigger box")):
        assert cli.main(args) == 2
        err = capsys.readouterr().err
        assert said in err and len(err.strip().splitlines()) == 1, err
