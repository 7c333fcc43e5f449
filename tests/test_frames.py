"""Runs that start from a GSD frame (`circles.frames`, `circles run --from`): circles' own files
bit for bit, HOOMD-blue's with its centred box moved to circles' corner, and the refusals."""

import gsd.hoomd
import numpy as np
import pytest

from circles import cli
from circles.frames import circle_list_from_gsd, split_spec


def hoomd_file(path, pos, diameter, mass=None, velocity=None, box=(10.0, 8.0, 0.0, 0.0, 0.0, 0.0), dimensions=2):
    frame = gsd.hoomd.Frame()
    frame.configuration.box = list(box)
    frame.configuration.dimensions = dimensions
    frame.particles.N = len(pos)
    frame.particles.position = np.column_stack([pos, np.zeros(len(pos))]).astype(np.float32)
    frame.particles.diameter = np.asarray(diameter, np.float32)
    if mass is not None:
        frame.particles.mass = np.asarray(mass, np.float32)
    if velocity is not None:
        frame.particles.velocity = np.column_stack([velocity, np.zeros(len(pos))]).astype(np.float32)
    with gsd.hoomd.open(str(path), "w") as f:
        f.append(frame)
    return path


def test_a_frame_of_circles_own_trajectory_is_read_as_the_simulation_held_it(circles_cpu, tmp_path):
    """Frame 1 of a --trajectory: positions, velocities, radii, masses, colours and box as
    `read_simulation` gives them, bit for bit; the scheme, precision and dt its own."""
    from circles.trajectory import read_simulation

    traj = tmp_path / "run.gsd"
    assert cli.main(["run", "--n", "60", "--radius", "0.2", "--box", "8", "5", "--duration", "0.5", "--fps", "4",
                     "--out", "none", "--trajectory", str(traj)]) == 0
    circles = circle_list_from_gsd(f"{traj}:1")
    state = read_simulation(traj, 1).state()
    for name in ("pos", "vel", "radius", "mass", "color"):
        assert np.array_equal(getattr(circles, name), getattr(state, name)), name
    assert circles.box == (8.0, 5.0) and circles.boundary == "walls" and circles.scheme == "event"
    assert np.array_equal(circle_list_from_gsd(str(traj)).pos, read_simulation(traj, -1).state().pos)


def test_a_hoomd_frame_is_moved_from_the_centred_box_to_the_corner(tmp_path):
    """HOOMD's box is centred on 0, circles' starts at 0: x + L/2. Radii are half the
    diameters, masses HOOMD's, velocities its own (x and y), the box periodic."""
    pos = np.array([[-4.0, -3.0], [0.0, 0.0], [3.5, 2.5]])
    path = hoomd_file(tmp_path / "h.gsd", pos, [1.0, 1.5, 0.5], mass=[1.0, 2.0, 3.0],
                      velocity=[[0.5, 0.0], [0.0, -0.25], [1.0, 1.0]])
    circles = circle_list_from_gsd(str(path))
    assert circles.pos.tolist() == [[1.0, 1.0], [5.0, 4.0], [8.5, 6.5]]
    assert circles.radius.tolist() == [0.5, 0.75, 0.25] and circles.mass.tolist() == [1.0, 2.0, 3.0]
    assert circles.vel.tolist() == [[0.5, 0.0], [0.0, -0.25], [1.0, 1.0]]
    assert circles.box == (10.0, 8.0) and circles.boundary == "periodic"


def test_a_hoomd_frame_without_velocities_gets_the_scenes_speeds(tmp_path):
    path = hoomd_file(tmp_path / "h.gsd", np.array([[-4.0, -3.0], [0.0, 0.0], [3.5, 2.5]]), [1.0, 1.0, 1.0])
    circles = circle_list_from_gsd(str(path), speed=(2.0, 2.0), seed=4)
    assert np.hypot(circles.vel[:, 0], circles.vel[:, 1]) == pytest.approx([2.0, 2.0, 2.0], rel=1e-15)
    assert circles.mass.tolist() == [1.0, 1.0, 1.0]  # HOOMD's default mass
    assert np.array_equal(circle_list_from_gsd(str(path), speed=(2.0, 2.0), seed=4).vel, circles.vel)
    assert not np.array_equal(circle_list_from_gsd(str(path), speed=(2.0, 2.0), seed=5).vel, circles.vel)


