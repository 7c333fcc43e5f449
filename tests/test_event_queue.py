"""The event scheme's two executions agree bit for bit: rounds with causal bounds (the GPU's)
and one queue of events (the CPU's, `circles.event.stepper.EVENT_QUEUE_ON_CPU`).

Both execute the same collisions in the same order with the same arithmetic per event, and
independent events touch disjoint circles, so the states must be equal exactly, not to a
tolerance: positions, velocities, collision counts, the pressure sums and the event log. The
scenes cover both boundaries and precisions, three mass models, a radius spread and steps cut
short because a collision would outrun the grid (light circles hit by heavy ones). Elsewhere
the suite runs the CPU's default, the queue, against the serial reference (test_reference)."""

import numpy as np
import pytest

from conftest import TEST_ARCH

SCENES = {
    "walls-f64-radius": dict(n=1500, box=(1.0, 1.0), radius=(0.004, 0.008), speed=(0.5, 1.0), boundary="walls",
                             precision="f64", mass="radius"),
    "periodic-f64-area": dict(n=1500, box=(1.0, 1.0), radius=(0.004, 0.008), speed=(0.5, 1.0),
                              boundary="periodic", precision="f64", mass="area"),
    "walls-f32-equal": dict(n=2000, box=(0.8, 0.8), radius=0.006, speed=(0.5, 1.0), boundary="walls",
                            precision="f32", mass="equal"),
    "periodic-f32-dense": dict(n=2000, box=(0.55, 0.55), radius=0.006, speed=(0.1, 1.0), boundary="periodic",
                               precision="f32", mass="radius"),
    "walls-f64-spread": dict(n=1200, box=(0.7, 0.7), radius=(0.002, 0.01), speed=(0.5, 1.0), boundary="walls",
                             precision="f64", mass="area"),
}

#: The parts' test also takes the steps cut short in float32 (the step's saved states, put back
#: at a cut, are in the working precision: `event.queue_parts`), and
#: speeds from 0 up, where the split's reaches (`event._reach_of`) differ most from circle to
#: circle: a slow circle by a border reaches far only when a fast one can hit it first.
PARTS_SCENES = dict(SCENES, **{"walls-f32-radius": dict(SCENES["walls-f64-radius"], precision="f32"),
                               "walls-f32-slow-fast": dict(SCENES["walls-f32-equal"], speed=(0.0, 1.0),
                                                           mass="radius"),
                               # Wider than tall: the grid's rows are the box's columns
                               # (`simulation.TRANSPOSE_WIDE_GRIDS`), the strips vertical.
                               "walls-f32-wide": dict(SCENES["walls-f32-equal"], box=(1.6, 0.4)),
                               "periodic-f64-wide": dict(SCENES["periodic-f64-area"], box=(1.6, 0.625))})


def on_threads(monkeypatch):
    """Event scenes of any size run their loops on the CPU's threads, as a large scene's do
    (`backend.serial_loops` with its limits at 0)."""
    from circles import backend
    monkeypatch.setattr(backend, "SERIAL_N", 0)
    monkeypatch.setattr(backend, "EVENT_SERIAL_WORK", 0)


@pytest.mark.skipif(TEST_ARCH != "cpu", reason="the limits are a CPU's")
@pytest.mark.parametrize("threads", [1, 2, 8])
def test_event_scenes_up_to_a_work_limit_run_on_one_thread(circles_cpu, monkeypatch, threads):
    """The event scheme runs on one thread (one queue, `event.queue_step`) while its circles
    times the threads are at most EVENT_SERIAL_WORK, up to SERIAL_N circles whatever the
    threads, and with one thread below EVENT_PARTS_ONE_THREAD_N circles (from there in parts,
    taken in turn); the discrete scheme up to SERIAL_N circles."""
    from circles import backend
    monkeypatch.setattr(backend, "cpu_threads", lambda: threads)
    limit = backend.EVENT_SERIAL_WORK // threads
    alone = backend.EVENT_PARTS_ONE_THREAD_N
    assert alone == 500_000
    for n in (1, backend.SERIAL_N, limit, limit + 1, alone - 1, alone, 10**7):
        assert backend.serial_loops(n, "discrete") == (n <= backend.SERIAL_N), n
        expected = (n < alone) if threads == 1 else (n <= backend.SERIAL_N or n <= limit)
        assert backend.serial_loops(n, "event") == expected, (n, threads)


def assert_same_as_rounds(rounds, sim, keys=("pair_collisions",)):
    """The queue's run `sim` the same as the rounds' bit for bit: positions, velocities, the
    stats `keys` and the event log, after more than 1000 pair collisions. And every circle's
    clock is 0 between steps, as a step's first predictions take it (`event.STEP_START`), and
    on one thread it holds no event (the walls are offered in the pairs' pass,
    `event._first_events_once`)."""
    from circles.geometry import NO_EVENT
    assert not np.any(sim.tau.to_numpy())
    if sim._serial:
        assert np.all(sim._ev_p.to_numpy() == NO_EVENT)
    a, b = rounds.state(), sim.state()
    assert np.array_equal(a.pos, b.pos) and np.array_equal(a.vel, b.vel)
    sa, sb = rounds.stats(), sim.stats()
    for key in keys:
        assert sa[key] == sb[key], key
    assert sa["pair_collisions"] > 1000
    assert np.array_equal(rounds.events(), sim.events())


def run(circles, monkeypatch, scene, queue, steps=25):
    from circles.event import stepper as event_stepper
    monkeypatch.setattr(event_stepper, "EVENT_QUEUE_ON_CPU", queue)
    sim = circles.Simulation(circles.Scene(scheme="event", seed=3, **scene), record_events=100_000)
    assert sim._event_queue == (queue and TEST_ARCH == "cpu")
    sim.step(steps)
    return sim


@pytest.mark.skipif(TEST_ARCH != "cpu", reason="the queue runs on a CPU only")
@pytest.mark.parametrize("name", [name if name in ("walls-f64-radius", "walls-f64-spread")
                                  else pytest.param(name, marks=pytest.mark.slow) for name in SCENES])
def test_queue_equals_rounds_bit_for_bit(circles_cpu, monkeypatch, name):
    rounds = run(circles_cpu, monkeypatch, SCENES[name], False)
    queue = run(circles_cpu, monkeypatch, SCENES[name], True)
    a, b = rounds.state(), queue.state()
    assert np.array_equal(a.pos, b.pos)
    assert np.array_equal(a.vel, b.vel)
    sa, sb = rounds.stats(), queue.stats()
    for key in ("pair_collisions", "wall_collisions", "virial", "wall_impulse", "kinetic_energy"):
        assert sa[key] == sb[key], key
    ea, eb = rounds.events(), queue.events()
    assert len(ea) == sa["pair_collisions"] + sa["wall_collisions"] > 0
    assert np.array_equal(ea, eb)
    assert rounds.time == queue.time
    # One launch per step for the queue (one more per step cut short: the rest of the step),
    # several rounds per step for the other. Both cut the same steps short (the rounds redo
    # them; the queue stops where the collision is).
    assert queue.rounds == queue.steps + queue.cut_steps < rounds.rounds
    assert queue.cut_steps == rounds.cut_steps
    if name in ("walls-f64-radius", "walls-f64-spread"):
        # Steps are cut short here (a light circle hit by a heavy one).
        assert queue.cut_steps > 0


