"""The reference simulator (tests/reference.py) checked on its own, then the
engine's event scheme checked against it collision for collision.

Part 1 needs no engine: analytic cases, conservation, and agreement with a
second, deliberately naive event-driven loop (all pairs searched from scratch
after every event, the textbook quadratic root, the 1-D elastic formula in the
normal frame) so that the queue and its invalidation are not trusted blindly.

Part 2 runs ``circles.Simulation.from_arrays(..., scheme="event")`` on ~60
circles of mixed radii and masses and compares every executed collision.
"""

import math

import numpy as np
import pytest

from reference import Reference, random_disks, time_of_impact


# ---------------------------------------------------------------------------
# Part 1: the reference on its own
# ---------------------------------------------------------------------------

def fold(x0, v, t, lo, hi):
    """Position and number of wall hits of a point bouncing between lo and hi,
    by unfolding the reflections onto a line of period 2 (hi - lo)."""
    L = hi - lo
    u = (x0 - lo) + v * t  # unfolded coordinate; a wall at every multiple of L
    hits = abs(math.floor(u / L))
    u = u % (2 * L)
    x = lo + (u if u <= L else 2 * L - u)
    return x, hits


def test_single_circle_bounces_match_unfolded_motion():
    """One circle in a box: after T the position and the wall-hit counts follow
    from unfolding the reflections. Each hit adds one rounding of ~1e-16 of
    the box to the position, so 1e-12 of the box is far above round-off."""
    W, H, r, m = 2.0, 1.0, 0.1, 3.0
    x0, y0, vx, vy = 0.7, 0.45, 1.3 * math.sqrt(2), -0.9 * math.pi
    T = 37.3
    ref = Reference([[x0, y0]], [[vx, vy]], [r], [m], box=(W, H)).run(until=T)
    x, hx = fold(x0, vx, T, r, W - r)
    y, hy = fold(y0, vy, T, r, H - r)
    assert ref.pos[0] == pytest.approx([x, y], abs=1e-12 * W)
    walls = [j for _, _, j in ref.events]
    assert walls.count(-1) + walls.count(-2) == hx
    assert walls.count(-3) + walls.count(-4) == hy
    assert ref.wall_collisions == hx + hy
    # each hit transfers 2 m |v_n|; speeds never change
    assert ref.wall_impulse == pytest.approx(2 * m * (hx * abs(vx) + hy * abs(vy)), rel=1e-12)
    assert abs(ref.vx[0]) == abs(vx) and abs(ref.vy[0]) == abs(vy)
    times = [t for t, _, _ in ref.events]
    assert times == sorted(times)


def test_head_on_equal_masses_swap():
    """Equal masses, head on: exact swap at t = gap / closing speed. The normal
    is exactly (1, 0), so the arithmetic is exact up to a few roundings."""
    ref = Reference([[0.3, 0.5], [0.7, 0.5]], [[1.0, 0.0], [-1.0, 0.0]],
                    [0.05, 0.05], "equal").run(until=0.2)
    assert ref.events == [pytest.approx((0.15, 0, 1), abs=1e-15)]
    assert ref.vel == pytest.approx(np.array([[-1.0, 0.0], [1.0, 0.0]]), abs=1e-15)
    assert ref.pos == pytest.approx(np.array([[0.4, 0.5], [0.6, 0.5]]), abs=1e-15)
    # |J| = 2 |vn| / (w_i + w_j) = 2 * 2 / 2 = 2, virial = s |J|
    assert ref.virial == pytest.approx(0.1 * 2.0, rel=1e-15)
    assert ref.pair_collisions == 1 and ref.wall_collisions == 0


def test_unequal_masses_follow_1d_formula():
    """v1' = ((m1 - m2) v1 + 2 m2 v2) / (m1 + m2) and symmetric, to round-off."""
    m1, m2, v1, v2 = 1.0, 3.0, 1.0, -0.5
    ref = Reference([[0.3, 0.5], [0.7, 0.5]], [[v1, 0.0], [v2, 0.0]],
                    [0.05, 0.05], [m1, m2]).run(until=0.25)
    e1 = ((m1 - m2) * v1 + 2 * m2 * v2) / (m1 + m2)
    e2 = ((m2 - m1) * v2 + 2 * m1 * v1) / (m1 + m2)
    assert ref.vel[:, 0] == pytest.approx([e1, e2], abs=1e-15)
    assert ref.events[0][0] == pytest.approx(0.3 / 1.5, abs=1e-15)
    J = 2 * (v2 - v1) / (1 / m1 + 1 / m2)
    assert ref.virial == pytest.approx(0.1 * abs(J), rel=1e-15)


