"""Single collisions with known outcomes, through ``Simulation.from_arrays``.

The exact outcomes follow from momentum and energy conservation along the
contact normal. Where the normal is exactly (1, 0) (head-on along x) the
arithmetic of the impulse is exact but for a few roundings, so velocities are
held to 1e-14 of the speed; where the normal is computed from a root (glancing
hits, time of impact) a few more roundings enter, still far below 1e-12.
"""

import math

import numpy as np
import pytest

from conftest import TEST_ARCH
from reference import Reference

BOX = (1.0, 1.0)
R = 0.05


def two(circles, pos, vel, mass, scheme="event", dt=None, box=BOX, radius=(R, R), **kw):
    return circles.Simulation.from_arrays(
        np.array(pos, float), np.array(vel, float), np.array(radius, float),
        mass=np.array(mass, float), box=box, boundary="walls", scheme=scheme,
        precision="f64", dt=dt, **kw)


@pytest.mark.parametrize("scheme", ["event", "discrete"])
def test_head_on_equal_masses_swap_velocities(circles_cpu, scheme):
    """Both schemes resolve a head-on hit with the same impulse: an exact swap.
    The event scheme also places the hit at t = gap / closing speed = 0.15, so
    after 0.2 the circles are back at 0.40 and 0.60."""
    sim = two(circles_cpu, [[0.3, 0.5], [0.7, 0.5]], [[1.0, 0.0], [-1.0, 0.0]], [1.0, 1.0],
              scheme=scheme, dt=0.01)
    sim.advance(0.2)
    s = sim.state()
    assert s.vel == pytest.approx(np.array([[-1.0, 0.0], [1.0, 0.0]]), abs=1e-14)
    st = sim.stats()
    assert st["pair_collisions"] == 1 and st["wall_collisions"] == 0
    assert st["kinetic_energy"] == pytest.approx(1.0, rel=1e-14)
    if scheme == "event":
        assert s.pos == pytest.approx(np.array([[0.4, 0.5], [0.6, 0.5]]), abs=1e-14)
        # |J| = 2 |vn| / (w_i + w_j) = 2, virial = (r_i + r_j) |J|
        assert st["virial"] == pytest.approx(2 * R * 2.0, rel=1e-14)
        assert st["max_overlap"] == 0.0


@pytest.mark.parametrize("scheme", ["event", "discrete"])
def test_unequal_masses_follow_1d_formula(circles_cpu, scheme):
    """v1' = ((m1 - m2) v1 + 2 m2 v2) / (m1 + m2), v2' likewise, and momentum
    and energy unchanged to round-off."""
    m1, m2, v1, v2 = 1.0, 3.0, 1.0, -0.5
    sim = two(circles_cpu, [[0.3, 0.5], [0.7, 0.5]], [[v1, 0.0], [v2, 0.0]], [m1, m2],
              scheme=scheme, dt=0.01)
    sim.advance(0.25)
    s = sim.state()
    e1 = ((m1 - m2) * v1 + 2 * m2 * v2) / (m1 + m2)
    e2 = ((m2 - m1) * v2 + 2 * m1 * v1) / (m1 + m2)
    assert s.vel == pytest.approx(np.array([[e1, 0.0], [e2, 0.0]]), abs=1e-14)
    st = sim.stats()
    assert st["pair_collisions"] == 1
    assert st["momentum"][0] == pytest.approx(m1 * v1 + m2 * v2, abs=1e-14)
    assert st["kinetic_energy"] == pytest.approx(0.5 * (m1 * v1**2 + m2 * v2**2), rel=1e-14)
    if scheme == "event":
        t_hit = 0.3 / 1.5
        x1 = 0.3 + v1 * t_hit + e1 * (0.25 - t_hit)
        x2 = 0.7 + v2 * t_hit + e2 * (0.25 - t_hit)
        assert s.pos[:, 0] == pytest.approx([x1, x2], abs=1e-14)


@pytest.mark.parametrize("scheme", ["event", "discrete"])
@pytest.mark.parametrize("small_first", [True, False])
def test_virial_of_unequal_radii_counts_both(circles_cpu, scheme, small_first):
    """Head on along x, equal masses closing at 2: |J| = 2, and the virial adds (r_i + r_j)|J|
    = (0.05 + 0.10) 2 = 0.3, with both radii whichever circle comes first. The normal is exactly
    (1, 0), so a few roundings (of the contact distance and the impulse) enter: 1e-14."""
    pos, vel, radius = [[0.3, 0.5], [0.7, 0.5]], [[1.0, 0.0], [-1.0, 0.0]], [0.05, 0.10]
    k = [0, 1] if small_first else [1, 0]
    sim = two(circles_cpu, [pos[i] for i in k], [vel[i] for i in k], [1.0, 1.0], scheme=scheme, dt=0.01,
              radius=[radius[i] for i in k])
    sim.advance(0.3)
    st = sim.stats()
    assert st["pair_collisions"] == 1
    assert st["virial"] == pytest.approx(0.3, rel=1e-14)


@pytest.mark.parametrize("scheme", ["event", "discrete"])
@pytest.mark.parametrize("mass", [3.0, 0.3])
def test_wall_impulse_is_twice_mass_times_normal_speed(circles_cpu, scheme, mass):
    """One circle of mass 3 (or 0.3: masses whose inverse is no power of two, so an impulse
    formed with the inverse mass in place of the mass shows) hits the wall x = W once at speed
    2: the wall impulse is 2 m |v_n| = 12 m / 3, to a few roundings."""
    sim = circles_cpu.Simulation.from_arrays(np.array([[5.0, 5.0]]), np.array([[2.0, 0.0]]), np.array([1.0]),
                                             mass=np.array([mass]), box=(10.0, 10.0), scheme=scheme,
                                             precision="f64", dt=0.01)
    sim.advance(3.0)
    st = sim.stats()
    assert st["wall_collisions"] == 1
    assert st["wall_impulse"] == pytest.approx(2.0 * mass * 2.0, rel=1e-14)
    assert sim.state().vel[0] == pytest.approx([-2.0, 0.0], abs=1e-15)