@pytest.mark.parametrize("queue", [True, False], ids=["queue", "rounds"])
def test_a_neighbour_that_turns_back_bounds_the_rounds(circles_cpu, monkeypatch, queue):
    """Three circles of radius 0.1 in a row along y = 5: l (x = 0.3) and k (x = 1.5) move left at
    1, m a little above k's row catches k up at 1.5. l hits the wall x = 0 at 0.2 and comes back
    at 1, so l and k meet at 0.7 (k then moves right at 1) and k meets m at 0.71. Before l's
    wall hit, k's own earliest event is m's at 0.75: a round that executes it with l's hit treats
    l as if it kept its course. A bound on when a neighbour can reach a circle must let the
    neighbour's velocity reverse (deviate at 2 vlim, not vlim). Times held to 1e-12 (a few
    roundings of numbers near 1); on a CPU the rounds must also equal the queue bit for bit."""
    from circles.event import stepper as event_stepper

    if queue and TEST_ARCH != "cpu":
        pytest.skip("the queue runs on a CPU only")

    def run(on_queue):
        monkeypatch.setattr(event_stepper, "EVENT_QUEUE_ON_CPU", on_queue)
        sim = circles_cpu.Simulation.from_arrays(
            np.array([[0.3, 5.0], [1.5, 5.0], [2.0482050807568877, 5.1]]),
            np.array([[-1.0, 0.0], [-1.0, 0.0], [-1.5, 0.0]]), np.full(3, 0.1), mass="equal", box=(20.0, 10.0),
            scheme="event", precision="f64", dt=2.0, record_events=100)
        sim.advance(1.0)
        return sim

    sim = run(queue)
    got = sim.events()
    assert got[:, 1:].tolist() == [[0, -1], [0, 1], [1, 2]]
    np.testing.assert_allclose(got[:, 0], [0.2, 0.7, 0.71], rtol=0, atol=1e-12)
    if not queue and TEST_ARCH == "cpu":
        other = run(True)
        assert np.array_equal(sim.state().vel, other.state().vel)
        assert np.array_equal(sim.state().pos, other.state().pos)
        assert np.array_equal(got, other.events())


@pytest.mark.slow
@pytest.mark.skipif(TEST_ARCH != "cpu", reason="the queue runs on a CPU only")
@pytest.mark.parametrize("name", ["walls-f32-equal", "periodic-f32-dense", "periodic-f64-area"])
def test_queue_on_several_threads_equals_rounds(circles_cpu, monkeypatch, name):
    """Scenes this small run the queue's first predictions on one thread, each pair's time
    offered to both circles (event._first_events_once), and the grid build and the finish
    serially too (backend.serial_loops); with its limits at 0 they run as a large scene's
    do, on several threads, each circle searching all its cells. The state must equal the
    rounds' bit for bit."""

    rounds = run(circles_cpu, monkeypatch, SCENES[name], False)
    on_threads(monkeypatch)
    sim = run(circles_cpu, monkeypatch, SCENES[name], True)
    assert not sim._serial and sim._event_queue
    assert_same_as_rounds(rounds, sim)


@pytest.mark.skipif(TEST_ARCH != "cpu", reason="the queue runs on a CPU only")
@pytest.mark.parametrize("name,claims", [("walls-f32-equal", 4), pytest.param("walls-f64-radius", 4, marks=pytest.mark.slow),
                                         pytest.param("walls-f32-radius", 4, marks=pytest.mark.slow),
                                         pytest.param("periodic-f64-area", 4, marks=pytest.mark.slow), ("walls-f32-slow-fast", 4),
                                         pytest.param("walls-f64-radius", 16, marks=pytest.mark.slow),
                                         pytest.param("walls-f32-radius", 16, marks=pytest.mark.slow),
                                         ("walls-f32-equal", 10**9), ("walls-f32-wide", 4),
                                         pytest.param("periodic-f64-wide", 4, marks=pytest.mark.slow)],
                         ids=["windows", "cut-steps", "cut-steps-f32", "periodic", "slow-fast", "cut-windows",
                              "cut-windows-f32", "no-split", "wide", "wide-periodic"])
def test_queue_in_parts_equals_rounds(circles_cpu, monkeypatch, name, claims):
    """Circles split into parts of about 200 (event.split_parts), each part's
    events run from its own queue, the parts shared among the threads (event.queue_parts):
    the state and the event log must equal the rounds' bit for bit. In the equal-mass scene
    the clusters of linked circles grow past what a split may claim (a quarter of the
    circles), so the steps run in windows; the radius-mass scene has steps cut short by a
    collision that would outrun the grid (the step runs again from its start up to it, every
    circle put back), in either precision, and with room for a sixteenth of the circles in the
    claims, those cuts come in later windows too (asserted); in the periodic box
    the strips' borders wrap around (the last strip's is with the first). With room for no
    claims at all every split fails, and the steps fall back to one queue for all circles.
    Scenes of equal circles run the parts with the radius and inverse mass as the queue's
    arguments (`event.Same`), the others with their arrays, as the rounds do."""
    from circles.event import stepper as event_stepper

    rounds = run(circles_cpu, monkeypatch, PARTS_SCENES[name], False)
    on_threads(monkeypatch)
    monkeypatch.setattr(event_stepper, "PART_CIRCLES", 200)
    monkeypatch.setattr(event_stepper, "PART_CLAIMS", claims)
    # The windows a step in parts had run when it met a cut (its restore).
    runs_at_cuts = []
    step_start = [0]
    parts_step = event_stepper.EventStepper._queue_parts_step
    restore = event_stepper.EventStepper._restore

    def counted_step(self, *args):
        step_start[0] = self.parts_run
        return parts_step(self, *args)

    def counted_restore(self, *args, **kwargs):
        runs_at_cuts.append(self.parts_run - step_start[0])
        return restore(self, *args, **kwargs)

    monkeypatch.setattr(event_stepper.EventStepper, "_queue_parts_step", counted_step)
    monkeypatch.setattr(event_stepper.EventStepper, "_restore", counted_restore)
    sim = run(circles_cpu, monkeypatch, PARTS_SCENES[name], True)
    assert sim._parts and sim._part_shape()[0] >= 4
    assert (sim._same is not None) == np.isscalar(PARTS_SCENES[name]["radius"])
    assert sim.grid.transposed == name.endswith("-wide") == rounds.grid.transposed
    if claims in (4, 16):
        assert sim.parts_run >= sim.steps  # every step ran in parts, one window or more
    else:
        assert sim.parts_run == 0 and sim._windows == event_stepper.MOST_WINDOWS
    if name == "walls-f32-equal" and claims == 4:
        assert sim._windows > 1
    assert_same_as_rounds(rounds, sim, ("pair_collisions", "wall_collisions", "virial", "wall_impulse"))
    assert sim.cut_steps == rounds.cut_steps
    if name.endswith("-radius"):
        assert sim.cut_steps > 0
    if claims == 16:
        assert max(runs_at_cuts) > 1  # a cut met in a window after the first