def test_glancing_equal_masses_leave_at_right_angles():
    """Equal masses, target at rest, impact parameter half the contact distance:
    the outgoing velocities are perpendicular and the target leaves along the
    contact normal (sin of the angle to the x axis = b / s = 1/2)."""
    r = 0.05
    s = 2 * r
    ref = Reference([[0.2, 0.5], [0.6, 0.5 + 0.5 * s]], [[1.0, 0.0], [0.0, 0.0]],
                    [r, r], "equal").run(until=0.4)
    v1, v2 = ref.vel
    assert ref.pair_collisions == 1
    assert np.dot(v1, v2) == pytest.approx(0.0, abs=1e-15)
    assert v2 == pytest.approx([math.cos(math.pi / 6) ** 2, math.cos(math.pi / 6) * 0.5], abs=1e-15)
    assert v1 + v2 == pytest.approx([1.0, 0.0], abs=1e-15)


def test_newtons_cradle_touching_circles_collide_at_once():
    """Two touching circles at rest are hit: the pair in contact collides at
    the same time (the 'touching and approaching: now' case); the last leaves
    with the full speed, the others stop."""
    r = 0.05
    ref = Reference([[0.1, 0.5], [0.3, 0.5], [0.4, 0.5]],
                    [[1.0, 0.0], [0.0, 0.0], [0.0, 0.0]], [r] * 3, "equal").run(until=0.2)
    assert [(i, j) for _, i, j in ref.events] == [(0, 1), (1, 2)]
    assert ref.events[1][0] == pytest.approx(0.1, abs=1e-15)
    assert ref.vel == pytest.approx(np.array([[0, 0], [0, 0], [1.0, 0]]), abs=1e-15)


def test_periodic_collision_across_the_seam():
    """Two circles on either side of the x seam approach through it."""
    ref = Reference([[0.05, 0.5], [0.95, 0.5]], [[-1.0, 0.0], [1.0, 0.0]],
                    [0.02, 0.02], "equal", boundary="periodic").run(until=0.05)
    assert len(ref.events) == 1
    assert ref.events[0] == pytest.approx((0.03, 0, 1), abs=1e-15)
    assert ref.vel == pytest.approx(np.array([[1.0, 0.0], [-1.0, 0.0]]), abs=1e-15)
    assert ref.pos == pytest.approx(np.array([[0.04, 0.5], [0.96, 0.5]]), abs=1e-15)


def test_periodic_collision_after_many_wraps():
    """A circle crossing the torus 40 times before it meets one at rest: the
    hit is through a far image that the 3x3 search only sees after the
    horizon re-predictions. The exact time is the earliest root over all
    images, computed here by brute force over 100 wraps."""
    s = 0.04
    p0, p1, v = np.array([0.5, 0.3]), np.array([0.5, 0.5]), np.array([1.0, 0.0041])
    ref = Reference([p0, p1], [v, [0.0, 0.0]], [s / 2, s / 2], "equal",
                    boundary="periodic").run(until=60.0)
    dx = p1 - p0
    exact = min(time_of_impact(dx[0] + k, dx[1], -v[0], -v[1], s) for k in range(-100, 101))
    assert 39 < exact < 40
    assert len(ref.events) == 1
    assert ref.events[0][0] == pytest.approx(exact, rel=1e-12)


def test_conservation_and_no_overlap_over_many_collisions():
    """2000 events among 60 circles: energy is conserved to round-off (each
    collision changes it by ~1e-16 relative; 1e-13 allows 1000 such steps
    adding coherently); momentum too in the periodic box, relative to sum m|v|;
    no pair ever closer than contact beyond round-off (1e-12)."""
    for boundary in ("walls", "periodic"):
        rng = np.random.default_rng(7)
        pos, vel, r = random_disks(60, (1.0, 1.0), (0.02, 0.06), rng)
        m = rng.uniform(0.1, 10.0, 60)
        ref = Reference(pos, vel, r, m, boundary=boundary)
        e0, p0 = ref.kinetic_energy(), np.array(ref.momentum())
        scale = np.sum(m * np.hypot(*vel.T))
        for chunk in range(1, 5):
            ref.run(max_events=500 * chunk)
            assert abs(ref.kinetic_energy() - e0) <= 1e-13 * e0
            if boundary == "periodic":
                assert np.abs(np.array(ref.momentum()) - p0).max() <= 1e-13 * scale
            x = ref.pos
            d = x[None, :, :] - x[:, None, :]
            if boundary == "periodic":
                d -= np.round(d)
            dist = np.hypot(d[..., 0], d[..., 1])
            contact = r[None, :] + r[:, None]
            iu = np.triu_indices(60, 1)
            assert np.max((contact - dist)[iu] / contact[iu]) <= 1e-12
            if boundary == "walls":
                assert np.all(x >= r[:, None] * (1 - 1e-12))
                assert np.all(x <= 1.0 - r[:, None] * (1 - 1e-12))
        assert len(ref.events) == 2000