def test_glancing_equal_masses_leave_at_right_angles(circles_cpu):
    """Equal masses, target at rest, impact parameter b = s / 2: at contact the
    normal makes 30 degrees with x, the target leaves along it with speed
    cos 30, the bullet at right angles to it."""
    s = 2 * R
    sim = two(circles_cpu, [[0.2, 0.5], [0.6, 0.5 + 0.5 * s]], [[1.0, 0.0], [0.0, 0.0]],
              [1.0, 1.0], dt=0.01)
    sim.advance(0.4)
    v1, v2 = sim.state().vel
    assert sim.stats()["pair_collisions"] == 1
    assert np.dot(v1, v2) == pytest.approx(0.0, abs=1e-14)
    c30 = math.cos(math.pi / 6)
    assert v2 == pytest.approx([c30 * c30, c30 * 0.5], abs=1e-14)
    assert v1 == pytest.approx([0.25, -c30 * 0.5], abs=1e-14)


def test_glancing_discrete_also_right_angles(circles_cpu):
    """The discrete scheme collides at an overlapping position, so the angle
    is off, but with equal masses and a target at rest the impulse along any
    normal leaves the two at right angles with the energy unchanged."""
    s = 2 * R
    sim = two(circles_cpu, [[0.2, 0.5], [0.6, 0.5 + 0.5 * s]], [[1.0, 0.0], [0.0, 0.0]],
              [1.0, 1.0], scheme="discrete", dt=0.013)
    sim.advance(0.4)
    v1, v2 = sim.state().vel
    assert sim.stats()["pair_collisions"] == 1
    assert np.dot(v1, v2) == pytest.approx(0.0, abs=1e-14)
    assert np.dot(v1, v1) + np.dot(v2, v2) == pytest.approx(1.0, rel=1e-14)


def test_mass_ratio_1e6_light_on_heavy(circles_cpu):
    """A light circle (m = 1) bounces off a heavy one (m = 1e6) at rest:
    v1' = (1 - 1e6) / (1 + 1e6) v, v2' = 2 / (1 + 1e6) v. Almost all energy
    stays with the light circle, so the energy check (1e-12 relative, f64) is
    sensitive to the cancellation the impulse form avoids."""
    m1, m2 = 1.0, 1e6
    sim = two(circles_cpu, [[0.3, 0.5], [0.7, 0.5]], [[1.0, 0.0], [0.0, 0.0]], [m1, m2],
              radius=(0.02, 0.1), dt=0.01)
    e0 = sim.stats()["kinetic_energy"]
    sim.advance(0.5)
    st = sim.stats()
    v = sim.state().vel
    assert st["pair_collisions"] == 1
    assert v[0, 0] == pytest.approx((m1 - m2) / (m1 + m2), rel=1e-14)
    assert v[1, 0] == pytest.approx(2 * m1 / (m1 + m2), rel=1e-12)
    assert abs(st["kinetic_energy"] - e0) <= 1e-12 * e0
    e_state = 0.5 * np.sum(sim.state().mass * np.sum(v * v, axis=1))
    assert abs(e_state - e0) <= 1e-12 * e0


def test_mass_ratio_1e6_piston(circles_cpu):
    """A light circle trapped between a wall and a slowly advancing heavy one
    (m ratio 1e6) gains 0.1 of speed at every bounce, each time beyond the
    largest speed at the step's start that the grid's margin assumed.
    Over ~20 collisions: the same events as the exact reference, energy
    conserved to 1e-12 relative, the light circle's final speed within 1e-9
    of the reference's (each bounce adds ~1e-16 relative round-off and the
    1-D motion does not amplify it)."""
    pos = np.array([[0.2, 0.5], [0.8, 0.5]])
    vel = np.array([[1.0, 0.0], [-0.05, 0.0]])
    r = np.array([0.02, 0.1])
    m = np.array([1.0, 1e6])
    T = 9.0
    ref = Reference(pos, vel, r, m, box=BOX).run(until=T)
    sim = circles_cpu.Simulation.from_arrays(pos, vel, r, mass=m, box=BOX, boundary="walls",
                                             scheme="event", precision="f64", dt=0.05,
                                             record_events=1024)
    e0 = sim.stats()["kinetic_energy"]
    sim.advance(T)
    st = sim.stats()
    assert ref.pair_collisions >= 10
    assert [tuple(e[1:]) for e in np.asarray(sim.events()).astype(int).tolist()] == \
        [e[1:] for e in ref.events]
    assert st["pair_collisions"] == ref.pair_collisions
    assert abs(st["kinetic_energy"] - e0) <= 1e-12 * e0
    v = sim.state().vel
    assert v[0] == pytest.approx(ref.vel[0], rel=1e-9)
    assert v[1] == pytest.approx(ref.vel[1], rel=1e-9)


