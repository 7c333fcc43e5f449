"""Counter-based random draws that every placement shares, and the clearance it keeps: a
circle's numbers are a hash of (seed, circle, draw), so a placement does not depend on the
thread count."""
import numpy as np
import taichi as ti

from ..scene import PLACE_CLEARANCE

#: Placed circles keep this relative clearance, so rounding never makes an overlap (a walled
#: scene is checked to leave room for it, `scene.check_room`).
CLEARANCE = PLACE_CLEARANCE


@ti.func
def mix32(x):
    """A 32-bit integer hash with good avalanche (lowbias32)."""
    x ^= x >> ti.u32(16)
    x *= ti.u32(0x7FEB352D)
    x ^= x >> ti.u32(15)
    x *= ti.u32(0x846CA68B)
    x ^= x >> ti.u32(16)
    return x


@ti.func
def uniform(seed, i, k):
    """A float64 in [0, 1) from the counters (seed, i, k)."""
    h = mix32(ti.cast(seed, ti.u32) ^ mix32(ti.cast(i, ti.u32) ^ mix32(ti.cast(k, ti.u32) * ti.u32(0x9E3779B9))))
    return ti.cast(h, ti.f64) * (1.0 / 4294967296.0)


@ti.func
def stored(x, single: ti.template()):
    """x (float64) rounded to the storage precision: the value the simulation will hold."""
    y = x
    if ti.static(single):
        y = ti.cast(ti.cast(x, ti.f32), ti.f64)
    return y


@ti.func
def inside(x, r, box_w, box_h, periodic: ti.template()):
    """Whether a circle of radius r at x is CLEARANCE r inside the walls (in [0, W) x [0, H) if periodic)."""
    ok = True
    if ti.static(periodic):
        ok = 0.0 <= x[0] < box_w and 0.0 <= x[1] < box_h
    else:
        m = r * (1.0 + CLEARANCE)
        ok = m <= x[0] <= box_w - m and m <= x[1] <= box_h - m
    return ok


def seed_key(seed: int) -> int:
    """The 31-bit key of the placement's hash for a seed >= 0: the seed itself below 2**31, else
    a key drawn from all of its bits (so that seeds that differ only above bit 31 place apart)."""
    seed = int(seed)
    if seed < 1 << 31:
        return seed
    return int(np.random.SeedSequence(seed).generate_state(1, np.uint32)[0]) & 0x7FFFFFFF


@ti.func
def _draw_key(seed, draw):
    """A key for draw number `draw`; mix32(mix32(i) ^ key) is circle i's 32-bit number for it."""
    return mix32(ti.cast(seed, ti.u32) ^ mix32(ti.cast(draw, ti.u32) * ti.u32(0x9E3779B9)))
