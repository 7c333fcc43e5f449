"""Time of impact of two circles, with its cull of pairs that cannot meet before a horizon, and
the key (time, lo, hi) that orders events."""
import taichi as ti

from ..geometry import displacement, NEVER, NO_EVENT

#: The cull of `pair_time_of_impact`: a pair is dropped as meeting after the horizon only when
#: its gap closes too slowly by this relative margin, and by CULL_ABSOLUTE of the horizon's size
#: (a few of its units in the last place, even in float32).
CULL_RELATIVE = 2.0 ** -10
CULL_ABSOLUTE = 2.0 ** -20


@ti.func
def pair_time_of_impact(pos: ti.template(), vel: ti.template(), radius: ti.template(), tau: ti.template(), lo, hi,
                        box, horizon, real: ti.template(), periodic: ti.template()):
    """Time of impact of circles lo < hi, or NEVER; computed from lo's side only so both agree bit for bit.

    Most pairs of a search cannot meet before the horizon; their time is not computed (a square
    root and a division), and NEVER comes back for them. The cull is a bound, not an estimate:
    with T = horizon - t0 >= 0, q = -dx.dv > 0 and c = |dx|^2 - s^2, the gap squared
    |dx + dv t|^2 - s^2 >= c - 2 q t stays positive up to the horizon when c > 2 q T, and then
    the computed time, t0 + c / (q + sqrt(q^2 - |dv|^2 c)) >= t0 + c / (2 q), rounds above the
    horizon too (margins CULL_RELATIVE and CULL_ABSOLUTE cover the round-off of every step). So
    a time at or before the horizon is the same number with or without the cull, and a culled
    pair is one whose time every caller rejects: the searches' results do not change, bit for
    bit."""
    return _time_of_impact(own_values(lo, pos, vel, radius, tau), own_values(hi, pos, vel, radius, tau), box,
                           horizon, real, periodic, ti.static(_at_step_start(tau)))


class _StepStart:
    """In place of the clocks `tau` at a step's start, where every circle's clock is 0: a time
    of impact then reads no clock, and its places at the pair's start time are the positions
    themselves (x + v * 0 is x), so it is the same number."""

    def __getitem__(self, i):
        return 0.0


#: The clocks at a step's start (`_StepStart`), for the first predictions.
STEP_START = _StepStart()


class Same:
    """In place of an array whose entries are all one value (every circle's radius or inverse
    mass in a scene of equal circles), that value: read from a kernel's argument, not from
    memory at every circle, in the same type, so every result is the same number."""

    def __init__(self, value):
        self.value = value

    def __getitem__(self, i):
        return self.value


def _at_step_start(tau) -> bool:
    """Whether the clocks `tau` are `STEP_START` (known when a kernel compiles): then a time of
    impact starts from the positions themselves, with no advance along the velocities."""
    return isinstance(tau, _StepStart)


@ti.func
def own_values(i, pos: ti.template(), vel: ti.template(), radius: ti.template(), tau: ti.template()):
    """(tau, x, v, r) of circle i: what its pair times read of it (`pair_time`)."""
    return tau[i], pos[i], vel[i], radius[i]


@ti.func
def pair_time(i, own: ti.template(), j, pos: ti.template(), vel: ti.template(), radius: ti.template(),
              tau: ti.template(), box, horizon, real: ti.template(), periodic: ti.template()):
    """`pair_time_of_impact` of circles i and j, with i's values `own` (`own_values`) read once by
    a search. In a walled box from i's side: dx and dv are then the exact negations of the lower
    slot's (a difference of two floats negates exactly), and every product and sum below is the
    same number for either sign, so both circles get the time bit for bit. In a periodic box
    from the lower slot's side (the minimum image of a displacement of half the box is not the
    negation of the other's)."""
    t = ti.cast(NEVER, real)
    if ti.static(periodic):
        t = pair_time_of_impact(pos, vel, radius, tau, ti.min(i, j), ti.max(i, j), box, horizon, real, periodic)
    else:
        t = _time_of_impact(own, own_values(j, pos, vel, radius, tau), box, horizon, real, periodic,
                            ti.static(_at_step_start(tau)))
    return t


@ti.func
def _time_of_impact(u: ti.template(), w: ti.template(), box, horizon, real: ti.template(),
                    periodic: ti.template(), start: ti.template()):
    """The time of impact of two circles of values u and w (`own_values`), as
    `pair_time_of_impact` describes it. `start`: both clocks are 0 (`STEP_START`), so the places
    at the pair's start time are the positions themselves: x + v * 0 is x for a finite v and a
    position x > 0, and the compiler does not fold the product by zero away (it may not, for an
    infinite v), so it is left out here; the same numbers."""
    t0 = ti.cast(0.0, real)
    xu = u[1]
    xw = w[1]
    if ti.static(not start):
        # The later clock, as a plain comparison (clocks are never NaN): one instruction, where
        # ti.max's NaN-aware form takes three.
        t0 = ti.select(u[0] < w[0], w[0], u[0])
        xu = u[1] + u[2] * (t0 - u[0])
        xw = w[1] + w[2] * (t0 - w[0])
    dx = displacement(xu, xw, box, periodic)
    dv = w[2] - u[2]
    s = u[3] + w[3]
    b = dx.dot(dv)
    c = dx.dot(dx) - s * s
    never = ti.cast(NEVER, real)
    t = never
    t_left = (horizon - t0) * (1.0 + CULL_RELATIVE) + ti.abs(horizon) * CULL_ABSOLUTE  # T, with the margins
    # Touching already or closing fast enough to touch by the horizon: one test, rarely passed
    # (a search's neighbours are mostly beyond reach), so its branch is well predicted; a
    # separate test of b < 0 first would be a coin toss. (Receding pairs that pass it get
    # NEVER below; with b >= 0 a pair passes only when it overlaps.)
    if c + 2.0 * b * t_left <= 0:
        a = dv.dot(dv)
        disc = b * b - a * c
        # Every case computed and the answer selected, with no branches: which case a pair falls
        # in is close to random, and a mispredicted branch costs more than the square root.
        hit = t0 + c / (-b + ti.sqrt(ti.max(disc, 0.0)))  # the root without cancellation
        t = ti.select(disc > 0, hit, never)
        t = ti.select(c <= 0, t0, t)  # touching (or overlapping by round-off) and approaching: collide now
        t = ti.select(b < 0, t, never)
    return t


@ti.func
def _tie_ids(x, ev_p: ti.template(), ids: ti.template(), n):
    """(lo, hi): the ids part of circle x's event key (`event_key`)."""
    p = ev_p[x]
    lo = n + 8
    hi = n + 8
    if p >= 0:
        lo = ti.min(ids[x], ids[p])
        hi = ti.max(ids[x], ids[p])
    elif p != NO_EVENT:
        lo = ids[x]
        hi = n + (-1 - p)
    return lo, hi


@ti.func
def event_key(i, ev_t: ti.template(), ev_p: ti.template(), ids: ti.template(), n):
    """The key (time, lo, hi) of circle i's stored event: a pair's creation ids in order, a
    wall's (id, n + wall), no event's (NEVER, n + 8, n + 8)."""
    lo, hi = _tie_ids(i, ev_p, ids, n)
    return ev_t[i], lo, hi