def test_record_events_is_checked_before_any_work(circles_cpu):
    """The log's capacity is a whole number >= 0, and above 0 only with the event scheme (the
    discrete scheme has no times of contact to log): refused at once, naming the value and
    the fix, by the constructor and by from_arrays."""
    scene = circles_cpu.Scene(n=10, box=(2.0, 2.0), radius=0.05, scheme="discrete")
    with pytest.raises(ValueError, match=r"record_events = 5 with scheme 'discrete'.*use scheme='event'"):
        circles_cpu.Simulation(scene, record_events=5)
    for bad in (-1, 2.5, True, "100"):
        with pytest.raises(ValueError, match="must be a whole number >= 0"):
            circles_cpu.Simulation(circles_cpu.Scene(n=10, box=(2.0, 2.0), radius=0.05), record_events=bad)
    with pytest.raises(ValueError, match="only the event scheme logs"):
        circles_cpu.Simulation.from_arrays(np.array([[0.5, 0.5]]), np.zeros((1, 2)), [0.1], box=(2.0, 2.0),
                                           scheme="discrete", record_events=10)
    circles_cpu.Simulation(scene, record_events=0)
    logged = circles_cpu.Simulation(circles_cpu.Scene(n=10, box=(2.0, 2.0), radius=0.05, speed=(1.0, 2.0)),
                                    record_events=np.int64(1000))
    logged.advance(2.0)
    events = logged.events()
    stats = logged.stats()
    walls = events[:, 2] < 0
    assert len(events) == stats["pair_collisions"] + stats["wall_collisions"] > 0
    assert set(events[walls, 2].astype(int)) <= {-1, -2, -3, -4}
    assert np.all(events[~walls, 1] < events[~walls, 2])


BULLET_DT = 0.1
BULLET_SPEED = 20 * 2 * R / BULLET_DT  # 20 diameters per step


def bullet(circles, scheme):
    """A bullet (m = 1) moving 20 diameters per step toward a target (m = 3)
    at rest 9 diameters away, in a box far larger than one step's travel."""
    return circles.Simulation.from_arrays(
        np.array([[2.0, 5.0], [3.0, 5.0]]), np.array([[BULLET_SPEED, 0.0], [0.0, 0.0]]),
        np.array([R, R]), mass=np.array([1.0, 3.0]), box=(10.0, 10.0), boundary="walls",
        scheme=scheme, precision="f64", dt=BULLET_DT)


def test_event_scheme_fast_bullet_hits(circles_cpu):
    """Event scheme: the hit happens at t = 0.9 / 20 = 0.045 inside the single
    step, with the 1-D result v1' = -v/2, v2' = v/2, and both circles where the
    exact motion puts them at t = dt."""
    sim = bullet(circles_cpu, "event")
    sim.step(1)
    assert sim.time == pytest.approx(BULLET_DT, rel=1e-15)
    st = sim.stats()
    assert st["pair_collisions"] == 1
    s = sim.state()
    v = BULLET_SPEED
    assert s.vel == pytest.approx(np.array([[-v / 2, 0.0], [v / 2, 0.0]]), rel=1e-14, abs=1e-14)
    t_hit = 0.9 / v
    x1 = 2.0 + v * t_hit - v / 2 * (BULLET_DT - t_hit)
    x2 = 3.0 + v / 2 * (BULLET_DT - t_hit)
    assert s.pos == pytest.approx(np.array([[x1, 5.0], [x2, 5.0]]), abs=1e-13)


def test_discrete_scheme_fast_bullet_tunnels(circles_cpu):
    """The known error of the discrete scheme: it only sees overlap at the end
    of a step, and after one step the bullet is already a full 10 diameters
    beyond the target. No collision happens; both keep their velocities."""
    sim = bullet(circles_cpu, "discrete")
    sim.step(1)
    st = sim.stats()
    s = sim.state()
    assert st["pair_collisions"] == 0
    assert np.array_equal(s.vel, np.array([[BULLET_SPEED, 0.0], [0.0, 0.0]]))
    assert s.pos[0, 0] == pytest.approx(4.0, abs=1e-14)
    assert s.pos[0, 0] - s.pos[1, 0] == pytest.approx(1.0, abs=1e-14)


def _rounds_in_a_row(v, m, first):
    """The discrete rounds for three circles in a row (left, middle, right), both outer ones
    overlapping the middle one: the pair `first` (0: left, 1: right) is resolved first, then
    whichever pair approaches, until none does (1D elastic impulses)."""
    v = list(v)
    side = first
    for _ in range(16):
        a, b = (0, 1) if side == 0 else (1, 2)
        if v[a] <= v[b]:  # not approaching: is the other pair?
            side = 1 - side
            a, b = (0, 1) if side == 0 else (1, 2)
            if v[a] <= v[b]:
                break
        va, vb = v[a], v[b]
        v[a] = ((m[a] - m[b]) * va + 2 * m[b] * vb) / (m[a] + m[b])
        v[b] = ((m[b] - m[a]) * vb + 2 * m[a] * va) / (m[a] + m[b])
        side = 1 - side
    return v


@pytest.mark.parametrize("left_id_lower", [True, False])
def test_discrete_exact_tie_goes_to_the_lower_id(circles_cpu, left_id_lower):
    """Two circles hit a middle one in the same step with the same key (the same overlap, 1/8,
    at the same approach speed, 1: exact binary fractions). The rule on ids decides which
    pair goes first (the one whose other circle has the lower id), and with masses 1, 2 and 4
    the order shows in the outcome: the two orders end 0.3 or more apart in velocity.
    """
    x = [6.875, 8.0, 9.125]
    v = [1.0, 0.0, -1.0]
    m = [2.0, 1.0, 4.0]
    # Creation order (ids): the middle circle, then the outer one with the lower id.
    order = [1, 0, 2] if left_id_lower else [1, 2, 0]
    sim = two(circles_cpu, [[x[k], 8.0] for k in order], [[v[k], 0.0] for k in order], [m[k] for k in order],
              scheme="discrete", dt=0.25, box=(16.0, 16.0), radius=(0.5, 0.5, 0.5))
    sim.step(1)
    got = sim.state().vel[np.argsort(order), 0]
    expected = _rounds_in_a_row(v, m, 0 if left_id_lower else 1)
    other = _rounds_in_a_row(v, m, 1 if left_id_lower else 0)
    assert np.abs(np.subtract(expected, other)).max() > 0.3
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-13)
    assert sim.state().vel[:, 1].tolist() == [0.0, 0.0, 0.0]


