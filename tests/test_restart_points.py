"""Restart points in-process: the checkpoint file, where a run goes on from, what a resumed
table keeps, and the refusals, each checked against files written here by hand. (The command
line's stop-and-resume, bit for bit, is tests/test_resume.py.)"""
import json
import math

import numpy as np
import pytest

from circles import checkpoint, resume
from circles.command import UsageError
from circles.trajectory import GSDWriter, run_of
from circles.writers import Run, StatsWriter, frame_times, row_of


def small(circles, boundary="periodic", seed=4):
    return circles.Scene(n=30, box=(2.1, 1.3), radius=0.06, speed=(0.5, 1.0), boundary=boundary, seed=seed)


def test_identity_names_the_scene_the_frame_rate_and_the_order(circles_cpu):
    scene = small(circles_cpu)
    made = resume.identity(scene, 10, False)
    assert made == {"scene": json.loads(json.dumps(scene.to_dict())), "fps": 10.0, "order": False}
    assert resume.identity(scene, 10, True)["order"] is True
    from circles.scenefile import CircleList

    circles = CircleList(pos=np.array([[0.5, 0.5], [1.5, 0.5]]), vel=np.array([[1.0, 0.0], [0.0, 0.0]]),
                         radius=np.array([0.125, 0.125]), mass=np.array([1.0, 1.0]), color=None, box=(2.0, 1.0),
                         boundary="walls", scheme="event", precision="f64", dt=None)
    first = resume.identity(circles, 30, False)
    digest = first["scene"].pop("sha256")
    assert len(digest) == 64 and first == {"scene": {"circles": 2, "box": [2.0, 1.0], "boundary": "walls",
                                                     "scheme": "event", "precision": "f64", "dt": None},
                                           "fps": 30.0, "order": False}
    # The digest is of the circles' values, whatever the arrays' types (these hold in float32).
    as_floats = {name: np.asarray(value, np.float32) for name, value in circles.__dict__.items()
                 if name in ("pos", "vel", "radius", "mass")}
    assert resume.identity(CircleList(**{**circles.__dict__, **as_floats}), 30, False)["scene"]["sha256"] == digest
    for change in ({"pos": np.array([[0.5, 0.5], [1.5, 0.6]])}, {"vel": np.array([[1.0, 0.0], [0.0, 0.1]])},
                   {"radius": np.array([0.1, 0.2])}, {"mass": np.array([1.0, 2.0])},
                   {"color": np.array([[1, 2, 3], [4, 5, 6]], np.uint8)}):
        other = resume.identity(CircleList(**{**circles.__dict__, **change}), 30, False)["scene"]["sha256"]
        assert other != digest, change
    coloured = CircleList(**{**circles.__dict__, "color": np.array([[1, 2, 3], [4, 5, 6]])})
    recoloured = CircleList(**{**circles.__dict__, "color": np.array([[1, 2, 3], [4, 5, 7]])})
    assert resume.identity(coloured, 30, False) != resume.identity(recoloured, 30, False)
    as_bytes = CircleList(**{**circles.__dict__, "color": np.array([[1, 2, 3], [4, 5, 6]], np.uint8)})
    assert resume.identity(coloured, 30, False) == resume.identity(as_bytes, 30, False)  # the colours, not their type


def test_difference_names_the_first_field_that_differs():
    held = {"scene": {"n": 30, "seed": 4, "box": [2.0, 1.0]}, "fps": 10.0, "order": False}
    assert resume.difference(held, json.loads(json.dumps(held))) is None
    assert resume.difference(held, {**held, "fps": 20.0}) == "fps 10.0, and this run has 20.0"
    assert resume.difference(held, {**held, "scene": {**held["scene"], "seed": 5}}) == "seed 4, and this run has 5"
    assert resume.difference(held, {**held, "scene": {**held["scene"], "box": [2.0, 1.5]}}) == \
        "box [2.0, 1.0], and this run has [2.0, 1.5]"
    assert resume.difference({**held, "scene": {"n": 30}}, {**held, "scene": {"n": 30, "dt": 0.1}}) == \
        "dt unset, and this run has 0.1"


def trajectory(circles, path, frames, wanted, start=0.0):
    """A run's trajectory as `circles run` writes it: `frames` frames 0.1 apart."""
    sim = circles.Simulation(small(circles))
    with GSDWriter(path, run={"run": wanted, "start": start}) as writer:
        for k in range(frames):
            if k:
                sim.advance(k / 10 - sim.time)
            writer.write(sim)
    return sim


