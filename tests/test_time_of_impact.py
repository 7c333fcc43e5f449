"""The event scheme's pair time of impact, its cases computed without branches, case by case
against the test suite's own float64 formula (tests/reference.py): pairs that recede, approach
and miss, approach and hit, and touch or overlap while approaching, with the two circles'
clocks apart.
And its cull: with a horizon, a time at or before it is the same number as without one, and
a pair left out is one that meets after it, in float32 and float64. A search reads its own
circle's values once and computes each pair from its side (`event.pair_time`): in a walled box
the same number from either circle, bit for bit."""
import math

import numpy as np
import pytest
import taichi as ti

from circles import event
from circles.geometry import NEVER
from reference import time_of_impact

@ti.kernel
def times(pos: ti.types.ndarray(ndim=1), vel: ti.types.ndarray(ndim=1), radius: ti.types.ndarray(ndim=1),
          tau: ti.types.ndarray(ndim=1), horizon: ti.types.ndarray(ndim=1), out: ti.types.ndarray(ndim=1),
          real: ti.template()):
    """Pair p's time of impact (circles 2p and 2p + 1) with horizon[p]."""
    box = ti.Vector([1e9, 1e9], dt=real)
    for p in range(out.shape[0]):
        out[p] = event.pair_time_of_impact(pos, vel, radius, tau, 2 * p, 2 * p + 1, box, horizon[p], real, False)


@ti.kernel
def times_from_each_side(pos: ti.types.ndarray(ndim=1), vel: ti.types.ndarray(ndim=1),
                         radius: ti.types.ndarray(ndim=1), tau: ti.types.ndarray(ndim=1),
                         horizon: ti.types.ndarray(ndim=1), out: ti.types.ndarray(ndim=2), real: ti.template()):
    """Pair p's time (circles 2p and 2p + 1) from the lower slot's side (`pair_time_of_impact`),
    and as a search of each circle computes it (`pair_time`)."""
    box = ti.Vector([1e9, 1e9], dt=real)
    for p in range(out.shape[1]):
        lo, hi = 2 * p, 2 * p + 1
        out[0, p] = event.pair_time_of_impact(pos, vel, radius, tau, lo, hi, box, horizon[p], real, False)
        out[1, p] = event.pair_time(lo, event.own_values(lo, pos, vel, radius, tau), hi, pos, vel, radius, tau, box,
                                    horizon[p], real, False)
        out[2, p] = event.pair_time(hi, event.own_values(hi, pos, vel, radius, tau), lo, pos, vel, radius, tau, box,
                                    horizon[p], real, False)


def device_arrays(real, *host):
    """Taichi arrays of the host arrays in precision `real` (positions and velocities as vectors)."""
    arrays = []
    for a in host:
        dtype = ti.types.vector(2, real) if a.ndim == 2 else real
        d = ti.ndarray(dtype, shape=a.shape[0])
        d.from_numpy(a.astype(np.float64 if real == ti.f64 else np.float32))
        arrays.append(d)
    return arrays


def run_times(real, pos, vel, radius, tau, horizon):
    arrays = device_arrays(real, pos, vel, radius, tau, horizon)
    out = ti.ndarray(real, shape=horizon.shape[0])
    times(*arrays, out, real)
    return out.to_numpy()


def pairs(rng, m):
    """m pairs: circle 2p and 2p + 1, within a few radii of each other, with random clocks."""
    centre = rng.uniform(-5, 5, size=(m, 2))
    pos = np.empty((2 * m, 2))
    pos[0::2] = centre
    pos[1::2] = centre + rng.uniform(-1.5, 1.5, size=(m, 2))
    vel = rng.uniform(-1, 1, size=(2 * m, 2))
    radius = rng.uniform(0.2, 0.5, size=2 * m)
    tau = rng.uniform(0, 0.3, size=2 * m)
    return pos, vel, radius, tau


def head_on(rng, pos, vel, radius, tau, k):
    """The first k pairs made a hair apart (1e-7 to 1e-2 of their contact distance) and heading
    nearly straight at each other, their clocks equal: their time of impact is close to
    c / (2 q), the cull's bound. In place."""
    gap = pos[1:2 * k:2] - pos[0:2 * k:2]
    unit = gap / np.linalg.norm(gap, axis=1, keepdims=True)
    s = radius[0:2 * k:2] + radius[1:2 * k:2]
    pos[1:2 * k:2] = pos[0:2 * k:2] + unit * (s * (1.0 + 10.0 ** rng.uniform(-7, -2, size=k)))[:, None]
    vel[1:2 * k:2] = vel[0:2 * k:2] - unit * rng.uniform(0.5, 1.5, size=(k, 1)) + rng.normal(0, 1e-3, size=(k, 2))
    tau[1:2 * k:2] = tau[0:2 * k:2]


