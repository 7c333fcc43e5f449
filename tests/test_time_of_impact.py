"""The event scheme's pair time of impact, computed without branches, case by case against the
test suite's own float64 formula (tests/reference.py): pairs that recede, approach and miss,
approach and hit, and touch or overlap while approaching, with the two circles' clocks apart."""
import math

import numpy as np
import pytest
import taichi as ti

from circles import event
from circles.geometry import NEVER
from reference import time_of_impact

vec2 = ti.types.vector(2, ti.f64)


@ti.kernel
def times(pos: ti.types.ndarray(dtype=vec2, ndim=1), vel: ti.types.ndarray(dtype=vec2, ndim=1),
          radius: ti.types.ndarray(ndim=1), tau: ti.types.ndarray(ndim=1), out: ti.types.ndarray(ndim=1)):
    box = ti.Vector([1e9, 1e9], dt=ti.f64)
    for p in range(out.shape[0]):
        out[p] = event.pair_time_of_impact(pos, vel, radius, tau, 2 * p, 2 * p + 1, box, ti.f64, False)


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
    arrays = []
    for host, dtype, shape in ((pos, vec2, m * 2), (vel, vec2, m * 2), (radius, ti.f64, m * 2), (tau, ti.f64, m * 2)):
        a = ti.ndarray(dtype, shape=shape)
        a.from_numpy(host)
        arrays.append(a)
    out = ti.ndarray(ti.f64, shape=m)
    times(*arrays, out)
    got = out.to_numpy()
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