def test_the_trajectorys_last_frame_or_a_newer_checkpoint_is_where_a_run_goes_on(circles_cpu, tmp_path):
    wanted = resume.identity(small(circles_cpu), 10, False)
    path, kept = tmp_path / "run.gsd", tmp_path / "run.checkpoint.gsd"
    sim = trajectory(circles_cpu, path, 3, wanted)
    assert resume.restart_point(None, kept, wanted) is None  # neither
    point = resume.restart_point(path, kept, wanted)  # no checkpoint
    assert (point.frame, point.refire, point.time, point.start, point.row) == (2, False, 0.2, 0.0, None)
    assert point.source == path
    again = point.simulation()
    assert np.array_equal(again.state().pos, sim.state().pos) and again.time == sim.time
    # A checkpoint of the frame after the last, before that frame's writers: it wins.
    sim.advance(0.3 - sim.time)
    row = {"time": 0.3, "pressure": math.nan}
    checkpoint.write(kept, sim, {"run": wanted, "frame": 3, "start": 0.25, "row": row})
    point = resume.restart_point(path, kept, wanted)
    assert (point.frame, point.refire, point.time, point.source, point.start) == (3, True, 0.3, kept, 0.25)
    assert np.array_equal(point.simulation().state().pos, sim.state().pos)
    assert point.row["time"] == 0.3 and math.isnan(point.row["pressure"])
    # An older checkpoint, or one of the last frame: the trajectory's last frame wins.
    for frame in (1, 2):
        checkpoint.write(kept, sim, {"run": wanted, "frame": frame, "start": 0.0})
        assert resume.restart_point(path, kept, wanted).source == path
    # A checkpoint of another run is refused, by its own name.
    checkpoint.write(kept, sim, {"run": {**wanted, "fps": 5.0}, "frame": 1, "start": 0.0})
    with pytest.raises(UsageError, match=r"run.checkpoint.gsd holds a run made with fps 5.0, and this run has 10.0"):
        resume.restart_point(path, kept, wanted)
    # Without a trajectory the checkpoint is the restart point, whatever its frame.
    checkpoint.write(kept, sim, {"run": wanted, "frame": 7, "start": 0.0})
    assert resume.restart_point(None, kept, wanted).frame == 7
    # A checkpoint more than a frame past the trajectory: not of one run.
    with pytest.raises(UsageError, match="of frame 7, but .*run.gsd holds 3 frames, not the 7 before it"):
        resume.restart_point(path, kept, wanted)


def test_files_of_another_run_or_of_none_are_refused(circles_cpu, tmp_path):
    wanted = resume.identity(small(circles_cpu), 10, False)
    path = tmp_path / "run.gsd"
    trajectory(circles_cpu, path, 2, wanted)
    other = {**wanted, "scene": {**wanted["scene"], "seed": 9}}
    with pytest.raises(UsageError) as refused:
        resume.restart_point(path, None, other)
    assert str(refused.value) == (f"--resume: {path} holds a run made with seed 4, and this run has 9: give the scene "
                                  "and flags that run was made with, or drop --resume (with --force to overwrite "
                                  "the files)")
    # The start of frame 0 comes from the file.
    later = tmp_path / "later.gsd"
    trajectory(circles_cpu, later, 2, wanted, start=5.0)
    assert resume.restart_point(later, None, wanted).start == 5.0
    bare = tmp_path / "bare.gsd"
    with GSDWriter(bare) as writer:
        writer.write(circles_cpu.Simulation(small(circles_cpu)))
    with pytest.raises(UsageError) as refused:
        resume.restart_point(bare, None, wanted)
    assert str(refused.value) == (f"--resume: {bare} does not say what made its run (no log/circles/run chunk): it "
                                  "was not written by circles run; drop --resume and give other files")
    empty = tmp_path / "empty.gsd"
    GSDWriter(empty).close()
    assert resume.restart_point(empty, tmp_path / "none.gsd", wanted) is None
    text = tmp_path / "text.gsd"
    text.write_text("not a gsd file")
    with pytest.raises(UsageError, match="not a GSD file that gsd can read"):
        resume.restart_point(text, None, wanted)
    with pytest.raises(UsageError, match=r"text.gsd is not a checkpoint gsd can read \(.*\): remove it to go on "
                                         r"from the trajectory's last frame$"):
        resume.restart_point(None, text, wanted)