@pytest.mark.skipif(TEST_ARCH != "cpu", reason="the queue runs on a CPU only")
@pytest.mark.parametrize("name,parts", [("walls-f32-radius", False),
                                        pytest.param("periodic-f32-dense", False, marks=pytest.mark.slow),
                                        pytest.param("walls-f32-radius", True, marks=pytest.mark.slow),
                                        pytest.param("periodic-f64-area", True, marks=pytest.mark.slow)],
                         ids=["one-queue", "one-queue-periodic", "parts-cut-steps", "parts-periodic"])
def test_queue_finish_measures_the_next_steps_speed(circles_cpu, monkeypatch, name, parts):
    """The queue's finish (`event.finish`, and `event.queue_step`'s own) also measures the
    largest speed of the state it leaves, for the next step's grid and speed limit: it must be
    the value of a separate pass over the circles (`reductions.max_speed`) bit for bit after
    every step, in one queue and in parts, with steps cut short, and it is forgotten as the
    next step starts and when the state is loaded anew. One queue on one thread also leaves no
    event held (`event.queue_step`: its next first predictions take the walls in the pairs'
    pass)."""
    from circles import reductions
    from circles.event import stepper as event_stepper
    from circles.geometry import NEVER, NO_EVENT

    if parts:
        on_threads(monkeypatch)
        monkeypatch.setattr(event_stepper, "PART_CIRCLES", 200)
    sim = circles_cpu.Simulation(circles_cpu.Scene(scheme="event", seed=3, **PARTS_SCENES[name]))
    if parts and not sim._parts:
        pytest.skip("one thread: no parts")
    assert sim._parts == parts and sim._known_speed is None
    for _ in range(12):
        sim.step(1)
        measured = reductions.max_speed(sim.pos, sim.vel, sim._speed_out, sim._serial)
        assert sim._known_speed is not None and sim._known_speed == measured > 0
        if not parts:
            # One queue on one thread also clears every event for its next first predictions,
            # NEVER as every kernel writes it (a float32 literal in the working precision).
            assert np.all(sim._ev_p.to_numpy() == NO_EVENT)
            assert np.all(sim._ev_t.to_numpy() == sim._np_real(np.float32(NEVER)))
    assert (sim.parts_run >= 12) == parts
    if name.endswith("-radius"):
        assert sim.cut_steps > 0
    sim._upload(*sim._download())
    assert sim._known_speed is None


@pytest.mark.skipif(TEST_ARCH != "cpu", reason="the queue runs on a CPU only")
@pytest.mark.parametrize("name", [pytest.param("walls-f64-radius", marks=pytest.mark.slow), "periodic-f64-area"])
def test_parts_with_a_full_sum_log_equal_rounds(circles_cpu, monkeypatch, name):
    """The parts' events write what they add to the counts and sums to a log, added once the
    step is done (`event.queue_parts`, `event.apply_sums`). With a log far too short for a
    step's events, a step that fills it is put back (positions and velocities from the backup,
    the log dropped) and runs from one queue, and the log doubles for later steps: the state,
    the sums and the event log still equal the rounds' bit for bit. The scene with radii has
    steps cut short too (their redo drops the log of the windows it ran)."""
    from circles.event import stepper as event_stepper

    rounds = run(circles_cpu, monkeypatch, PARTS_SCENES[name], False)
    on_threads(monkeypatch)
    monkeypatch.setattr(event_stepper, "PART_CIRCLES", 200)
    monkeypatch.setattr(event_stepper, "SUM_LOG_PER_CIRCLE", 0.002)  # 3 entries for 1500 circles
    monkeypatch.setattr(event_stepper, "SUM_LOG_MOST_PER_CIRCLE", 0.05)
    sim = run(circles_cpu, monkeypatch, PARTS_SCENES[name], True)
    assert sim._parts and sim.parts_run > 0
    assert sim.sum_log_full >= 2  # filled again after it first grew
    assert sim._sum_log[0].shape[0] == int(0.05 * sim.n)  # grown to its most
    assert_same_as_rounds(rounds, sim, ("pair_collisions", "wall_collisions", "virial", "wall_impulse"))
    assert sim.cut_steps == rounds.cut_steps
    if name.endswith("-radius"):
        assert sim.cut_steps > 0


@pytest.mark.slow
@pytest.mark.skipif(TEST_ARCH != "cpu", reason="the queue runs on a CPU only")
def test_a_copy_carries_the_steps_that_filled_the_sum_log(circles_cpu, monkeypatch):
    """A copy carries the event scheme's counters of work (`EventStepper.WORK_COUNTERS`), the
    steps whose parts filled the sum log among them, and goes on as the original does (its
    own sum log starts short again, which changes no state)."""
    from circles.event import stepper as event_stepper

    on_threads(monkeypatch)
    monkeypatch.setattr(event_stepper, "PART_CIRCLES", 200)
    monkeypatch.setattr(event_stepper, "SUM_LOG_PER_CIRCLE", 0.002)
    monkeypatch.setattr(event_stepper, "SUM_LOG_MOST_PER_CIRCLE", 0.05)
    sim = run(circles_cpu, monkeypatch, PARTS_SCENES["walls-f64-radius"], True, steps=10)
    copy = sim.copy()
    assert sim._parts and sim.sum_log_full >= 1
    assert copy.stepper.work() == sim.stepper.work()
    sim.step(3)
    copy.step(3)
    assert np.array_equal(copy.state().pos, sim.state().pos)
    assert np.array_equal(copy.state().vel, sim.state().vel)