def naive_events(pos, vel, r, m, box, boundary, n_events):
    """Event-driven simulation without a queue: after every event, search all
    pairs (5 x 5 images when periodic) and walls afresh, with the textbook root
    (-b - sqrt(b^2 - a c)) / a, and collide with the 1-D elastic formula in the
    normal frame. Independent of the reference's bookkeeping."""
    x, v = np.array(pos, float), np.array(vel, float)
    W, H = box
    n = len(r)
    iu, ju = np.triu_indices(n, 1)
    images = [(0, 0)] if boundary == "walls" else [(a, b) for a in range(-2, 3) for b in range(-2, 3)]
    events, t_now = [], 0.0
    while len(events) < n_events:
        best = (math.inf, 0, 0)
        dv = v[ju] - v[iu]
        s = r[iu] + r[ju]
        for ox, oy in images:
            dx = x[ju] - x[iu] + np.array([ox * W, oy * H])
            b = np.sum(dx * dv, axis=1)
            a = np.sum(dv * dv, axis=1)
            c = np.sum(dx * dx, axis=1) - s * s
            disc = b * b - a * c
            ok = (b < 0) & (disc > 0)
            t = np.full(len(iu), math.inf)
            t[ok] = np.maximum((-b[ok] - np.sqrt(disc[ok])) / a[ok], 0.0)
            k = int(np.argmin(t))
            cands = np.nonzero(t == t[k])[0]
            k = min(cands, key=lambda q: (iu[q], ju[q]))
            best = min(best, (t[k], int(iu[k]), int(ju[k])))
        if boundary == "walls":
            for axis, (lo_id, hi_id, L) in enumerate([(-1, -2, W), (-3, -4, H)]):
                for i in range(n):
                    if v[i, axis] < 0:
                        best = min(best, (max((x[i, axis] - r[i]) / -v[i, axis], 0.0), i, lo_id))
                    elif v[i, axis] > 0:
                        best = min(best, (max((L - r[i] - x[i, axis]) / v[i, axis], 0.0), i, hi_id))
        t, i, j = best
        x += v * t
        if boundary == "periodic":
            x %= np.array([W, H])
        t_now += t
        if j >= 0:
            d = x[j] - x[i]
            if boundary == "periodic":
                d -= np.round(d / np.array([W, H])) * np.array([W, H])
            nrm = d / np.hypot(*d)
            u1, u2 = v[i] @ nrm, v[j] @ nrm
            w1 = ((m[i] - m[j]) * u1 + 2 * m[j] * u2) / (m[i] + m[j])
            w2 = ((m[j] - m[i]) * u2 + 2 * m[i] * u1) / (m[i] + m[j])
            v[i] += (w1 - u1) * nrm
            v[j] += (w2 - u2) * nrm
        else:
            v[i, 0 if j in (-1, -2) else 1] *= -1
        events.append((t_now, i, j))
    return np.array(events), x, v


@pytest.mark.parametrize("boundary", ["walls", "periodic"])
def test_reference_equals_naive_search(boundary):
    """Same collisions in the same order as the naive loop, 300 events among 40
    circles at area fraction 0.4. The two differ by round-off (~1e-16 per
    event), which the chaotic dynamics amplify: measured at most 3e-9 here
    over 3 seeds, so times and positions must agree to 1e-6."""
    rng = np.random.default_rng(0)
    pos, vel, r = random_disks(40, (1.0, 1.0), (0.04, 0.07), rng)
    m = rng.uniform(0.5, 2.0, 40)
    ev, x, v = naive_events(pos, vel, r, m, (1.0, 1.0), boundary, 300)
    ref = Reference(pos, vel, r, m, boundary=boundary).run(max_events=300)
    got = ref.events_array()
    assert np.array_equal(got[:, 1:], ev[:, 1:])
    assert got[:, 0] == pytest.approx(ev[:, 0], abs=1e-6)
    d = ref.pos - x
    d -= np.round(d)
    assert np.abs(d).max() <= 1e-6
    assert ref.vel == pytest.approx(v, abs=1e-6)