@pytest.mark.parametrize("make, spec, message", [
    (lambda p: hoomd_file(p, np.zeros((1, 2)), [1.0]), "{p}:1",
     "--from {p}:1: {p} holds 1 frame, so frame 1 does not exist: give 0 to 0, or -1 for the last"),
    (lambda p: hoomd_file(p, np.zeros((1, 2)), [1.0], box=(10, 8, 0, 0.5, 0, 0)), "{p}",
     "--from {p}: frame 0 has a 2D box with tilts [0.5, 0.0, 0.0]: circles reads square-cornered 2D boxes "
     "(dimensions = 2, no tilt)"),
    (lambda p: hoomd_file(p, np.array([[0.0, 0.0], [0.5, 0.0]]), [1.0, 1.0]), "{p}",
     "--from {p}: frame 0: particles 0 and 1 overlap by 0.5 of their contact distance 1 (centres 0.5 apart): hard "
     "disks must be apart or touching"),
    (lambda p: p, "{p}", "--from {p}: {p} does not exist"),
    (lambda p: p, "{p}:x", "--from {p}:x: the frame after the colon must be a whole number, e.g. {p}:0 (or -1 for "
     "the last)"),
])
def test_frames_that_cannot_start_a_run_are_refused_in_one_line(tmp_path, make, spec, message):
    path = make(tmp_path / "h.gsd")
    with pytest.raises(ValueError) as refused:
        circle_list_from_gsd(spec.format(p=path))
    assert str(refused.value) == message.format(p=path)


def test_split_spec_takes_the_last_frame_by_default():
    assert split_spec("a.gsd") == ("a.gsd", -1)
    assert split_spec("dir:x/a.gsd:3") == ("dir:x/a.gsd", 3)
    assert split_spec("a.gsd:-2") == ("a.gsd", -2)


def test_the_command_line_runs_from_a_frame_and_a_scene_file_may_name_one(circles_cpu, tmp_path, capsys):
    """--from FILE, and a scene file's from = "FILE:FRAME" (from the file's folder) with speeds
    for a HOOMD frame; a flag that shapes another scene is refused in one line."""
    pos = np.array([[-4.0, -3.0], [0.0, 0.0], [3.5, 2.5], [2.0, -2.0]])
    hoomd_file(tmp_path / "h.gsd", pos, [1.0, 1.0, 1.0, 1.0])
    stats = tmp_path / "run.csv"
    assert cli.main(["run", "--from", str(tmp_path / "h.gsd"), "--duration", "1", "--fps", "2", "--out", "none",
                     "--stats", str(stats)]) == 0
    assert len(stats.read_text().splitlines()) == 3
    (tmp_path / "scene.toml").write_text('from = "h.gsd:0"\nspeed = [2.0, 2.0]\n')
    traj = tmp_path / "run.gsd"
    assert cli.main(["run", str(tmp_path / "scene.toml"), "--duration", "0.5", "--fps", "2", "--out", "none",
                     "--trajectory", str(traj)]) == 0
    with gsd.hoomd.open(str(traj)) as f:
        v = f[0].log["particles/circles/velocity"]
    assert np.hypot(v[:, 0], v[:, 1]) == pytest.approx(np.full(4, 2.0), rel=1e-12)
    capsys.readouterr()
    assert cli.main(["run", "--from", str(tmp_path / "h.gsd"), "--area-fraction", "0.3", "--out", "none"]) == 2
    assert capsys.readouterr().err == (f"circles: error: --area-fraction shapes a scene of its own, and the run "
                                       f"starts from {tmp_path / 'h.gsd'}: drop it, or drop the frame\n")