@pytest.mark.skipif(TEST_ARCH != "cpu", reason="the queue runs on a CPU only")
def test_equal_radii_with_masses_of_their_own_keep_the_arrays(circles_cpu, monkeypatch):
    """The event kernels take the radius and inverse mass as arguments (`event.Same`) only when
    both are one value for every circle as the kernels store them (`Simulation._same_circles`):
    circles of one radius with masses given one by one keep the arrays, and their queue in
    parts still equals the rounds bit for bit; with one mass for all they take the arguments,
    the values the arrays would hold."""
    from circles.event import stepper as event_stepper

    scene = PARTS_SCENES["walls-f32-equal"]
    start = circles_cpu.Simulation(circles_cpu.Scene(scheme="event", seed=3, **scene)).state()
    mass = np.random.default_rng(5).uniform(0.5, 2.0, scene["n"])

    def run_own(queue, masses):
        monkeypatch.setattr(event_stepper, "EVENT_QUEUE_ON_CPU", queue)
        sim = circles_cpu.Simulation.from_arrays(start.pos, start.vel, scene["radius"], masses, box=scene["box"],
                                                 precision="f32", record_events=100_000)
        sim.step(25)
        return sim

    rounds = run_own(False, mass)
    on_threads(monkeypatch)
    monkeypatch.setattr(event_stepper, "PART_CIRCLES", 200)
    sim = run_own(True, mass)
    assert sim._parts and sim.parts_run > 0 and sim._same is None
    assert_same_as_rounds(rounds, sim, ("pair_collisions", "wall_collisions", "virial", "wall_impulse"))
    equal = circles_cpu.Simulation.from_arrays(start.pos, start.vel, scene["radius"], np.full(scene["n"], 3.0),
                                               box=scene["box"], precision="f32")
    assert equal._same == (equal.radius.to_numpy()[0], equal.inv_mass.to_numpy()[0])
    assert np.all(equal.radius.to_numpy() == equal._same[0])
    assert np.all(equal.inv_mass.to_numpy() == equal._same[1])


@pytest.mark.slow
@pytest.mark.skipif(TEST_ARCH != "cpu", reason="the queue runs on a CPU only")
def test_one_queue_of_a_small_scene_after_failed_splits_equals_rounds(circles_cpu, monkeypatch):
    """400 circles at area fraction 0.75 with their loops on the threads and no room for claims:
    every split fails (clusters cross the borders), so each step runs from one queue, whose
    calendar then uses the parts' array of bucket heads, longer than the circles are many.
    Every bucket must start empty (stale lists from an earlier step once gave wrong events and
    crashes), and the state and events must equal the rounds' bit for bit."""
    from circles.event import stepper as event_stepper

    scene = dict(n=400, box=(0.164, 0.164), radius=0.004, speed=(0.5, 1.0), boundary="walls", precision="f64")
    rounds = run(circles_cpu, monkeypatch, scene, False, steps=6)
    on_threads(monkeypatch)
    monkeypatch.setattr(event_stepper, "PART_CLAIMS", 10**9)
    sim = run(circles_cpu, monkeypatch, scene, True, steps=6)
    if sim._head.shape[0] <= sim.n:
        pytest.skip("one thread: no parts' calendar")
    assert sim._parts and sim.parts_run == 0 and sim.rounds == sim.steps + sim.cut_steps
    assert_same_as_rounds(rounds, sim)