# ---------------------------------------------------------------------------
# Part 2: the engine's event scheme against the reference
# ---------------------------------------------------------------------------

N_EXACT = 64
PAIR_COLLISIONS = 500


def exact_scene():
    """64 circles of radii in [0.025, 0.07] (area fraction 0.51) and masses in
    [0.5, 2] in a unit box, speeds in [0.5, 1]."""
    rng = np.random.default_rng(1)
    pos, vel, r = random_disks(N_EXACT, (1.0, 1.0), (0.025, 0.07), rng)
    m = rng.uniform(0.5, 2.0, N_EXACT)
    return pos, vel, r, m


@pytest.fixture(scope="module", params=["walls", "periodic"])
def exact_run(request):
    """The reference run to a time T halfway between the 500th pair collision
    and the next event, so that no event sits at the end of the run, and the
    chaos premise of the tolerances checked on this very scene: a 1e-15
    relative change of the initial state changes no event, moves no circle by
    more than 1e-8 and the virial by less than 1e-11 (the engine's own round-off
    differs from the reference's by about that much; the tolerances below are
    100 times wider)."""
    boundary = request.param
    pos, vel, r, m = exact_scene()
    ref = Reference(pos, vel, r, m, boundary=boundary).run(max_pair_collisions=PAIR_COLLISIONS)
    probe = Reference(pos, vel, r, m, boundary=boundary).run(max_events=len(ref.events) + 1)
    T = 0.5 * (ref.events[-1][0] + probe.events[-1][0])
    ref.run(until=T)
    twin = Reference(pos * (1 + 1e-15), vel * (1 - 1e-15), r, m, boundary=boundary).run(until=T)
    assert [e[1:] for e in twin.events] == [e[1:] for e in ref.events]
    d = twin.pos - ref.pos
    d -= np.round(d)
    assert np.abs(d).max() < 1e-8
    assert abs(twin.virial / ref.virial - 1) < 1e-11
    return boundary, T, ref


@pytest.mark.parametrize("dt", [0.002, 0.15], ids=["dt_small", "dt_large"])
def test_event_scheme_equals_reference(circles_cpu, exact_run, dt):
    """Same collisions in the same order as the exact reference, at a dt of
    about 0.1 collisions per circle per step and at one of ~8 per step.
    Tolerances (see the fixture): event times and positions 1e-6 of the box
    (the box crossing time is ~1); velocities 1e-5 of the largest speed
    (a collision turns a position error d into a velocity error ~ v d / s,
    s ~ 0.1); counts exact; virial and wall impulse 1e-9 relative."""
    boundary, T, ref = exact_run
    pos, vel, r, m = exact_scene()
    sim = circles_cpu.Simulation.from_arrays(
        pos, vel, r, mass=m, box=(1.0, 1.0), boundary=boundary, scheme="event",
        precision="f64", dt=dt, record_events=4096)
    sim.advance(T)
    assert sim.time == pytest.approx(T, rel=1e-14)

    got = np.asarray(sim.events())
    want = ref.events_array()
    assert got.shape == want.shape, f"{len(got)} events executed, the reference has {len(want)}"
    mismatch = np.nonzero(np.any(got[:, 1:] != want[:, 1:], axis=1))[0]
    assert len(mismatch) == 0, (
        f"first different event #{mismatch[0]}: engine {got[mismatch[0]]}, "
        f"reference {want[mismatch[0]]}")
    assert np.abs(got[:, 0] - want[:, 0]).max() <= 1e-6

    st = sim.stats()
    assert st["pair_collisions"] == ref.pair_collisions >= PAIR_COLLISIONS
    assert st["wall_collisions"] == ref.wall_collisions
    assert st["virial"] == pytest.approx(ref.virial, rel=1e-9)
    if boundary == "walls":
        assert ref.wall_collisions > 50
        assert st["wall_impulse"] == pytest.approx(ref.wall_impulse, rel=1e-9)
    else:
        assert st["wall_impulse"] == 0.0

    s = sim.state()
    d = s.pos - ref.pos
    if boundary == "periodic":
        d -= np.round(d)
    assert np.abs(d).max() <= 1e-6
    assert np.abs(s.vel - ref.vel).max() <= 1e-5 * np.hypot(*vel.T).max()
    assert np.array_equal(s.radius, r) and np.array_equal(s.mass, m)