def test_discrete_resolves_the_pair_that_touched_first(circles_cpu):
    """Within one step two circles reach a middle one: the left pair overlaps more at the step's
    end (0.004 against 0.0018) but touched later (0.006 after the step's start, at closing speed
    1), the right pair touched first (0.001, at closing speed 0.2). The discrete scheme picks
    by how long ago a pair touched (overlap over approach speed), so the right pair goes first,
    as in the event scheme; with masses 1, 2 and 3 the other order ends 0.27 away in velocity.
    Along x the impulses are exact but for a few roundings: 1e-14."""
    r, v, m = 0.05, [1.0, 0.0, -0.2], [1.0, 2.0, 3.0]
    x = [0.5 - 2 * r - 0.006, 0.5, 0.5 + 2 * r + 0.0002]
    right_first, left_first = _rounds_in_a_row(v, m, 1), _rounds_in_a_row(v, m, 0)
    assert np.abs(np.subtract(right_first, left_first)).max() > 0.25
    for scheme in ("discrete", "event"):
        sim = two(circles_cpu, [[xk, 0.5] for xk in x], [[vk, 0.0] for vk in v], m, scheme=scheme, dt=0.01,
                  radius=(r, r, r))
        sim.step(1)
        np.testing.assert_allclose(sim.state().vel[:, 0], right_first, rtol=0, atol=1e-14, err_msg=scheme)


def test_discrete_step_reads_no_pick_it_did_not_write(circles_cpu):
    """The first round of a discrete step writes no pick for most circles (those with no
    partner this step), so every pick a step reads must be one it wrote. Two runs of a dense,
    fast scene, one with the picks left from an earlier step replaced by each circle's
    nearest neighbour (the stale value most likely to look like a mutual pick), the other
    by none, must end bit for bit the same; reading one stale pick would resolve a pair the
    other run does not."""
    scene = circles_cpu.Scene(n=3000, box=(1.0, 1.0), radius=(0.004, 0.01), speed=(2.0, 6.0), scheme="discrete",
                              precision="f32", seed=31, dt=0.002)
    runs = []
    for stale in ("nearest", "none"):
        sim = circles_cpu.Simulation(scene)
        multi = 0
        for _ in range(12):
            pos = sim.pos.to_numpy().astype(np.float64)
            if stale == "nearest":
                d2 = ((pos[:, None, :] - pos[None, :, :]) ** 2).sum(axis=2)
                np.fill_diagonal(d2, np.inf)
                sim._partner.from_numpy(np.argmin(d2, axis=1).astype(np.int32))
            else:
                sim._partner.from_numpy(np.full(scene.n, -1, np.int32))
            sim.step(1)
            multi += int((sim._n_contacts.to_numpy() >= 2).sum())
        runs.append((sim.state(), sim.stats()["pair_collisions"], multi))
    (a, pairs_a, multi_a), (b, pairs_b, multi_b) = runs
    assert multi_a > 100  # circles with two or more overlaps: picks that later rounds read
    assert pairs_a == pairs_b > 1000
    np.testing.assert_array_equal(a.pos, b.pos)
    np.testing.assert_array_equal(a.vel, b.vel)


def run_with_flag(circles, monkeypatch, scene, flag, steps, check, values=(True, False), module=None):
    """The discrete `scene` run `steps` single steps with `<module>.<flag>` (circles.discrete.stepper
    by default) at each of two `values`: a (state, stats, crowded) for each, crowded summing
    over the steps the circles whose contact list overflowed (they search their cells).
    `check(sim, value)` looks at each new Simulation."""
    from circles.discrete import stepper as discrete_stepper
    runs = []
    for value in values:
        monkeypatch.setattr(module or discrete_stepper, flag, value)
        sim = circles.Simulation(scene)
        check(sim, value)
        crowded = 0
        for _ in range(steps):
            sim.step(1)
            crowded += int((sim._n_contacts.to_numpy() > discrete_stepper.DISCRETE_CONTACTS).sum())
        runs.append((sim.state(), sim.stats(), crowded))
    return runs


def assert_runs_equal(runs, boundary, pairs, walls):
    """The two runs of `run_with_flag` the same bit for bit: positions, velocities, counts and
    sums; both had contact lists overflow, more than `pairs` pair collisions and, in a walled
    box, more than `walls` wall hits."""
    (a, st_a, crowded_a), (b, st_b, crowded_b) = runs
    assert crowded_a == crowded_b > 0
    assert st_a["pair_collisions"] == st_b["pair_collisions"] > pairs
    for key in ("wall_collisions", "virial", "wall_impulse"):
        assert st_a[key] == st_b[key]
    if boundary == "walls":
        assert st_a["wall_collisions"] > walls
    np.testing.assert_array_equal(a.pos, b.pos)
    np.testing.assert_array_equal(a.vel, b.vel)


@pytest.mark.parametrize("boundary", ["walls", pytest.param("periodic", marks=pytest.mark.slow)])
def test_discrete_equal_circles_read_one_radius_and_mass(circles_cpu, monkeypatch, boundary):
    """A discrete scene whose circles share one radius and one mass reads the first circle's
    (`discrete.per_circle`): the run must be the same bit for bit as one that reads each
    circle's, on a dense, fast scene whose circles overlap several others at once (contact
    lists that overflow into cell searches) and hit the walls. Equal radii with unequal
    masses read per circle (test_unequal_masses_follow_1d_formula checks their outcome)."""
    scene = circles_cpu.Scene(n=3000, box=(1.0, 1.0), radius=0.007, speed=(2.0, 6.0), scheme="discrete",
                              precision="f32", seed=5, dt=0.002, boundary=boundary)

    def check(sim, uniform):
        assert sim._uniform == uniform

    runs = run_with_flag(circles_cpu, monkeypatch, scene, "DISCRETE_UNIFORM", 12, check)
    assert_runs_equal(runs, boundary, pairs=1000, walls=50)
    pos = np.array([[0.3, 0.5], [0.7, 0.5]])
    unequal = circles_cpu.Simulation.from_arrays(pos, np.zeros((2, 2)), np.array([R, R]), mass=np.array([1.0, 3.0]),
                                                 box=BOX, scheme="discrete")
    assert not unequal._uniform