@pytest.mark.slow
@pytest.mark.skipif(TEST_ARCH != "cpu", reason="the queue runs on a CPU only")
def test_parts_come_in_multiples_of_the_threads(circles_cpu, monkeypatch):
    """A split into parts (`Simulation._part_shape`) asks for a multiple of the threads, so that
    they finish their shares together: one part more than the threads' count of PART_CIRCLES
    rounds up to twice the threads, on a grid with rows enough for that."""
    from circles.event import stepper as event_stepper
    from circles.grid import count_parts

    threads = count_parts()
    if threads < 2:
        pytest.skip("one thread: no parts")
    on_threads(monkeypatch)
    scene = SCENES["walls-f32-equal"]
    monkeypatch.setattr(event_stepper, "PART_CIRCLES", scene["n"] // (threads + 1))
    sim = circles_cpu.Simulation(circles_cpu.Scene(scheme="event", seed=3, **scene))
    sim.step(1)
    assert sim._parts and sim.grid.ncy // event_stepper.PART_MIN_ROWS >= 2 * threads
    parts, rows = sim._part_shape()
    assert parts == 2 * threads and rows * (parts - 1) < sim.grid.ncy <= rows * parts


@pytest.mark.slow
@pytest.mark.skipif(TEST_ARCH != "cpu", reason="the queue runs on a CPU only")
@pytest.mark.parametrize("boundary", ["walls", "periodic"])
def test_split_keeps_linked_circles_in_one_part(circles_cpu, monkeypatch, boundary):
    """event.split_parts on 4000 circles (speeds from 0 to 1, so that slow circles sit beside
    fast ones) in strips of about 300, for a window of a quarter step. Every pair of linked
    circles lies in one part: pairs within the sum of their radii and their reaches, found
    here by brute force over all pairs, a circle's reach being the farthest it can travel in
    the window (`event._reach_of`: at its own speed until the nearest circle could reach it at
    the speed limit vlim, then at vlim). Those links are far fewer than the pairs within
    2 vlim times the window, the bound for any two circles. The parts' lists (a strip's
    circles labelled with it, then the circles claimed for it, labelled -1 - k) hold every
    circle once, in parts of the sizes the split reports. And the window itself, run from
    one queue for all circles, has no collision between two parts. The split also clears every
    circle's flags of the window's searches (touched, dirty)."""
    from circles import event, reductions
    from circles.event import stepper as event_stepper
    from circles.geometry import spans
    from circles.event.stepper import SPEED_MARGIN

    on_threads(monkeypatch)
    monkeypatch.setattr(event_stepper, "PART_CIRCLES", 300)
    n, box = 4000, np.array([1.0, 1.0])
    sim = circles_cpu.Simulation(circles_cpu.Scene(n=n, box=tuple(box), radius=0.005, speed=(0.0, 1.0),
                                                   boundary=boundary, scheme="event", precision="f64", seed=2),
                                 record_events=100_000)
    sim.step(3)
    periodic = boundary == "periodic"
    vlim = SPEED_MARGIN * sim._max_speed()  # as the step after this one sets it
    window = 0.25 * sim.dt
    margin = 2 * vlim * window  # two circles closing in at vlim for the window
    g = sim.grid
    g.build(sim.pos, 2 * sim._rmax + margin)
    parts, rows_per = sim._part_shape()
    assert sim._parts and parts >= 8
    rows, segs = spans(g.ncx, g.ncy, periodic)
    reductions.fill_i32(sim._touched, 1)
    reductions.fill_i32(sim._dirty_w, 1)
    assert event.split_parts(sim.pos, sim.vel, sim.tau, sim.radius, sim._label, sim._claimed, sim._d1,
                             sim._touched, sim._dirty_w, sim._part_info, g.cell_of, g.cell_start, g.sorted_ids, g.ncx, g.ncy, rows, segs,
                             rows_per, parts, *box, 0.0, window, vlim, sim._link_allowance, sim._same_args()[0],
                             sim._real, periodic, sim._same is not None)
    assert not sim._touched.to_numpy().any() and not sim._dirty_w.to_numpy().any()
    label = sim._label.to_numpy()
    part = label ^ (label >> 31)
    pos, vel, r = sim.pos.to_numpy(), sim.vel.to_numpy(), sim.radius.to_numpy()  # every clock is at 0

    def pairs_from(lo):
        d = pos[None, :, :] - pos[lo:lo + 500, None, :]
        if periodic:
            d -= box * np.round(d / box)
        dist = np.sqrt((d ** 2).sum(-1))
        dist[np.arange(len(dist)), np.arange(lo, lo + len(dist))] = np.inf
        return dist, r[lo:lo + 500, None] + r[None, :]

    gap = np.concatenate([(dist - s).min(axis=1) for dist, s in map(pairs_from, range(0, n, 500))])
    speed = np.sqrt((vel ** 2).sum(-1))
    free = np.minimum(np.maximum(gap, 0) / (speed + vlim), window)
    reach = (speed * free + vlim * (window - free)) * 1.01
    linked = loose = 0
    for lo in range(0, n, 500):
        dist, s = pairs_from(lo)
        i, j = np.nonzero(dist < s + reach[lo:lo + 500, None] + reach[None, :])
        i += lo
        assert np.array_equal(part[i], part[j])
        linked += len(i)
        loose += np.sum(dist < s + margin)
    assert linked > 1000 and loose > 1.5 * linked  # pairs linked (each counted from both circles)
    assert np.sum(label < 0) > 20  # circles claimed with their clusters across borders
    info, claimed = sim._part_info.to_numpy(), sim._claimed.to_numpy()
    sorted_ids, cell_start = g.sorted_ids.to_numpy(), g.cell_start.to_numpy()

    def row_start(y):
        return y * g.ncx if periodic else (y + 1) * (g.ncx + 1)

    members = []
    for k in range(parts):
        y1 = g.ncy if k == parts - 1 else (k + 1) * rows_per
        strip = sorted_ids[cell_start[row_start(k * rows_per)]:cell_start[row_start(y1)]]
        claims = sorted_ids[claimed[info[parts + 1 + k]:info[2 * parts + 1 + k]]]
        assert np.all(label[claims] == -1 - k)
        mine = np.concatenate([strip[label[strip] == k], claims])
        assert len(mine) == info[k + 1] - info[k]
        members.append(mine)
    assert np.array_equal(np.sort(np.concatenate(members)), np.arange(n))
    # The window from one queue for all circles (`_split_wait`: no split for a while).
    start, logged = sim.time, len(sim.events())
    sim.stepper._split_wait = 10
    sim.advance(window)
    ev = sim.events()
    ev = ev[(ev[:, 2] >= 0) & (ev[:, 0] > start)]  # pair collisions in the window
    assert len(sim.events()) > logged and len(ev) > 50
    slot = np.argsort(sim.ids.to_numpy())  # creation id -> slot (no reorder since the split)
    assert np.array_equal(part[slot[ev[:, 1].astype(int)]], part[slot[ev[:, 2].astype(int)]])


@pytest.mark.skipif(TEST_ARCH != "cpu", reason="the queue runs on a CPU only")
def test_queue_step_to_an_exact_time(circles_cpu, monkeypatch):
    """advance() ends steps at a given time (a step shorter than dt): the same in both."""
    states = []
    for queue in (False, True):
        sim = run(circles_cpu, monkeypatch, SCENES["walls-f32-equal"], queue, steps=3)
        sim.advance(0.37 * sim.dt)
        states.append(sim.state())
    assert np.array_equal(states[0].pos, states[1].pos)
    assert np.array_equal(states[0].vel, states[1].vel)


def lattice_head_on(side=40):
    """side x side circles of radius 1/64 on a square lattice of spacing 1/16, the columns moving
    along x at +0.5, 0, -0.5, +0.5, ...: every number is a short binary fraction, so each
    resting circle is hit from both sides at one instant, and all rows alike (hundreds of
    events share one time; which of a circle's two comes first is set by the ids alone); the
    circles then meet the next columns and the walls the same way."""
    s = 1.0 / 16
    col, row = np.meshgrid(np.arange(side), np.arange(side))
    pos = np.stack([(col.ravel() + 0.5) * s, (row.ravel() + 0.5) * s], axis=1)
    vel = np.zeros_like(pos)
    vel[:, 0] = 0.5 * (1 - col.ravel() % 3)
    radius = np.full(side * side, 1.0 / 64)
    return pos, vel, radius, (side * s, side * s)


@pytest.mark.skipif(TEST_ARCH != "cpu", reason="the queue runs on a CPU only")
@pytest.mark.parametrize("scene", ["lattice", "walls-f32-equal", "walls-f64-spread"])
def test_queue_calendar_any_bucket_width(circles_cpu, monkeypatch, scene):
    """The queue keeps its events in a calendar of buckets in front of a small heap
    (event.queue_step). However wide the buckets, from one bucket for the whole step (every
    event in the heap) to one bucket per circle (nearly every event poured from a list), it
    hands out the events in key order, so the states and event logs equal the rounds' bit for
    bit: on a lattice whose events come hundreds at one instant, ordered by ids alone, and on
    two scenes of the suite (one with steps cut short)."""
    from circles.event import stepper as event_stepper

    def make(queue, per_bucket):
        monkeypatch.setattr(event_stepper, "EVENT_QUEUE_ON_CPU", queue)
        monkeypatch.setattr(event_stepper, "QUEUE_BUCKET_CIRCLES", per_bucket)
        if scene == "lattice":
            pos, vel, radius, box = lattice_head_on()
            sim = circles_cpu.Simulation.from_arrays(pos, vel, radius, box=box, scheme="event", precision="f64",
                                                     record_events=100_000)
        else:
            sim = circles_cpu.Simulation(circles_cpu.Scene(scheme="event", seed=3, **SCENES[scene]),
                                         record_events=100_000)
        sim.step(30 if scene == "lattice" else 15)
        return sim

    rounds = make(False, 4)
    ev = rounds.events()
    if scene == "lattice":
        _, count = np.unique(ev[:, 0], return_counts=True)
        assert count.max() >= 400 and rounds.stats()["pair_collisions"] >= 3000
    for per_bucket in (10**9, 1):
        sim = make(True, per_bucket)
        assert sim._head.shape[0] == (1 if per_bucket > 1 else sim.n)
        a, b = rounds.state(), sim.state()
        assert np.array_equal(a.pos, b.pos) and np.array_equal(a.vel, b.vel)
        assert np.array_equal(ev, sim.events())
        assert sim.cut_steps == rounds.cut_steps


@pytest.mark.skipif(TEST_ARCH != "cpu", reason="the queue runs on a CPU only")
@pytest.mark.parametrize("precision,tiny", [("f32", 1e-36), ("f64", 1e-300)])
def test_queue_step_of_1e_36_with_touching_pairs(circles_cpu, monkeypatch, precision, tiny):
    """A first step of 1e-36 (1e-300 in float64) over 800 pairs that touch and approach at the
    start: their collisions come at time 0 of a step whose calendar has 400 buckets, so the
    bucket of time t is t * 400 / 1e-36, past float32's range (event._bucket works in float64
    and clamps). Every pair collides in that step, and the queue equals the rounds bit for
    bit, then and after 3 more steps."""
    from circles.event import stepper as event_stepper

    k, row = (a.ravel() for a in np.meshgrid(np.arange(20), np.arange(40)))
    x = (4 * k + 1) / 16.0
    y = (row + 0.5) / 8
    pos = np.concatenate([np.stack([x, y], 1), np.stack([x + 1 / 16, y], 1)])  # 2 r apart
    vel = np.concatenate([np.tile([0.5, 0.0], (800, 1)), np.tile([-0.5, 0.0], (800, 1))])
    runs = []
    for queue in (True, False):
        monkeypatch.setattr(event_stepper, "EVENT_QUEUE_ON_CPU", queue)
        sim = circles_cpu.Simulation.from_arrays(pos, vel, np.full(1600, 1 / 32), box=(5.0, 5.0), scheme="event",
                                                 precision=precision)
        assert sim._head.shape[0] == (400 if queue else 1)
        sim.advance(tiny)
        assert sim.stats()["pair_collisions"] == 800
        first = sim.state()
        sim.step(3)
        runs.append((first, sim.state()))
    for a, b in zip(*runs):
        assert np.array_equal(a.pos, b.pos) and np.array_equal(a.vel, b.vel)
    assert np.all(runs[0][0].vel[:800, 0] == -0.5)  # equal masses, head on: velocities swapped


@pytest.mark.parametrize("queue", [True, False], ids=["queue", "rounds"])
def test_event_step_stops_on_circles_jammed_across_the_box(circles_cpu, monkeypatch, queue):
    """Three rows of three circles that fill their box exactly (each touching its neighbours and
    the walls), moving at +0.5, 0, -0.5: no circle can move, so the collisions at time 0 never
    end. The step stops after `event.most_events` events (MOST_EVENTS_PER_CIRCLE a circle, at
    least MOST_EVENTS_ANY_STEP) with an error that names the limit and the way out, instead of running for ever: on the queue (a CPU), and in
    the rounds (a GPU's execution), which count their events from circles.event.stepper.JAM_CHECK_ROUNDS
    rounds on."""
    from circles import event
    from circles.event import stepper as event_stepper

    if queue and TEST_ARCH != "cpu":
        pytest.skip("the queue runs on a CPU only")
    monkeypatch.setattr(event_stepper, "EVENT_QUEUE_ON_CPU", queue)
    # Both read the limit at every step (`event.most_events`): a lower one keeps the test short
    # (each round executes a few of the jam's events).
    monkeypatch.setattr(event_stepper, "MOST_EVENTS_PER_CIRCLE", 100)
    monkeypatch.setattr(event_stepper, "MOST_EVENTS_ANY_STEP", 100)
    pos, vel, radius, box = lattice_head_on(3)
    sim = circles_cpu.Simulation.from_arrays(pos, vel, 2 * radius, box=box, scheme="event", precision="f64")
    assert sim.stats()["max_overlap"] <= 1e-12  # touching, not overlapping
    with pytest.raises(RuntimeError, match=f"more than {event.most_events(sim.n)} events .*"
                                           "jammed.*scheme='discrete'.*shorter dt"):
        sim.step(1)
    if queue:
        # It stopped at the first event past the limit it was given.
        stats = sim.stats()
        assert stats["pair_collisions"] + stats["wall_collisions"] == event.most_events(sim.n) + 1
    else:
        # It stopped at a check (after JAM_CHECK_ROUNDS rounds, then at every doubling) that
        # found more events than the limit. A round may run no counted collision (at one
        # instant the keys order a jam's contacts, some of them touching without approaching).
        checks = event_stepper.JAM_CHECK_ROUNDS * 2 ** np.arange(12)
        assert sim.rounds in checks
        stats = sim.stats()
        assert stats["pair_collisions"] + stats["wall_collisions"] > event.most_events(sim.n)


@pytest.mark.skipif(TEST_ARCH != "cpu", reason="the queue runs on a CPU only")
@pytest.mark.parametrize("precision", [pytest.param("f32", marks=pytest.mark.slow), "f64"])
def test_two_level_queue_equals_one_level_bit_for_bit(circles_cpu, monkeypatch, precision):
    """A walled box with 2% of the circles 10 times larger: the queue's grid has two levels
    (cells sized for the small circles, the large ones also in coarse cells, see
    event.build_coarse). It must meet exactly the pairs that can collide in a step, as the
    one-level queue and the rounds do, so all three agree bit for bit: small-small,
    small-large and large-large collisions, walls, and steps cut short (asserted to occur)."""
    from circles import simulation
    from circles.event import stepper as event_stepper
    from physics_util import two_size_mixture

    pos, vel, radius, box = two_size_mixture(precision)

    def make(max_fraction, queue):
        monkeypatch.setattr(simulation, "TWO_LEVEL_MAX_FRACTION", max_fraction)
        monkeypatch.setattr(event_stepper, "EVENT_QUEUE_ON_CPU", queue)
        sim = circles_cpu.Simulation.from_arrays(pos, vel, radius, mass="radius", box=box, scheme="event",
                                                 precision=precision, record_events=100_000)
        sim.step(40)  # 40 steps: the arrays are reordered on the way (REORDER_EVERY), the large list with them
        return sim

    two = make(0.05, True)
    one = make(0.0, True)
    rounds = make(0.05, False)
    assert two._two_level and not one._two_level and not rounds._two_level
    # In this 1.5:1 box a one-level grid runs along the box's y (`simulation.TRANSPOSE_WIDE_GRIDS`),
    # a two-level one keeps the box's axes: the same pairs either way.
    assert not two.grid.transposed and one.grid.transposed and rounds.grid.transposed
    assert two.grid.ncx > 3 * one.grid.ncy  # the fine cells along x are sized for the small circles
    coarse_start, coarse_ids, ncx_c, ncy_c, mx, my = two._levels[:6]
    assert mx > 3 and my > 3
    listed = coarse_ids.to_numpy()
    assert sorted(two._ids[listed]) == list(range(20))  # the coarse cells list the large circles, once each
    assert coarse_start.to_numpy()[ncx_c * ncy_c] == 20
    ev = two.events()
    lo, hi = ev[:, 1], ev[:, 2]  # creation ids; a wall's hi is its negative code
    assert np.sum((lo < 20) & (hi >= 20)) > 100  # small-large pairs
    assert np.sum((hi >= 0) & (hi < 20)) > 0  # large-large pairs
    assert np.sum((lo >= 20) & (hi >= 0)) > 1000 and np.sum(hi < 0) > 100  # small-small pairs, walls
    assert two.cut_steps > 0
    for other in (one, rounds):
        a, b = two.state(), other.state()
        assert np.array_equal(a.pos, b.pos) and np.array_equal(a.vel, b.vel)
        sa, sb = two.stats(), other.stats()
        for key in ("pair_collisions", "wall_collisions", "virial", "wall_impulse"):
            assert sa[key] == sb[key], key
        assert np.array_equal(ev, other.events())
        assert two.cut_steps == other.cut_steps


@pytest.mark.skipif(TEST_ARCH != "cpu", reason="the queue runs on a CPU only")
@pytest.mark.parametrize("per_bucket", [10**9, 1])
def test_parts_calendar_any_bucket_width(circles_cpu, monkeypatch, per_bucket):
    """Each part's queue keeps its calendar in its own buckets of the shared array of heads, from
    info[k] // QUEUE_BUCKET_CIRCLES + k on (event.queue_parts): a part with fewer circles than a
    bucket holds still takes one bucket of its own (the `+ k`). With buckets wider than a part
    (every part one bucket) the parts' buckets would all be the first one without it, and
    threads filling their parts' queues at once would pour each other's circles. However wide
    the buckets, the state and the event log in parts equal the rounds' bit for bit. Parts of
    2000 circles, so that the threads' first parts of a window fill their queues at the same
    time (with parts of 200 the race was seen once in four runs; the suite's default width, 4
    circles a bucket, never gives a part fewer than one bucket of its own)."""
    from circles.event import stepper as event_stepper

    side = 0.8 * np.sqrt(10)
    scene = dict(SCENES["walls-f32-equal"], n=20000, box=(side, side))
    rounds = run(circles_cpu, monkeypatch, scene, False, steps=10)
    on_threads(monkeypatch)
    monkeypatch.setattr(event_stepper, "PART_CIRCLES", 2000)
    monkeypatch.setattr(event_stepper, "QUEUE_BUCKET_CIRCLES", per_bucket)
    sim = run(circles_cpu, monkeypatch, scene, True, steps=10)
    if not sim._parts:
        pytest.skip("one thread: no parts")
    assert sim._part_shape()[0] >= 4 and sim.parts_run >= sim.steps
    assert_same_as_rounds(rounds, sim, ("pair_collisions", "wall_collisions", "virial", "wall_impulse"))


@pytest.mark.skipif(TEST_ARCH != "cpu", reason="the queue runs on a CPU only")
@pytest.mark.parametrize("in_parts", [False, True], ids=["one-queue", "parts"])
def test_queue_uses_the_bucket_width_its_heads_were_made_for(circles_cpu, monkeypatch, in_parts):
    """A simulation's calendar heads are made for the QUEUE_BUCKET_CIRCLES of its making, and
    its queue's kernels use that width, though they were compiled for another: a Taichi kernel
    reads a module's constant once, when it compiles, so a kernel that read the width itself
    kept the first simulation's (4 circles a bucket), and in parts wrote past the end of heads
    made for wider buckets (the suite crashed once in test_parts_calendar_any_bucket_width).
    With one circle a bucket, a step touches one head a circle: n of them in one queue, and in
    parts n plus at most one more for each part of each window (`event.queue_parts`), against
    about n / 4 at the compiled width. Heads are filled with a mark first; the touched ones are
    those that no longer hold it."""
    from circles.event import stepper as event_stepper

    side = 0.8 * np.sqrt(10)
    scene = dict(SCENES["walls-f32-equal"], n=20000, box=(side, side))
    if in_parts:
        on_threads(monkeypatch)
        monkeypatch.setattr(event_stepper, "PART_CIRCLES", 2000)
    run(circles_cpu, monkeypatch, scene, True, steps=2)  # the kernels compiled (or found) at the default width
    monkeypatch.setattr(event_stepper, "QUEUE_BUCKET_CIRCLES", 1)
    sim = run(circles_cpu, monkeypatch, scene, True, steps=2)
    if in_parts and not sim._parts:
        pytest.skip("one thread: no parts")
    assert sim._parts == in_parts
    mark = 12345
    sim._head.from_numpy(np.full(sim._head.shape, mark, dtype=np.int32))
    windows = sim.parts_run
    sim.step(1)
    touched = int(np.count_nonzero(sim._head.to_numpy() != mark))
    if in_parts:
        assert sim.n <= touched <= sim.n + sim._part_shape()[0] * (sim.parts_run - windows)
    else:
        assert touched == sim.n


@pytest.mark.slow
@pytest.mark.skipif(TEST_ARCH != "cpu", reason="the queue runs on a CPU only")
def test_split_fails_when_a_border_needs_one_claim_more_than_its_share(circles_cpu, monkeypatch):
    """event.split_parts gives each border an equal share of `claimed` (its length over the
    borders): a border whose clusters need even one slot more than that must fail the split
    (return 0), for past its share lies the next border's list (or, for the last border, the
    array's end). The scene and window of test_split_keeps_linked_circles_in_one_part: a first
    split with room enough counts each border's claims; with a share one below the largest
    count the split fails, and with a share equal to it the split holds, with the same lists,
    each inside its own share."""
    import taichi as ti

    from circles import event
    from circles.event import stepper as event_stepper
    from circles.geometry import spans
    from circles.event.stepper import SPEED_MARGIN

    on_threads(monkeypatch)
    monkeypatch.setattr(event_stepper, "PART_CIRCLES", 300)
    n, box = 4000, (1.0, 1.0)
    sim = circles_cpu.Simulation(circles_cpu.Scene(n=n, box=box, radius=0.005, speed=(0.0, 1.0), boundary="walls",
                                                   scheme="event", precision="f64", seed=2))
    sim.step(3)
    if not sim._parts:
        pytest.skip("one thread: no parts")
    vlim = SPEED_MARGIN * sim._max_speed()
    window = 0.25 * sim.dt
    g = sim.grid
    g.build(sim.pos, 2 * sim._rmax + 2 * vlim * window)
    parts, rows_per = sim._part_shape()
    borders = parts - 1
    rows, segs = spans(g.ncx, g.ncy, False)

    def split(claimed):
        ok = event.split_parts(sim.pos, sim.vel, sim.tau, sim.radius, sim._label, claimed, sim._d1, sim._touched,
                               sim._dirty_w, sim._part_info, g.cell_of, g.cell_start, g.sorted_ids, g.ncx, g.ncy, rows, segs, rows_per, parts,
                               *box, 0.0, window, vlim, sim._link_allowance, sim._same_args()[0], sim._real,
                               False, sim._same is not None)
        info = sim._part_info.to_numpy()
        lo, hi = info[parts + 1:parts + 1 + borders], info[2 * parts + 1:2 * parts + 1 + borders]
        return ok, lo, hi, claimed.to_numpy(), sim._label.to_numpy()

    ok, lo, hi, roomy, label = split(sim._claimed)
    count = hi - lo
    most = int(count.max())
    assert ok and parts >= 8 and most >= 3 and np.sum(label < 0) == count.sum()
    tight = ti.ndarray(ti.i32, shape=(most - 1) * borders)
    ok_tight = split(tight)[0]
    exact = ti.ndarray(ti.i32, shape=most * borders)
    ok_exact, lo_e, hi_e, lists, label_e = split(exact)
    assert ok_tight == 0, f"a border with {most} claims held in a share of {most - 1}"
    assert ok_exact == 1 and np.array_equal(hi_e - lo_e, count) and np.array_equal(label_e, label)
    for b in range(borders):
        assert b * most == lo_e[b] <= hi_e[b] <= (b + 1) * most
        assert np.array_equal(np.sort(lists[lo_e[b]:hi_e[b]]), np.sort(roomy[lo[b]:hi[b]]))


@pytest.mark.skipif(TEST_ARCH != "cpu", reason="the queue runs on a CPU only")
def test_a_split_that_fails_after_a_window_ran_refines_the_rest_of_the_step(circles_cpu, monkeypatch):
    """A split that fails after some windows of a step ran (Simulation._queue_parts_step)
    doubles the windows and the count of those done, so that the next window starts where the
    last one ended: the windows that run tile the step, each from the end of the one before
    and of positive length. The suite's scenes fail their splits only at a step's start (none
    after a window ran, counted over 40 steps of the windows scene), so here the split is made
    to fail once at the step's start (two windows) and once at the start of each step's second
    window (four); the state and event log must still equal the rounds' bit for bit."""
    from circles import event
    from circles.event import stepper as event_stepper
    from circles.event import split as event_split

    scene = PARTS_SCENES["walls-f32-equal"]
    rounds = run(circles_cpu, monkeypatch, scene, False)
    on_threads(monkeypatch)
    monkeypatch.setattr(event_stepper, "PART_CIRCLES", 200)
    monkeypatch.setattr(event_stepper, "PART_CLAIMS", 4)
    split = event.split_parts
    steps = []  # per step (a split that holds at time 0 starts one): (start, length) of its windows
    state = {"start_failed": False, "step_failed": True, "mid_step_failures": 0, "sim": None}

    def failing_split(*args):
        t, length = args[-8], args[-7]  # (t, window, vlim, allowance, r_same, real, periodic, same)
        if t == 0 and not state["start_failed"]:
            state["start_failed"] = True
            return 0
        if t > 0 and not state["step_failed"] and state["sim"]._windows < event_stepper.MOST_WINDOWS:
            state["step_failed"] = True
            state["mid_step_failures"] += 1
            return 0
        ok = split(*args)
        if ok:
            if t == 0:
                steps.append([])
                state["step_failed"] = False
            steps[-1].append((t, length))
        return ok

    monkeypatch.setattr(event_split, "split_parts", failing_split)
    monkeypatch.setattr(event_stepper, "EVENT_QUEUE_ON_CPU", True)
    sim = circles_cpu.Simulation(circles_cpu.Scene(scheme="event", seed=3, **scene), record_events=100_000)
    if not sim._parts:
        pytest.skip("one thread: no parts")
    state["sim"] = sim
    sim.step(25)
    assert state["mid_step_failures"] >= 3  # splits failed after a window had run
    for windows in steps:
        assert all(length > 0 for _, length in windows), windows
        assert all(b[0] == pytest.approx(a[0] + a[1], rel=1e-12) for a, b in zip(windows, windows[1:])), windows
    assert_same_as_rounds(rounds, sim, ("pair_collisions", "wall_collisions", "virial", "wall_impulse"))


def _cascade(velocities, masses):
    """1-D elastic collisions along a row of touching circles at one instant, in key order: the
    approaching pair of lowest ids first, until none approaches (exact, in fractions)."""
    from fractions import Fraction

    v = [Fraction(x) for x in velocities]
    m = [Fraction(x) for x in masses]
    while True:
        i = next((i for i in range(len(v) - 1) if v[i] > v[i + 1]), None)
        if i is None:
            return [float(x) for x in v]
        a, b = m[i], m[i + 1]
        v[i], v[i + 1] = ((a - b) * v[i] + 2 * b * v[i + 1]) / (a + b), ((b - a) * v[i + 1] + 2 * a * v[i]) / (a + b)


@pytest.mark.skipif(TEST_ARCH != "cpu", reason="the queue runs on a CPU only")
@pytest.mark.parametrize("masses", [[1, 2, 0.5, 3, 1, 7], [7, 1, 3, 0.5, 2, 1]])
def test_collisions_at_one_instant_run_in_key_order_in_the_rounds_as_in_the_queue(circles_cpu, monkeypatch,
                                                                                   masses):
    """A Newton's cradle of unequal masses: after the first hit every collision of the row falls
    at one instant, and their order (the keys': lowest ids first) decides the outcome. The
    rounds ran an event whose bound equalled its time in the same round as one of lower key
    that made a third event with one of its circles, first: another order than the queue's
    (circle 4 left at +0.25 instead of -0.039). Now the bounds carry the key of the event that
    sets them, and both give the cascade in key order, bit for bit between them."""
    from circles.event import stepper as event_stepper

    r = 0.125
    pos = np.array([[0.5, 1.0]] + [[1.0 + 0.25 * k, 1.0] for k in range(5)])  # a row in contact, exactly
    vel = np.array([[1.0, 0.0]] + [[0.0, 0.0]] * 5)
    runs = {}
    for queue in (True, False):
        monkeypatch.setattr(event_stepper, "EVENT_QUEUE_ON_CPU", queue)
        sim = circles_cpu.Simulation.from_arrays(pos, vel, r, mass=masses, box=(4.0, 2.0), record_events=100)
        sim.advance(0.5)  # the hit at 0.25, then the circles part; no wall is reached
        runs[queue] = sim
    expected = _cascade([1, 0, 0, 0, 0, 0], masses)
    for sim in runs.values():
        assert sim.state().vel[:, 0] == pytest.approx(expected, rel=1e-12, abs=1e-15)
    queue, rounds = runs[True].state(), runs[False].state()
    assert np.array_equal(queue.pos, rounds.pos) and np.array_equal(queue.vel, rounds.vel)
    assert np.array_equal(runs[True].events(), runs[False].events())
    # A row resting against a wall, hit from the other side: the wall's events take part.
    row = np.array([[0.125 + 0.25 * k, 1.0] for k in range(4)] + [[2.0, 1.0]])
    ends = []
    for queue in (True, False):
        monkeypatch.setattr(event_stepper, "EVENT_QUEUE_ON_CPU", queue)
        sim = circles_cpu.Simulation.from_arrays(row, np.array([[0.0, 0.0]] * 4 + [[-1.0, 0.0]]), r,
                                                 mass=masses[:5], box=(4.0, 2.0), record_events=1000)
        sim.advance(3.0)
        ends.append((sim.state(), sim.stats()["pair_collisions"], sim.stats()["wall_collisions"]))
    (a, pa, wa), (b, pb, wb) = ends
    assert (pa, wa) == (pb, wb) and pa > 4
    assert np.array_equal(a.pos, b.pos) and np.array_equal(a.vel, b.vel)
