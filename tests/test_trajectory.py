"""GSD trajectories (circles.trajectory) read back with gsd.hoomd, and stats tables
(circles.writers): the file equals the state, a frame restarts a run bit for bit, image flags
unwrap to the integrated motion, and writing a trajectory does not change the run."""

import math

import gsd.hoomd
import numpy as np
import pytest

from circles import observables
from circles.trajectory import GSDWriter, ImageTracker, read_simulation, type_names, unwrapped
from circles.writers import Run, StatsWriter, frame_times, read_stats, stats_rows


def periodic_scene(circles, precision="f64", scheme="event", n=60, seed=2, radius=0.1):
    return circles.Scene(n=n, box=(3.0, 2.0), radius=radius, speed=(1.0, 2.0), boundary="periodic",
                         scheme=scheme, precision=precision, seed=seed)


@pytest.mark.parametrize("boundary", ["periodic", "walls"])
def test_gsd_frames_equal_the_state(circles_cpu, tmp_path, boundary):
    sim = circles_cpu.Simulation(circles_cpu.Scene(n=50, box=(3.0, 2.0), radius=(0.05, 0.1), speed=(0.5, 1.0),
                                                   boundary=boundary, seed=4))
    path = tmp_path / "run.gsd"
    states, stats, steps = [], [], []
    with GSDWriter(path) as writer:
        for _ in range(3):
            writer.write(sim)
            states.append(sim.state())
            stats.append(sim.stats())
            steps.append(sim.steps)
            sim.advance(0.3)
    w, h = sim.box
    with gsd.hoomd.open(str(path)) as traj:
        assert len(traj) == 3
        for k, frame in enumerate(traj):
            s = states[k]
            assert frame.configuration.dimensions == 2
            assert list(frame.configuration.box) == [3.0, 2.0, 0, 0, 0, 0]
            assert frame.particles.N == 50
            # The steps taken when the frame was written: 0, then at least the steps of 0.3 s.
            assert frame.configuration.step == steps[k]
            assert steps[k] >= math.ceil(k * 0.3 / sim.dt - 1e-9)
            np.testing.assert_array_equal(frame.particles.position[:, 0], (s.pos[:, 0] - w / 2).astype(np.float32))
            np.testing.assert_array_equal(frame.particles.position[:, 1], (s.pos[:, 1] - h / 2).astype(np.float32))
            assert np.all(frame.particles.position[:, 2] == 0)
            np.testing.assert_array_equal(frame.particles.velocity[:, :2], s.vel.astype(np.float32))
            np.testing.assert_array_equal(frame.particles.diameter, (2 * s.radius).astype(np.float32))
            np.testing.assert_array_equal(frame.particles.mass, s.mass.astype(np.float32))
            typeid, types = type_names(s.radius)
            assert len(types) == 1  # 50 radii drawn from a range: one type for all
            np.testing.assert_array_equal(frame.particles.typeid, typeid)
            np.testing.assert_array_equal(frame.log["particles/circles/position"], s.pos)
            np.testing.assert_array_equal(frame.log["particles/circles/velocity"], s.vel)
            assert frame.log["circles/time"][0] == stats[k]["time"]
            assert frame.log["circles/kinetic_energy"][0] == stats[k]["kinetic_energy"]
            assert frame.log["circles/pair_collisions"][0] == stats[k]["pair_collisions"]
            if boundary == "periodic":
                assert frame.particles.image.shape == (50, 3)
            else:
                assert not np.any(frame.particles.image)


def test_types_one_per_radius():
    typeid, types = type_names(np.array([0.2, 0.1, 0.2, 0.3]))
    assert types == ["A", "B", "C"] and list(typeid) == [1, 0, 1, 2]


def test_types_name_up_to_26_radii_and_one_type_beyond():
    """26 radii are A to Z, each circle's type id as GSD's uint32; a 27th makes one type A."""
    radius = np.linspace(0.1, 0.35, 26)[::-1]
    typeid, types = type_names(radius)
    assert types == [chr(c) for c in range(ord("A"), ord("Z") + 1)]
    assert typeid.dtype == np.uint32 and list(typeid) == list(range(25, -1, -1))
    typeid, types = type_names(np.append(radius, 0.4))
    assert types == ["A"] and typeid.dtype == np.uint32 and not typeid.any()