@pytest.mark.slow
@pytest.mark.skipif(TEST_ARCH != "cpu", reason="one thread or several is a CPU's choice")
@pytest.mark.parametrize("boundary", ["walls", "periodic"])
def test_discrete_on_one_thread_equals_several(circles_cpu, monkeypatch, boundary):
    """Scenes up to backend.SERIAL_N circles run every loop of a discrete step on one thread,
    its rounds in one loop; larger ones run them on the threads. The state must not depend on
    which: a dense, fast scene of mixed radii run both ways, the same bit for bit."""
    from circles import backend

    scene = circles_cpu.Scene(n=3000, box=(1.0, 1.0), radius=(0.005, 0.009), speed=(2.0, 6.0), scheme="discrete",
                              precision="f32", seed=5, dt=0.002, boundary=boundary)

    def check(sim, limit):
        assert sim._serial == (limit > 0) and (sim._parallel_rounds == 0) == sim._serial

    runs = run_with_flag(circles_cpu, monkeypatch, scene, "SERIAL_N", 40, check, values=(10**9, 0), module=backend)
    assert_runs_equal(runs, boundary, pairs=10000, walls=500)


@pytest.mark.slow
@pytest.mark.parametrize("boundary", ["walls", "periodic"])
def test_discrete_first_round_in_parts_equals_every_circle(circles_cpu, monkeypatch, boundary):
    """On a CPU with several threads a step's first round runs in one part of the circles per
    thread, each listing its marked circles before picking for them
    (`discrete._first_round_in_parts`). It must give the same state bit for bit as the loop over
    every circle that a GPU runs, on a dense, fast scene of mixed radii run with parallel loops
    (backend.SERIAL_N at 0): isolated pairs, circles with several overlaps, contact lists that
    overflow into cell searches, and walls."""
    from circles import backend, grid
    from circles.discrete import stepper as discrete_stepper
    if grid.count_parts() < 2:
        pytest.skip("one CPU thread (or a GPU): the first round has no parts")
    monkeypatch.setattr(backend, "SERIAL_N", 0)
    monkeypatch.setattr(discrete_stepper, "DISCRETE_TEAM", False)  # the team always runs the first round in parts
    scene = circles_cpu.Scene(n=3000, box=(1.0, 1.0), radius=(0.005, 0.009), speed=(2.0, 6.0), scheme="discrete",
                              precision="f32", seed=5, dt=0.002, boundary=boundary)

    def check(sim, parts):
        assert sim._parallel_rounds > 0 and not sim._team

    runs = run_with_flag(circles_cpu, monkeypatch, scene, "DISCRETE_FIRST_IN_PARTS", 40, check)
    assert_runs_equal(runs, boundary, pairs=10000, walls=500)


@pytest.mark.slow
@pytest.mark.parametrize("boundary", ["walls", "periodic"])
def test_discrete_team_equals_loops(circles_cpu, monkeypatch, boundary):
    """On a CPU with several threads a discrete step runs as one team (`discrete.team_step`,
    `circles.team`): its stages in chunks that the threads take, with no start of the thread
    pool between them. It must give the state of the step's loops (`discrete.begin_step`) bit
    for bit, on a dense, fast scene of mixed radii whose rounds go on for several rounds:
    isolated pairs, circles with several overlaps, contact lists that overflow into cell
    searches, walls. And with the team's members run one after another on one thread (the
    first does every chunk, the others find them done), again the same state."""
    from circles import backend, grid
    from circles.discrete import stepper as discrete_stepper
    if grid.count_parts() < 2:
        pytest.skip("one CPU thread (or a GPU): no team")
    monkeypatch.setattr(backend, "SERIAL_N", 0)
    scene = circles_cpu.Scene(n=3000, box=(1.0, 1.0), radius=(0.005, 0.009), speed=(2.0, 6.0), scheme="discrete",
                              precision="f32", seed=5, dt=0.002, boundary=boundary)

    def check(sim, team):
        assert sim._team == team and sim._parallel_rounds > 0

    runs = run_with_flag(circles_cpu, monkeypatch, scene, "DISCRETE_TEAM", 40, check)
    assert_runs_equal(runs, boundary, pairs=10000, walls=500)
    monkeypatch.setattr(discrete_stepper, "DISCRETE_TEAM_SERIAL", True)
    one = run_with_flag(circles_cpu, monkeypatch, scene, "DISCRETE_TEAM", 40, check, values=(True,))
    assert_runs_equal([runs[0], one[0]], boundary, pairs=10000, walls=500)