def test_the_schedule_refuses_a_point_past_the_end_or_between_frames(circles_cpu, tmp_path):
    def point(frame, time, start=0.0):
        return resume.RestartPoint(source=None, frame=frame, time=time, refire=True, start=start)

    resume.check_schedule(point(4, 0.4), frame_times(1.0, 10), 10)  # frame 4 of 10
    resume.check_schedule(point(4, 0.4), frame_times(0.4, 10), 10)  # the end of a run of 4 frames
    resume.check_schedule(point(2, 5.2, start=5.0), frame_times(1.0, 10), 10)
    with pytest.raises(UsageError, match=r"^--resume: the run reached t = 0.4 s \(4 frames\), beyond this --duration "
                                         r"0.3 s: give a --duration of at least 0.4$"):
        resume.check_schedule(point(4, 0.4), frame_times(0.3, 10), 10)
    with pytest.raises(UsageError, match=r"reached t = 5.4 s \(4 frames\), beyond this --duration 0.35 s: give a "
                                         r"--duration of at least 0.4$"):
        resume.check_schedule(point(4, 5.4, start=5.0), frame_times(0.35, 10), 10)
    with pytest.raises(UsageError, match=r"^--resume: the run stopped at t = 0.35 s, between frames \(the frame "
                                         r"instant there is 0.4 s at 10 fps\): only a run whose duration is a whole "
                                         r"number of frames can be made longer$"):
        resume.check_schedule(point(4, 0.35), frame_times(1.0, 10), 10)
    with pytest.raises(UsageError, match="beyond this --duration"):
        resume.check_schedule(point(4, 0.45), frame_times(0.4, 10), 10)
    with pytest.raises(UsageError, match="beyond this --duration"):  # a frame past the last, at the end's time
        resume.check_schedule(point(5, 0.4), frame_times(0.4, 10), 10)
    with pytest.raises(UsageError, match="between frames"):  # off by 1e-10 of itself: not a frame instant
        resume.check_schedule(point(4, 0.4 * (1 + 1e-10)), frame_times(1.0, 10), 10)


def test_a_checkpoint_is_replaced_whole_or_not_at_all(circles_cpu, tmp_path, monkeypatch):
    assert checkpoint.path_beside(tmp_path / "run.gsd") == tmp_path / "run.checkpoint.gsd"
    assert checkpoint.path_beside("a/run.csv").name == "run.checkpoint.gsd"
    sim = circles_cpu.Simulation(small(circles_cpu, "walls"))
    path = tmp_path / "run.checkpoint.gsd"
    checkpoint.write(path, sim, {"frame": 1})
    sim.advance(0.3)
    old = path.read_bytes()

    def fails(self, sim, row=None, stats=None):
        raise OSError("disk full")

    monkeypatch.setattr(GSDWriter, "write", fails)
    with pytest.raises(OSError, match="disk full"):
        checkpoint.write(path, sim, {"frame": 2})
    monkeypatch.undo()
    assert path.read_bytes() == old and [p.name for p in tmp_path.iterdir()] == [path.name]
    checkpoint.write(path, sim, {"frame": 2})
    again, progress = checkpoint.read(path)
    assert progress == {"frame": 2} and run_of(path) == progress
    a, b = sim._fields(), again._fields()
    for name in ("pos", "vel", "pair_count", "wall_count", "virial", "wall_impulse", "time", "steps", "box"):
        assert np.array_equal(a[name], b[name]), name
    assert a["wall_count"].sum() > 0 and a["pair_count"].sum() > 0


def test_reading_what_is_not_a_checkpoint_says_so(circles_cpu, tmp_path):
    with pytest.raises(FileNotFoundError):
        checkpoint.read(tmp_path / "missing.gsd")
    text = tmp_path / "text.gsd"
    text.write_text("not a gsd file")
    with pytest.raises(ValueError, match="is not a checkpoint that circles wrote: gsd cannot read it"):
        checkpoint.read(text)
    bare = tmp_path / "bare.gsd"
    with GSDWriter(bare) as writer:
        writer.write(circles_cpu.Simulation(small(circles_cpu, "walls")))
    with pytest.raises(ValueError, match="it has no log/circles/run chunk"):
        checkpoint.read(bare)