@pytest.mark.parametrize("precision,boundary", [("f64", "periodic"), ("f32", "periodic"), ("f64", "walls")])
def test_a_frame_restarts_the_run_bit_for_bit(circles_cpu, tmp_path, precision, boundary):
    """The state of a frame, and each circle's share of the stats totals, so that the totals go
    on exactly; in a box whose sides float32 does not hold (configuration/box is float32)."""
    scene = periodic_scene(circles_cpu, precision)
    scene = circles_cpu.Scene.from_dict({**scene.to_dict(), "box": [3.1, 2.3], "boundary": boundary})
    sim = circles_cpu.Simulation(scene)
    sim.advance(0.4)
    path = tmp_path / "run.gsd"
    sim_time, steps = sim.time, sim.steps
    if boundary == "periodic":
        with GSDWriter(path, tracker=None) as writer, pytest.raises(ValueError, match="before its first step"):
            writer.write(sim)
    with GSDWriter(path, tracker=ImageTracker(sim) if boundary == "periodic" else None) as writer:
        writer.write(sim)
        sim.advance(0.5)
        writer.write(sim)
    restarted = read_simulation(path, 0)
    assert (restarted.time, restarted.steps, restarted.dt) == (sim_time, steps, sim.dt)
    assert (restarted.precision, restarted.boundary, restarted.scheme) == (precision, boundary, "event")
    assert restarted.box == sim.box == (3.1, 2.3)
    restarted.advance(0.5)
    a, b = sim.state(), restarted.state()
    for name in ("pos", "vel", "radius", "mass", "color"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    after, again = sim.stats(), restarted.stats()
    for name in ("pair_collisions", "wall_collisions", "virial", "wall_impulse", "kinetic_energy"):
        assert again[name] == after[name], name
    assert after["pair_collisions"] > 50 and (boundary == "periodic" or after["wall_collisions"] > 10)
    if boundary == "walls":
        return
    # The images carried on from the frame equal those counted by the run itself.
    with gsd.hoomd.open(str(path)) as traj:
        np.testing.assert_array_equal(restarted.image_tracker.images(), traj[1].particles.image[:, :2])


@pytest.mark.parametrize("scheme", ["event", "discrete"])
def test_image_flags_unwrap_to_the_integrated_motion(circles_cpu, tmp_path, scheme):
    """Unwrapped positions from the file against displacements summed every 0.05 of simulated
    time (the minimum image of each displacement, in numpy): equal to round-off, over a run in
    which circles cross the box several times."""
    sim = circles_cpu.Simulation(periodic_scene(circles_cpu, scheme=scheme, n=40, radius=0.05))
    path = tmp_path / "run.gsd"
    box = np.array(sim.box)
    start = sim.state().pos
    moved = np.zeros_like(start)
    previous = start
    expected = []
    with GSDWriter(path) as writer:
        for k in range(81):
            if k % 20 == 0:
                writer.write(sim)
                expected.append(start + moved)
            sim.advance(0.05)  # at most 0.1 (speeds up to 2) of the box's 2 by 3 per check
            now = sim.state().pos
            d = now - previous
            moved += d - box * np.round(d / box)
            previous = now
    with gsd.hoomd.open(str(path)) as traj:
        frames = list(traj)
    assert np.abs(frames[-1].particles.image).max() >= 2  # crossed the box more than once
    for frame, want in zip(frames, expected):
        np.testing.assert_allclose(unwrapped(frame) + box / 2, want, rtol=0, atol=1e-9)


def test_a_trajectory_does_not_change_the_run(circles_cpu, tmp_path):
    plain = circles_cpu.Simulation(periodic_scene(circles_cpu))
    watched = circles_cpu.Simulation(periodic_scene(circles_cpu))
    with GSDWriter(tmp_path / "run.gsd") as writer:
        for _ in range(4):
            writer.write(watched)
            watched.advance(0.25)
    for _ in range(4):  # the same pieces: an advance's last step ends at its end
        plain.advance(0.25)
    a, b = plain.state(), watched.state()
    np.testing.assert_array_equal(a.pos, b.pos)
    np.testing.assert_array_equal(a.vel, b.vel)


def test_stats_rows_from_python_and_csv(circles_cpu, tmp_path):
    scene = circles_cpu.Scene(n=40, box=(3.0, 2.0), radius=0.08, speed=(0.5, 1.0), seed=5)
    sim = circles_cpu.Simulation(scene)
    rows = list(stats_rows(sim, 1.0, 4))
    assert len(rows) == 4 and [r["time"] for r in rows] == [0.25, 0.5, 0.75, 1.0]
    assert all(tuple(r) == observables.COLUMNS for r in rows)
    # The rates over the intervals add up to the totals since the start.
    total = sim.stats()
    assert sum(r["collision_rate"] * 0.25 * sim.n / 2 for r in rows) == pytest.approx(total["pair_collisions"])
    z = np.mean([r["compressibility"] for r in rows])
    assert z == pytest.approx(total["compressibility"], rel=0.05)  # equal interval lengths, nearly equal kT
    again = circles_cpu.Simulation(scene)
    path = tmp_path / "run.csv"
    with StatsWriter(path) as table:
        run = Run(again, 1.0, 4, at_interval=[table])
        for _ in run:
            pass
    columns = read_stats(path)
    assert list(columns) == list(observables.COLUMNS)
    for name in observables.COLUMNS:
        np.testing.assert_array_equal(columns[name], [r[name] for r in rows])


def test_csv_leaves_the_wall_pressure_empty_in_a_periodic_box(circles_cpu, tmp_path):
    sim = circles_cpu.Simulation(periodic_scene(circles_cpu))
    path = tmp_path / "run.csv"
    with StatsWriter(path) as table:
        for row in stats_rows(sim, 0.5, 4):
            table.write(row)
    lines = path.read_text().splitlines()
    wall, pressure = (observables.COLUMNS.index(name) for name in ("wall_pressure", "pressure"))
    assert len(lines) == 3 and all(line.split(",")[wall] == "" for line in lines[1:])
    assert all(math.isfinite(float(line.split(",")[pressure])) for line in lines[1:])


def test_frame_times():
    assert frame_times(1.0, 4) == [0.0, 0.25, 0.5, 0.75, 1.0]
    assert frame_times(0.9, 4) == [0.0, 0.25, 0.5, 0.75, 0.9]
    assert frame_times(0.1, 4) == [0.0, 0.1]


def test_a_restarted_run_goes_on_with_the_same_trajectory(circles_cpu, tmp_path):
    """Frames appended after a restart from the last frame equal those of the run that did not
    stop, image flags included."""
    whole, split = tmp_path / "whole.gsd", tmp_path / "split.gsd"
    sim = circles_cpu.Simulation(periodic_scene(circles_cpu, n=40, radius=0.05))
    with GSDWriter(whole) as writer:
        for _ in range(4):
            writer.write(sim)
            sim.advance(0.6)
    sim = circles_cpu.Simulation(periodic_scene(circles_cpu, n=40, radius=0.05))
    with GSDWriter(split) as writer:
        for _ in range(2):
            writer.write(sim)
            sim.advance(0.6)
    restarted = read_simulation(split, -1)
    restarted.advance(0.6)
    with GSDWriter(split, "a", tracker=restarted.image_tracker) as writer:
        for _ in range(2):
            writer.write(restarted)
            restarted.advance(0.6)
    with gsd.hoomd.open(str(whole)) as a, gsd.hoomd.open(str(split)) as b:
        assert len(a) == len(b) == 4
        assert np.abs(a[3].particles.image).max() >= 1
        for k in range(4):
            for chunk in ("position", "velocity", "image"):
                np.testing.assert_array_equal(getattr(a[k].particles, chunk), getattr(b[k].particles, chunk))
            assert a[k].configuration.step == b[k].configuration.step


def test_check_path_refuses_with_the_fix_and_makes_missing_folders(tmp_path):
    from circles.trajectory import check_path

    made = []
    path = check_path(tmp_path / "a" / "b" / "run.gsd", made=made)
    assert path == tmp_path / "a" / "b" / "run.gsd" and made == [tmp_path / "a", tmp_path / "a" / "b"]
    assert (tmp_path / "a" / "b").is_dir() and not path.exists()
    assert check_path(str(tmp_path / "RUN.GSD")) == tmp_path / "RUN.GSD"  # the suffix in any case
    for bad, words in ((tmp_path / "run.csv", f"--trajectory {tmp_path / 'run.csv'}: the file name must end in .gsd, "
                                              "e.g. run.gsd"),
                       (tmp_path / "a.gsd", f"--trajectory {tmp_path / 'a.gsd'} is a folder: give a file's path, such "
                                            f"as {tmp_path / 'a.gsd' / 'run.gsd'}")):
        if bad.suffix == ".gsd":
            bad.mkdir()
        with pytest.raises(ValueError) as refused:
            check_path(bad)
        assert str(refused.value) == words
    (tmp_path / "old.csv").write_text("x")
    with pytest.raises(ValueError) as refused:
        check_path(tmp_path / "old.csv", suffix=".csv", what="--stats")
    assert str(refused.value) == (f"--stats {tmp_path / 'old.csv'} exists: give --force to overwrite it, --resume to "
                                  "continue its run, or another name")
    assert check_path(tmp_path / "old.csv", force=True, suffix=".csv") == tmp_path / "old.csv"


def test_frames_of_older_files_restart_from_their_totals(circles_cpu, tmp_path):
    """A frame without each circle's shares (and without the float64 box), as circles wrote
    them before: the totals go on circle 0, a count beyond int32 spread over the first circles."""
    import gsd.fl

    sim = circles_cpu.Simulation(circles_cpu.Scene(n=30, box=(3.0, 2.0), radius=0.1, speed=(1.0, 2.0), seed=3))
    sim.advance(1.0)
    path, old = tmp_path / "new.gsd", tmp_path / "old.gsd"
    with GSDWriter(path) as writer:
        writer.write(sim)
    totals = np.array([5e9, 7.0, 1.25, 2.5])
    with gsd.fl.open(str(path), "r") as new, gsd.fl.open(str(old), "w", application="circles", schema="hoomd",
                                                          schema_version=[1, 4]) as out:
        for name in new.find_matching_chunk_names(""):
            if name in ("log/circles/box", "log/circles/totals") or name.startswith("log/particles/circles/") and \
                    name.split("/")[-1] in ("pair_count", "wall_count", "virial", "wall_impulse"):
                continue
            out.write_chunk(name, new.read_chunk(0, name))
        out.write_chunk("log/circles/totals", totals)
        out.end_frame()
    again = read_simulation(old)
    fields = again._fields()
    assert again.box == (3.0, 2.0)
    assert fields["pair_count"][:3].tolist() == [2 ** 31 - 1, 2 ** 31 - 1, 5 * 10 ** 9 - 2 * (2 ** 31 - 1)]
    assert fields["pair_count"][3:].sum() == 0 and fields["wall_count"].tolist() == [7] + [0] * 29
    assert fields["virial"].tolist() == [1.25] + [0.0] * 29 and fields["wall_impulse"].tolist() == [2.5] + [0.0] * 29
    stats = again.stats()
    assert (stats["pair_collisions"], stats["wall_collisions"], stats["virial"], stats["wall_impulse"]) == \
        (5 * 10 ** 9, 7, 1.25, 2.5)


def test_the_writer_and_reader_refuse_with_one_line(circles_cpu, tmp_path):
    import gsd.fl

    periodic = circles_cpu.Simulation(periodic_scene(circles_cpu))
    path = tmp_path / "run.gsd"
    with GSDWriter(path) as writer:
        assert (writer.frames, writer.seconds, writer.cpu_seconds, writer.order) == (0, 0.0, 0.0, False)
        periodic.step(1)
        with pytest.raises(ValueError) as refused:
            writer.write(periodic)
    assert str(refused.value) == ("a periodic run's trajectory must start before its first step, so that every wrap "
                                  "is counted: make the GSDWriter (or an ImageTracker) at the start")
    with gsd.fl.open(str(path), "r") as file:
        assert file.schema == "hoomd" and tuple(file.schema_version) == (1, 4) and file.nframes == 0
    with pytest.raises(ValueError, match=f"^{path} holds no frames$"):
        read_simulation(path)
    with gsd.fl.open(str(tmp_path / "hoomd.gsd"), "w", application="hoomd", schema="hoomd",
                     schema_version=[1, 4]) as file:
        file.write_chunk("particles/N", np.array([1], np.uint32))
        file.end_frame()
    with pytest.raises(ValueError) as refused:
        read_simulation(tmp_path / "hoomd.gsd")
    assert str(refused.value) == (f"{tmp_path / 'hoomd.gsd'} was not written by circles (no "
                                  "log/particles/circles/position chunk): read it with gsd.hoomd")
    walls = circles_cpu.Simulation(circles_cpu.Scene(n=5, box=(3.0, 2.0), radius=0.1, seed=1))
    with pytest.raises(ValueError) as refused:
        ImageTracker(walls)
    assert str(refused.value) == "image flags count wraps of a periodic box; this simulation has walls"
    tracker = ImageTracker(circles_cpu.Simulation(periodic_scene(circles_cpu)))
    assert tracker in tracker.sim.after_step
    tracker.detach()
    assert tracker not in tracker.sim.after_step
    tracker.detach()  # again: nothing to do
    with GSDWriter(tmp_path / "order.gsd", order=1) as writer:
        assert writer.order is True


def test_unwrapped_takes_the_float32_positions_of_a_frame_without_the_full_ones():
    import gsd.hoomd

    frame = gsd.hoomd.Frame()
    frame.configuration.box = [4.0, 2.0, 0, 0, 0, 0]
    frame.particles.N = 2
    frame.particles.position = np.array([[0.5, -0.25, 0.0], [-1.0, 0.75, 0.0]], np.float32)
    frame.particles.image = np.array([[1, 0, 0], [-2, 3, 0]], np.int32)
    got = unwrapped(frame)
    assert got.dtype == np.float64
    np.testing.assert_array_equal(got, [[4.5, -0.25], [-9.0, 6.75]])


def test_order_writes_each_circles_psi6_and_the_global_order(circles_cpu, tmp_path):
    """With order=True a frame holds psi_6 of each circle (real, imaginary) in creation order and
    |mean psi_6|, as circles.order computes them from the frame's positions; without, neither."""
    from circles.order import hexatic_order, psi6

    sim = circles_cpu.Simulation(periodic_scene(circles_cpu, n=60))
    sim.advance(0.3)
    path = tmp_path / "order.gsd"
    with GSDWriter(path, order=True, tracker=False) as writer:
        writer.write(sim)
    with gsd.hoomd.open(str(path)) as traj:
        log = traj[0].log
    local = psi6(sim.state().pos, sim.box, True)
    np.testing.assert_array_equal(log["particles/circles/psi6"], np.stack([local.real, local.imag], axis=1))
    assert log["circles/hexatic_order"].tolist() == [hexatic_order(local)]
    assert 0 < hexatic_order(local) < 1
    with GSDWriter(tmp_path / "plain.gsd", tracker=False) as writer:
        writer.write(sim)
    with gsd.hoomd.open(str(tmp_path / "plain.gsd")) as traj:
        assert "particles/circles/psi6" not in traj[0].log and "circles/hexatic_order" not in traj[0].log


def test_older_totals_go_on_circle_0_as_32_bit_counts():
    from circles.trajectory import _totals_on_circle_0

    fields = _totals_on_circle_0(np.array([2.0 ** 31, 3.0, 0.5, 0.25]), 4)
    assert fields["pair_count"].dtype == np.int32 and fields["wall_count"].dtype == np.int32
    assert fields["pair_count"].tolist() == [2 ** 31 - 1, 1, 0, 0] and fields["wall_count"].tolist() == [3, 0, 0, 0]
    assert fields["virial"].dtype == np.float64 and fields["virial"].tolist() == [0.5, 0.0, 0.0, 0.0]
    assert fields["wall_impulse"].tolist() == [0.25, 0.0, 0.0, 0.0]


def test_a_trajectory_in_a_folder_that_cannot_be_made_names_itself(tmp_path):
    from circles.trajectory import check_path

    (tmp_path / "file").write_text("x")
    with pytest.raises(ValueError, match=f"--trajectory {tmp_path / 'file' / 'run.gsd'}"):
        check_path(tmp_path / "file" / "run.gsd")


def test_unwrapped_takes_the_full_precision_box_where_the_frame_has_it(circles_cpu, tmp_path):
    """In a box whose sides float32 does not hold, the unwrapped positions come from the float64
    positions and box: position - W/2 + image W, exactly."""
    sim = circles_cpu.Simulation(circles_cpu.Scene(n=20, box=(3.1, 2.3), radius=0.05, speed=(2.0, 3.0),
                                                   boundary="periodic", seed=2))
    with GSDWriter(tmp_path / "run.gsd") as writer:
        writer.write(sim)
        sim.advance(1.5)
        writer.write(sim)
        image = writer.tracker.images()
    with gsd.hoomd.open(str(tmp_path / "run.gsd")) as traj:
        frame = traj[1]
    box = np.array([3.1, 2.3])
    assert np.abs(image).max() > 0
    np.testing.assert_array_equal(unwrapped(frame), sim.state().pos - 0.5 * box + image * box)


#: The chunks of a frame, with the type and shape each has (n circles, k types of width w):
#: HOOMD's schema (https://gsd.readthedocs.io, "HOOMD Schema") and circles' own log chunks.
FIRST_FRAME_ONLY = {"configuration/box": ("float32", (6,)), "configuration/dimensions": ("uint8", (1,)),
                    "particles/N": ("uint32", (1,)), "particles/types": ("int8", ("k", "w")),
                    "particles/typeid": ("uint32", ("n",)), "particles/diameter": ("float32", ("n",)),
                    "particles/mass": ("float32", ("n",)), "log/particles/circles/radius": ("float64", ("n",)),
                    "log/particles/circles/mass": ("float64", ("n",)),
                    "log/particles/circles/color": ("uint8", ("n", 3))}
EVERY_FRAME = {"configuration/step": ("uint64", (1,)), "particles/position": ("float32", ("n", 3)),
               "particles/velocity": ("float32", ("n", 3)), "log/circles/box": ("float64", (2,)),
               "log/circles/dt": ("float64", (1,)), "log/circles/time": ("float64", (1,)),
               "log/circles/precision_bits": ("uint8", (1,)), "log/circles/totals": ("float64", (4,)),
               "log/particles/circles/position": ("float64", ("n", 2)),
               "log/particles/circles/velocity": ("float64", ("n", 2)),
               "log/particles/circles/pair_count": ("int32", ("n",)),
               "log/particles/circles/virial": ("float64", ("n",))}


@pytest.mark.parametrize("boundary", ["periodic", "walls"])
def test_every_chunk_has_the_schemas_type_and_shape_and_the_values_of_the_state(circles_cpu, tmp_path, boundary):
    """Each chunk of the first two frames, read raw with gsd.fl: its type and shape as the
    schemas fix them, no chunk beyond them, and the values a reader takes from it: the box,
    2 dimensions, the step count, N, the type names, the totals and the run's JSON with sorted
    keys."""
    import json

    import gsd.fl

    from circles import Scene, Simulation

    sim = Simulation(Scene(n=30, radius=[0.1, 0.2], box=(4.0, 3.0), boundary=boundary, seed=2))
    path = tmp_path / "t.gsd"
    run = {"z": 1, "a": [2, 3]}
    writer = GSDWriter(path, run=run, order=True)
    before = sim.stats()
    writer.write(sim)
    sim.advance(0.3)
    after = sim.stats()
    steps = sim.steps
    writer.write(sim, observables.interval(before, after, 30, sim.box, boundary, 0.15), after)
    sim.advance(0.1)
    writer.write(sim, observables.interval(after, sim.stats(), 30, sim.box, boundary, 0.15))  # its totals taken now
    writer.close()
    walls = {"log/particles/circles/wall_count": ("int32", ("n",)),
             "log/particles/circles/wall_impulse": ("float64", ("n",))} if boundary == "walls" else {}
    image = {"particles/image": ("int32", ("n", 3))} if boundary == "periodic" else {}
    first = {**FIRST_FRAME_ONLY, "log/circles/boundary": ("uint8", (len(boundary),)),
             "log/circles/scheme": ("uint8", (5,)), "log/circles/run": ("uint8", ("j",)),
             "log/circles/hexatic_order": ("float64", (1,)), "log/particles/circles/psi6": ("float64", ("n", 2))}
    sizes = {"n": 30, "k": 1, "w": 2, "j": len(json.dumps(run, sort_keys=True))}  # 30 radii: one type, "A"
    rows = {f"log/circles/{name}": ("float64", (1,)) for name in observables.COLUMNS}
    with gsd.fl.open(str(path), "r") as f:
        names = set(f.find_matching_chunk_names(""))
        for frame, expected in ((0, {**first, **EVERY_FRAME, **walls, **image, **rows}),
                                (1, {**EVERY_FRAME, **walls, **image, **rows,
                                     "log/circles/hexatic_order": ("float64", (1,)),
                                     "log/particles/circles/psi6": ("float64", ("n", 2)),
                                     "log/circles/boundary": ("uint8", (len(boundary),)),
                                     "log/circles/scheme": ("uint8", (5,))})):
            held = {name for name in names if f.chunk_exists(frame, name)}
            assert held == set(expected), (frame, sorted(held ^ set(expected)))
            for name, (dtype, shape) in expected.items():
                data = f.read_chunk(frame, name)
                assert str(data.dtype) == dtype, (frame, name)
                assert data.shape == tuple(sizes.get(s, s) for s in shape), (frame, name)
        assert f.read_chunk(0, "configuration/box").tolist() == [4.0, 3.0, 0, 0, 0, 0]
        assert f.read_chunk(0, "configuration/dimensions").tolist() == [2]
        assert f.read_chunk(0, "particles/N").tolist() == [30]
        assert f.read_chunk(1, "configuration/step").tolist() == [steps] and steps > 0
        assert f.read_chunk(0, "particles/types").view("S2").ravel().tolist() == [b"A"]
        assert f.read_chunk(1, "log/circles/precision_bits").tolist() == [64]
        assert f.read_chunk(1, "log/circles/totals").tolist() == [after["pair_collisions"], after["wall_collisions"],
                                                                  after["virial"], after["wall_impulse"]]
        assert bytes(f.read_chunk(0, "log/circles/run")).decode() == json.dumps(run, sort_keys=True)
        final = sim.stats()
        assert f.read_chunk(2, "log/circles/totals").tolist() == [final["pair_collisions"], final["wall_collisions"],
                                                                  final["virial"], final["wall_impulse"]]
        assert f.read_chunk(1, "log/circles/dt").tolist() == [sim.dt]
        assert f.read_chunk(1, "log/circles/box").tolist() == [4.0, 3.0]


def test_the_writer_counts_its_frames_and_the_time_it_spends(circles_cpu, tmp_path, monkeypatch):
    """frames, seconds and cpu_seconds add up over writes: a clock that moves 1 s at each
    reading makes each write last 1 s of each."""
    import itertools
    import time

    from circles import Scene, Simulation

    sim = Simulation(Scene(n=20, radius=0.1, box=(3.0, 3.0), seed=1))
    writer = GSDWriter(tmp_path / "t.gsd")
    ticks, cpu = itertools.count(0.0), itertools.count(0.0)
    monkeypatch.setattr(time, "perf_counter", lambda: float(next(ticks)))
    monkeypatch.setattr(time, "process_time", lambda: float(next(cpu)))
    for _ in range(3):
        writer.write(sim)
    monkeypatch.undo()
    writer.close()
    assert writer.frames == 3 and writer.seconds == 3.0 and writer.cpu_seconds == 3.0