def expected(pos, vel, radius, tau, m):
    """The reference's time for each pair, from the later of the two clocks; math.inf for never,
    and a flag for the cases whose outcome round-off could tip (disc within 1e-9 of b^2 + |a c|)."""
    out, doubtful = [], []
    for p in range(m):
        lo, hi = 2 * p, 2 * p + 1
        t0 = max(tau[lo], tau[hi])
        xl = pos[lo] + vel[lo] * (t0 - tau[lo])
        xh = pos[hi] + vel[hi] * (t0 - tau[hi])
        d = xh - xl
        dv = vel[hi] - vel[lo]
        s = radius[lo] + radius[hi]
        t = time_of_impact(d[0], d[1], dv[0], dv[1], s)
        out.append(t0 + t)
        b = d @ dv
        a = dv @ dv
        c = d @ d - s * s
        doubtful.append(abs(b) < 1e-9 * (1 + abs(b)) or abs(b * b - a * c) < 1e-9 * (b * b + abs(a * c)))
    return np.array(out), np.array(doubtful)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_pair_time_of_impact_matches_the_reference_in_every_case(circles_cpu, seed):
    m = 4000
    rng = np.random.default_rng(seed)
    pos, vel, radius, tau = pairs(rng, m)
    # A quarter of the pairs start touching or overlapping, so the "collide now" case is drawn.
    k = m // 4
    gap = pos[1:2 * k:2] - pos[0:2 * k:2]
    norm = np.linalg.norm(gap, axis=1, keepdims=True)
    pos[1:2 * k:2] = pos[0:2 * k:2] + gap / norm * (radius[0:2 * k:2] + radius[1:2 * k:2])[:, None] * 0.9
    tau[1:2 * k:2] = tau[0:2 * k:2]
    # A horizon far beyond every time: nothing is culled.
    got = run_times(ti.f64, pos, vel, radius, tau, np.full(m, 1e30))
    want, doubtful = expected(pos, vel, radius, tau, m)
    sure = ~doubtful
    never = ~np.isfinite(want)
    # Every case is drawn many times.
    t0 = np.maximum(tau[0::2], tau[1::2])
    assert (never & sure).sum() > 500
    assert (~never & sure & (want > t0)).sum() > 300
    assert (~never & sure & (want == t0)).sum() > 200
    # Never is NEVER; a hit is the same formula in float64, which differs from the
    # reference's only by the rounding of a fused multiply-add here or there: a few ulps in b,
    # c and disc, which the square root and the quotient keep within 1e-9 of t (times here
    # are at most tens of units, and the doubtful cases, where disc cancels, are left out).
    # (NEVER reaches the kernel as a float32 literal, so in float64 it reads float32(1e30).)
    assert np.all(got[never & sure] == np.float64(np.float32(NEVER)))
    hit = ~never & sure
    assert np.allclose(got[hit], want[hit], rtol=1e-9, atol=1e-9)
    assert math.isfinite(float(got[hit].max()))


@pytest.mark.parametrize("real", ["f32", "f64"])
def test_a_hair_apart_the_time_keeps_its_precision(circles_cpu, real):
    """Two circles of radius 1/2 a gap g = 2^-k apart along x, closing at 1 with a sideways speed
    2^-q: b^2 is about 1 / (2 g) times a c, so the root (-b - sqrt(disc)) / a would lose k bits
    to cancellation; c / (-b + sqrt(disc)) keeps the precision's own. The inputs are chosen so
    that a, b and c are exact (few bits), so the time's only errors are the roundings of disc,
    its root, one sum and one quotient: within 8 epsilons of the exact time (computed here with
    50 digits), where the cancelling root is off by 2^k epsilons."""
    from decimal import Decimal, getcontext
    from fractions import Fraction

    getcontext().prec = 50
    dtype, eps, ks, qs = ((np.float64, 2.0 ** -52, range(16, 27), (4, 10, 16)) if real == "f64"
                          else (np.float32, 2.0 ** -23, range(6, 12), (2, 3, 4)))
    cases = [(k, q) for k in ks for q in qs]
    m = len(cases)
    pos, vel = np.zeros((2 * m, 2)), np.zeros((2 * m, 2))
    want = []
    for p, (k, q) in enumerate(cases):
        g, side = 2.0 ** -k, 2.0 ** -q
        pos[2 * p + 1] = (1.0 + g, 0.0)
        vel[2 * p + 1] = (-1.0, side)
        # |d + dv t| = 1 with d = (1 + g, 0), dv = (-1, side): exact a, b, c, then the root.
        a, b, c = Fraction(1) + Fraction(side) ** 2, -(1 + Fraction(g)), (1 + Fraction(g)) ** 2 - 1
        disc = b * b - a * c
        root = Decimal(disc.numerator).sqrt() / Decimal(disc.denominator).sqrt()
        want.append(float(Decimal(c.numerator) / Decimal(c.denominator) / (Decimal(-b.numerator) / Decimal(b.denominator) + root)))
    assert np.array_equal(pos.astype(dtype), pos) and np.array_equal(vel.astype(dtype), vel)
    got = run_times(getattr(ti, real), pos, vel, np.full(2 * m, 0.5), np.zeros(2 * m), np.full(m, 1e30))
    np.testing.assert_allclose(got, want, rtol=8 * eps, atol=0)