def test_a_continued_table_keeps_its_first_rows_and_goes_on(tmp_path):
    path = tmp_path / "run.csv"
    with StatsWriter(path) as table:
        for k in range(5):
            table.write({name: float(k) for name in table.columns})
    header = path.read_text().splitlines()[0]
    with open(path, "a") as file:
        file.write("9.0,9.0")  # a row cut short by a stop
    with StatsWriter(path, keep=3) as table:
        assert table.rows == 3
        table.write({name: 7.0 for name in table.columns})
    lines = path.read_text().split("\n")
    assert lines[0] == header and lines[-1] == ""
    assert [line.split(",")[0] for line in lines[1:-1]] == ["0.0", "1.0", "2.0", "7.0"]
    with pytest.raises(ValueError) as refused:
        StatsWriter(path, keep=5)
    assert str(refused.value) == (f"{path} holds 4 rows, fewer than the 5 the run had written by its restart point: "
                                  "it is not this run's table")
    with StatsWriter(path, keep=4) as table:  # all of them
        assert table.rows == 4
    assert path.read_text() == "\n".join(lines[:-1]) + "\n"
    with pytest.raises(ValueError) as refused:
        StatsWriter(path, order=True, keep=1)
    assert str(refused.value) == (f"{path} is not the stats table of this run: its header is {header[:80]!r}, not that "
                                  "of --order --stats")
    (tmp_path / "empty.csv").write_text("")
    with pytest.raises(ValueError, match=r"empty.csv is not the stats table of this run: its header is 'nothing', not "
                                         r"that of --stats$"):
        StatsWriter(tmp_path / "empty.csv", keep=0)
    (tmp_path / "binary.csv").write_bytes(b"\xff\xfe,time\n1,2\n")
    with pytest.raises(ValueError, match="its header is '\ufffd\ufffd,time', not that of --stats$"):
        StatsWriter(tmp_path / "binary.csv", keep=1)


def test_a_run_continued_from_frame_k_advances_to_the_same_instants(circles_cpu):
    """Run(start=) measures the frame instants from the run's first start, and row= is what the
    frame writers get first: a run continued from frame 3 ends where one never stopped does."""
    whole = circles_cpu.Simulation(small(circles_cpu))
    seen = []

    class Frames:
        def write(self, sim, row, stats):
            seen.append((sim.time, None if row is None else row["time"]))

    for _ in Run(whole, 0.6, 10):
        pass
    part = circles_cpu.Simulation(small(circles_cpu))
    run = Run(part, 0.6, 10, need_stats=True)
    for k in range(3):
        run.fire_frame()
        run.advance(k)
        run.fire_interval()
    row = run.row
    later = Run(part, 0.6, 10, at_frame=[Frames()], start=0.0, row=row)
    assert later.start == 0.0 and later.row is row
    later.fire_frame()
    for k in range(3, 6):
        later.advance(k)
        later.fire_interval()
        later.fire_frame()
    assert part.time == whole.time == 0.6
    assert np.array_equal(part.state().pos, whole.state().pos)
    assert seen[0] == (0.3, 0.3) and [t for t, _ in seen] == [0.3, 0.4, 0.5, 0.6]
    assert Run(part, 0.6, 10).start == part.time  # by default the simulation's time now
    assert row_of(part.stats(), part.stats(), part)["time"] == 0.6


def test_a_checkpoint_keeps_the_image_flags_it_is_given_and_takes_any_name(circles_cpu, tmp_path):
    """With the run's ImageTracker the frame holds its flags (a trajectory goes on from them);
    without, none. A name of 255 bytes, cut in the middle of a character for the temporary
    name, is written."""
    from circles.trajectory import ImageTracker

    sim = circles_cpu.Simulation(circles_cpu.Scene(n=20, box=(1.0, 1.0), radius=0.02, speed=(2.0, 3.0),
                                                   boundary="periodic", seed=1))
    tracker = ImageTracker(sim)
    sim.advance(2.0)
    assert np.abs(tracker.images()).max() > 0
    name = "a" + "é" * 119 + "b.checkpoint.gsd"  # 255 bytes, the most a name takes; byte 100 in an é
    assert len(name.encode()) == 255
    path = checkpoint.write(tmp_path / name, sim, {"frame": 1}, tracker=tracker)
    assert path.exists() and [p.name for p in tmp_path.iterdir()] == [name]
    again, _ = checkpoint.read(path)
    assert np.array_equal(again.image_tracker.images(), tracker.images())
    bare = checkpoint.write(tmp_path / "bare.gsd", sim, {"frame": 1})
    assert not np.any(checkpoint.read(bare)[0].image_tracker.images())