@pytest.mark.slow
def test_discrete_team_equals_loops_on_a_two_level_grid(circles_cpu, monkeypatch):
    """The team step (see above) on a two-level grid, whose large circles search their blocks
    in a stage of their own: the state of the step's loops, bit for bit."""
    from circles import backend, grid
    from circles.discrete import stepper as discrete_stepper
    from physics_util import two_size_mixture
    if grid.count_parts() < 2:
        pytest.skip("one CPU thread (or a GPU): no team")
    monkeypatch.setattr(backend, "SERIAL_N", 0)
    pos, vel, radius, box = two_size_mixture("f32")
    out = []
    for team in (True, False):
        monkeypatch.setattr(discrete_stepper, "DISCRETE_TEAM", team)
        sim = circles_cpu.Simulation.from_arrays(pos, vel, radius, mass="radius", box=box, scheme="discrete",
                                                 precision="f32", dt=0.02)
        assert sim._team == team and sim._two_level
        sim.step(20)
        out.append((sim.state(), sim.stats()))
    (a, st_a), (b, st_b) = out
    assert st_a == st_b and st_a["pair_collisions"] > 500 and st_a["wall_collisions"] > 50
    np.testing.assert_array_equal(a.pos, b.pos)
    np.testing.assert_array_equal(a.vel, b.vel)


@pytest.mark.skipif(TEST_ARCH != "cpu", reason="steps run on one thread on a CPU only")
@pytest.mark.parametrize("name", ["walls-f32", *(pytest.param(name, marks=pytest.mark.slow)
                                                for name in ("periodic-f32", "walls-f64-dense", "two-level-f32"))])
def test_discrete_steps_at_once_equal_one_at_a_time(circles_cpu, monkeypatch, name):
    """Where a discrete step runs on one thread, `step(k)` and `advance` run up to
    circles.discrete.stepper.DISCRETE_STEPS_AT_ONCE steps in one launch (`discrete.serial_steps`), a batch
    ending early at a step whose fused rounds did not settle, which the host finishes with
    more rounds (and, at the round limit, the walls). The run must be the one of a launch a
    step bit for bit: state, counts, sums, clock, steps and rounds, over steps that cross the
    reorders (every simulation.REORDER_EVERY steps) and an advance that ends in a part step.
    Scenes: fast enough that some steps need more rounds than the fused ones (every step, in
    the dense one), a periodic box, float64, and a two-level grid."""
    from circles.discrete import rounds as discrete
    from circles.discrete import stepper as discrete_stepper
    from physics_util import two_size_mixture

    def make():
        if name == "two-level-f32":
            pos, vel, radius, box = two_size_mixture("f32")
            return circles_cpu.Simulation.from_arrays(pos, vel, radius, mass="radius", box=box, scheme="discrete",
                                                      precision="f32", dt=0.02)
        dense = name == "walls-f64-dense"
        scene = circles_cpu.Scene(n=3000, box=(1.0, 1.0), radius=(0.005, 0.009), speed=(2.0, 6.0),
                                  scheme="discrete", precision="f64" if dense else "f32", seed=5,
                                  dt=0.002 if dense else 0.0005, boundary=name.split("-")[0])
        return circles_cpu.Simulation(scene)

    launches = []
    runs = []
    for at_once in (discrete_stepper.DISCRETE_STEPS_AT_ONCE, 1):
        monkeypatch.setattr(discrete_stepper, "DISCRETE_STEPS_AT_ONCE", at_once)
        calls = []
        kernel = discrete.serial_steps

        def counted(*args, kernel=kernel, calls=calls):
            calls.append(args)
            return kernel(*args)

        monkeypatch.setattr(discrete, "serial_steps", counted)
        sim = make()
        assert sim._serial and sim._steps_at_once == at_once
        sim.step(37)
        sim.advance(21.3 * sim.dt)
        launches.append(len(calls))
        runs.append((sim.state(), sim.stats(), sim.time, sim.steps, sim.rounds))
    (a, st_a, *clock_a), (b, st_b, *clock_b) = runs
    assert st_a == st_b and clock_a == clock_b
    np.testing.assert_array_equal(a.pos, b.pos)
    np.testing.assert_array_equal(a.vel, b.vel)
    steps, rounds = clock_a[1], clock_a[2]
    assert steps == 37 + 22 and st_a["pair_collisions"] > 1000
    if name != "periodic-f32":
        assert st_a["wall_collisions"] > 50
    # Some steps needed more rounds than the fused ones; a launch a step made none in batches.
    assert rounds > discrete_stepper.DISCRETE_FUSED_ROUNDS * steps
    assert launches[1] == 0
    if name == "walls-f64-dense":
        assert rounds == discrete_stepper.DISCRETE_MAX_ROUNDS * steps  # every step: a batch of one
    else:
        assert 0 < launches[0] <= steps // 3


@pytest.mark.skipif(TEST_ARCH != "cpu", reason="steps run on one thread on a CPU only")
def test_discrete_steps_at_once_stop_where_the_clock_stops_counting(circles_cpu, monkeypatch):
    """A batch of steps checks the clock before each of its steps as a step at a time does:
    from time 2^24 - 5.5 dt (dt = 0.001), the clock counts the steps before 2^24 to within
    2^-20 of dt (float64's unit there is 2^-29, below 2^-20 dt) and not the first after it
    (2^-28), so step(10) takes those steps and then refuses with the clock's message, with
    `circles.discrete.stepper.DISCRETE_STEPS_AT_ONCE` at 16 as at 1: the same steps, time and state."""
    from circles.discrete import stepper as discrete_stepper

    runs = []
    for at_once in (16, 1):
        monkeypatch.setattr(discrete_stepper, "DISCRETE_STEPS_AT_ONCE", at_once)
        sim = circles_cpu.Simulation(circles_cpu.Scene(n=500, box=(10.0, 10.0), radius=0.1, scheme="discrete",
                                                       seed=2, dt=0.001))
        assert sim._steps_at_once == at_once
        sim.step(3)
        sim.time = 2.0 ** 24 - 5.5 * 0.001
        with pytest.raises(ValueError, match="dt = 0.001 is too short for the simulated clock"):
            sim.step(10)
        runs.append((sim.steps, sim.time, sim.state().pos))
    (steps_a, time_a, pos_a), (steps_b, time_b, pos_b) = runs
    assert steps_a == steps_b == 3 + 6 and time_a == time_b > 2.0 ** 24
    np.testing.assert_array_equal(pos_a, pos_b)