@pytest.mark.parametrize("real", ["f32", "f64"])
def test_cull_keeps_every_time_up_to_the_horizon(circles_cpu, real):
    """Pairs that meet, with horizons drawn around their times of impact: some a few units in
    the last place before or after, some far. With the horizon, a time at or before it is the
    same number as without one (bit for bit), and any other pair comes back after it. The
    horizons cull most pairs (else the cull would not be tested)."""
    real = {"f32": ti.f32, "f64": ti.f64}[real]
    np_real = np.float32 if real == ti.f32 else np.float64
    m = 20000
    rng = np.random.default_rng(7)
    pos, vel, radius, tau = pairs(rng, m)
    # Half the pairs a hair apart and heading nearly straight at each other: the cull's
    # margins are what keeps them.
    k = m // 2
    head_on(rng, pos, vel, radius, tau, k)
    free = run_times(real, pos, vel, radius, tau, np.full(m, 1e30))
    t0 = np.maximum(tau[0::2], tau[1::2]).astype(np_real)
    hits = free < 1e29
    # Horizons: at the time of impact moved by -4..4 units in the last place, or at the later
    # clock plus a random share of the time to impact (0 to 2), or at the later clock itself.
    target = np.where(hits, free, t0 + 1.0).astype(np_real)
    ulps = rng.integers(-4, 5, size=m)
    near = target.copy()
    toward = np.where(ulps > 0, np_real(np.inf), np_real(-np.inf))
    for done in range(4):
        more = np.abs(ulps) > done
        near[more] = np.nextafter(near[more], toward[more])
    share = (t0 + (target - t0) * rng.uniform(0.0, 2.0, size=m)).astype(np_real)
    kind = rng.integers(0, 3, size=m)
    horizon = np.where(kind == 0, near, np.where(kind == 1, share, t0)).astype(np_real)
    got = run_times(real, pos, vel, radius, tau, horizon)
    kept = free <= horizon
    assert kept.sum() > 2000 and (~kept & hits).sum() > 2000
    assert np.array_equal(got[kept], free[kept])
    assert np.all(got[~kept] > horizon[~kept])
    # The cull drops most of the pairs that meet after their horizon (returned as NEVER).
    dropped = got[~kept] >= np_real(1e29)
    assert dropped.mean() > 0.5


@pytest.mark.parametrize("real", ["f32", "f64"])
def test_pair_time_is_the_same_from_either_circle(circles_cpu, real):
    """Both circles of a pair must agree on its time bit for bit (each offers it to the other,
    and an event is executed when both chose it). Pairs of every case (receding, missing,
    hitting, touching, a hair apart and closing head on) with clocks apart, horizons far and
    near: the time from the higher slot's side, with its own values read once, is the lower
    slot's number, NEVER included."""
    real = {"f32": ti.f32, "f64": ti.f64}[real]
    np_real = np.float32 if real == ti.f32 else np.float64
    m = 20000
    rng = np.random.default_rng(11)
    pos, vel, radius, tau = pairs(rng, m)
    head_on(rng, pos, vel, radius, tau, m // 4)
    horizon = np.where(rng.random(m) < 0.5, 1e30, rng.uniform(0.0, 3.0, size=m))
    arrays = device_arrays(real, pos, vel, radius, tau, horizon)
    out = ti.ndarray(real, shape=(3, m))
    times_from_each_side(*arrays, out, real)
    got = out.to_numpy()
    met = got[0] < np_real(1e29)
    assert met.sum() > 3000 and (~met).sum() > 3000
    assert np.array_equal(got[1], got[0])
    assert np.array_equal(got[2], got[0])