def test_advance_and_step_refuse_bad_lengths_before_any_work(circles_cpu):
    """A length that is not a finite number >= 0 (a string, a bool, NaN, infinity, a negative
    or, for step, a fraction of a step) is refused with the value named, and nothing moves;
    whole floats and numpy numbers are lengths like any other."""
    sim = circles_cpu.Simulation(circles_cpu.Scene(n=50, box=(3.0, 2.0), radius=0.08, seed=3))
    sim.step(2)
    before = sim.state().pos
    for bad in ("1", True, float("nan"), float("inf"), -0.5):
        with pytest.raises(ValueError, match="duration .* must be a finite number of simulated seconds"):
            sim.advance(bad)
    for bad in ("2", True, 1.5, -1, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="k = .* must be a whole number of steps"):
            sim.step(bad)
    assert sim.steps == 2 and np.array_equal(sim.state().pos, before)
    sim.step(np.int64(1)).step(2.0).advance(np.float32(0.5) * sim.dt)
    sim.step(np.array(1)).advance(np.array(0.5 * sim.dt))  # 0-d arrays, as numpy reductions give
    with pytest.raises(ValueError, match="k = .* must be a whole number of steps"):
        sim.step(np.array(True))
    assert sim.steps == 2 + 1 + 2 + 1 + 1 + 1


def test_speeds_beyond_the_arithmetic_and_steps_below_the_clock_are_refused(circles_cpu):
    """Speeds whose squares would overflow (in f64 a speed of 1e300 gave a default dt of 0, and
    advance never ended) are refused before any work, naming the limit; so is an advance whose
    dt is below the resolution of the simulated clock (time + dt == time would never end)."""
    from circles.scene import MAX_SPEED

    with pytest.raises(ValueError, match=r"speed 1e\+200 is above 1.3e\+151"):
        circles_cpu.Scene(n=10, box=(4.0, 3.0), radius=0.1, speed=(1.0, 1e200))
    with pytest.raises(ValueError, match=r"speed 1e\+17 is above 1.8e\+16, the largest speed f32"):
        circles_cpu.Scene(n=10, box=(4.0, 3.0), radius=0.1, speed=(1.0, 1e17), precision="f32")
    pos, radius = np.array([[1.0, 1.0], [3.0, 1.0]]), np.array([0.1, 0.1])
    for precision, speed in (("f64", 1e300), ("f32", 1e20)):
        with pytest.raises(ValueError, match=r"the speed of circle 1, .* is above"):
            circles_cpu.Simulation.from_arrays(pos, np.array([[0.0, 0.0], [0.0, speed]]), radius, box=(4.0, 3.0),
                                               precision=precision)
    fast = circles_cpu.Simulation.from_arrays(pos, np.array([[MAX_SPEED["f64"], 0.0], [0.0, 0.0]]), radius,
                                              box=(4.0, 3.0))
    assert 0 < fast.dt < 1e-150
    fast.step(2)
    energy = fast.stats()["kinetic_energy"]
    assert energy == pytest.approx(0.5 * 0.1 * MAX_SPEED["f64"] ** 2, rel=1e-12)

    slow_clock = circles_cpu.Simulation.from_arrays(pos, np.array([[1.0, 0.0], [0.0, 0.0]]), radius,
                                                    box=(4.0, 3.0), dt=1e-12)
    slow_clock.time = 1e6  # as a loaded long run's: float64 counts 1.2e-10 there
    with pytest.raises(ValueError, match=r"dt = 1e-12 is too short for the simulated clock at time 1e\+06, which "
                                         r"counts in units of 1.16e-10 \(it would count 1e-12 as 0\): give a dt of "
                                         r"at least 0.000122, or start the clock again with sim.time = 0"):
        slow_clock.advance(1.0)
    with pytest.raises(ValueError, match=r"dt = 1e-12 is too short for the simulated clock"):
        slow_clock.step(3)  # it moved the circles and left the clock where it was
    assert slow_clock.steps == 0 and np.array_equal(slow_clock.state().pos, pos)
    # A clock that moves, but by another length than the circles: at 1e14 float64 counts in
    # units of 1/64, and steps of 0.01 were counted as 0.015625 each (an advance of 1.0 moved
    # the circles by 0.64), and at 1e16 an advance of 1.0 was rounded away, with no error.
    coarse = circles_cpu.Simulation.from_arrays(pos, np.array([[0.1, 0.0], [0.0, 0.0]]), radius, box=(4.0, 3.0),
                                                dt=0.01)
    coarse.time = 1e14
    for call in (lambda: coarse.advance(1.0), lambda: coarse.step(1)):
        with pytest.raises(ValueError, match=r"dt = 0.01 is too short .* \(it would count 0.01 as 0.015625\)"):
            call()
    coarse.dt = 1.0 / 64  # counted exactly there
    coarse.advance(1.0)
    assert coarse.time == 1e14 + 1.0 and coarse.steps == 64
    assert coarse.state().pos[0, 0] == pytest.approx(1.0 + 0.1, rel=1e-12)
    coarse.time, coarse.dt = 1e16, 1.0
    with pytest.raises(ValueError, match=r"duration = 1 is too short .* counts in units of 2 \(it would count 1 as 0"):
        coarse.advance(1.0)
    coarse.time = 0  # the fix the message names
    coarse.advance(1.0)
    assert coarse.time == 1.0 and coarse.state().pos[0, 0] == pytest.approx(1.2, rel=1e-12)
    # dt and time take what a Scene takes (a dt of -0.01 ran the clock backwards before).
    for name, value, why in (("dt", -0.01, "must be > 0"), ("dt", float("nan"), "not finite"),
                             ("time", -1.0, "must be a finite number of simulated seconds >= 0"),
                             ("time", float("inf"), "must be a finite number"), ("time", True, "must be")):
        with pytest.raises(ValueError, match=f"{name} .*{why}"):
            setattr(coarse, name, value)
    assert (coarse.dt, coarse.time) == (1.0, 1.0)
    coarse.dt = None  # the scene's choice for the speeds now
    assert coarse.dt == pytest.approx(circles_cpu.event.stepper.EVENT_STEP_RADII * 0.1 / 0.1, rel=1e-15)
    # A periodic box cuts each step to (W/2 - 2 rmax) / (2 vlim), 0.59 s here, below the clock's
    # resolution at 1e16 (2 s), where dt (10 s) is not: advance stopped never.
    torus = circles_cpu.Simulation.from_arrays(pos, np.array([[1.0, 0.0], [0.0, 1.0]]), radius, box=(4.0, 3.0),
                                               boundary="periodic", dt=10.0)
    torus.time = 1e16
    with pytest.raises(ValueError, match=r"a step was cut to 0.5\d* s, below the resolution of the simulated clock"):
        torus.advance(100.0)
    assert torus.steps == 1 and torus.time == 1e16


def test_a_dense_scenes_event_step_holds_about_one_collision_a_circle(circles_cpu):
    """The event scheme's default step is the radii's (the fastest circle moves 0.3 mean radii)
    or, when shorter, the step in which a circle takes part in 1.1 collisions by Enskog's
    frequency omega = 2 rho sigma g(sigma) sqrt(pi kT / m), with g from Liu's equation of state
    (Z = 1 + 2 eta g), worked out here. Liu's Z runs above the measured one in the dense fluid
    (the Validation page), and a crystal start collides less often still, so a run's circles
    take part in fewer than 1.1 collisions a step; more than 0.6 (0.82 measured, from the
    crystal; the radii's step would give 1.8, and a rate off by 2 either 0.41 or 1.6)."""
    stepper = circles_cpu.event.stepper
    assert (stepper.EVENT_STEP_RADII, stepper.EVENT_STEP_COLLISIONS) == (0.3, 1.1)
    scene = circles_cpu.Scene(n=870, crystal=[29, 30], area_fraction=0.698, radius=0.5, speed=[1.0, 1.0],
                              mass="equal", boundary="periodic", start="crystal", seed=2)
    sim = circles_cpu.Simulation(scene)
    eta, rho, sigma, kt = 0.698, 0.698 / (math.pi * 0.25), 1.0, 0.5
    z = (1 + eta ** 2 / 8 + eta ** 3 / 18 - 4 * eta ** 4 / 21) / (1 - eta) ** 2
    omega = 2 * rho * sigma * (z - 1) / (2 * eta) * math.sqrt(math.pi * kt)
    assert sim.dt == pytest.approx(1.1 / omega, rel=1e-9)
    assert sim.dt < 0.3 * 0.5 / 1.0  # the radii's step, 0.15, is longer
    sim.advance(5.0)
    before, steps = sim.stats()["pair_collisions"], sim.steps
    sim.advance(20.0)
    per_step = 2 * (sim.stats()["pair_collisions"] - before) / (870 * (sim.steps - steps))
    assert 0.6 < per_step < 1.1
    sim.dt = None  # the same choice again from the speeds now: the fastest is faster than 1 now
    vmax = float(np.hypot(*sim.state().vel.T).max())
    assert vmax > 2.0
    assert sim.dt == pytest.approx(min(0.3 * 0.5 / vmax, 1.1 / omega), rel=1e-9)
    # A dilute scene keeps the radii's step.
    dilute = circles_cpu.Scene(n=1000, area_fraction=0.3, radius=0.5, speed=[1.0, 1.0], seed=2)
    assert circles_cpu.Simulation(dilute).dt == pytest.approx(0.15, rel=1e-12)
    # From 500000 circles, where every thread count runs steps in parts, 0.33 collisions a step.
    large = circles_cpu.backend.EVENT_PARTS_ONE_THREAD_N
    assert (large, stepper.EVENT_STEP_COLLISIONS_LARGE) == (500_000, 0.33)
    for n, most in ((large - 1, 1.1), (large, 0.33)):
        assert stepper.EventStepper.default_dt(np.full(n, 0.5), 1.0, omega) == pytest.approx(most / omega, rel=1e-12)


@pytest.mark.parametrize("mass", [[1.0, 100.0], "equal"])
def test_a_pair_approaching_in_contact_at_the_start_collides_and_the_run_goes_on(circles_cpu, mass):
    """Circles given in contact and approaching collide at t = 0. When the collision makes a
    circle faster than the step's grid allows, the step is cut at its start; advance took
    that for a clock that cannot move and raised, though the collision was done and the next
    step (made for the new speeds) goes on."""
    # Equal masses: the circle at rest moving across the line of centres leaves at speed 1.41.
    across = 0.0 if mass != "equal" else 1.0
    pos, vel = np.array([[1.0, 1.0], [1.25, 1.0]]), np.array([[0.0, across], [-1.0, 0.0]])
    sim = circles_cpu.Simulation.from_arrays(pos, vel, 0.125, mass=mass, box=(4.0, 2.0), record_events=10)
    sim.advance(0.01)
    m0, m1 = (1.0, 100.0) if mass != "equal" else (1.0, 1.0)
    # 1-D elastic collision: the light circle at rest is hit by the other at speed -1.
    assert sim.state().vel[:, 0] == pytest.approx([-2 * m1 / (m0 + m1), -(m1 - m0) / (m0 + m1)], abs=1e-12)
    assert sim.time == 0.01 and sim.events().tolist() == [[0.0, 0.0, 1.0]]
