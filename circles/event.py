"""Scheme "event": exact collisions by time of impact, executed in parallel rounds.

Within a step [0, t_end] every circle carries a local clock tau (its position is stored at
tau). A round has three stages:

1. predict: each circle whose neighbourhood changed finds its earliest event in
   (tau, t_end], a pair time of impact (both circles brought to a common time) or a wall hit,
   chosen by the key (time, lo, hi) so that ties break by ids.
2. bound: a lower bound D_k on the time at which circle k's straight path can be disturbed
   by anything other than its own predicted event. A neighbour l can only touch k
   unexpectedly after l itself leaves its straight path (at min(t_l, D_l)), and then only
   once its deviation, growing at most at 2 vlim, has closed their straight-path gap:
       D_k = min over l in the 3x3 cells of k of F_kl(min(t_l, D_l))   (see bound_sweep).
   Delays add up along a chain of neighbours, so far events do not hold up near ones. The
   sweeps run from D = infinity down to the fixed point, which is unique, so D does not
   depend on the order in which threads update it.
3. execute: an event (i, j, t) is safe when i and j chose each other and t <= D_i, D_j.
   Safe events touch disjoint circles (no races, no atomics on velocities); the earliest
   event overall is always safe, so every round makes progress. Simultaneous safe events
   touch disjoint circles and commute, so executing them together equals any serial order.

On a CPU the step runs from one queue instead (`queue_step`, below): the same events in the
same order with the same arithmetic, without the rounds. With several threads and one grid
level, the circles are split into parts whose events cannot touch each other within a window
of the step, and each part runs its own queue (`split_parts`, `queue_parts`, below).

Radius spread: cells as wide as the reach of the largest circles would hold hundreds of small
circles when a few circles are much larger. In a walled box with a few large circles (see
simulation.LARGE_RADIUS_RATIO) the queue's grid has two levels: fine cells sized for the small
circles, and coarse cells, blocks of fine cells as wide as the reach of two large circles,
that list the large circles only (`build_coarse`). A small circle meets the small ones in its
3 x 3 fine cells and the large ones in its 3 x 3 coarse cells; a large circle meets the small
ones in the block of fine cells its reach spans and the large ones in its coarse cells
(`_runs`). Every pair that can collide in the step is met from both of its circles, as with
one level, so the state is the same bit for bit.

The grid and the bounds assume every speed stays below vlim during the step. A collision
that would exceed it (a light circle hit by a heavy one) ends the step at its time: the
rounds, which execute independent events out of time order, redo the step up to that time
(the events before it are the same, by causality); the queue, which executes them in time
order, has executed exactly those when it meets the collision, and goes on with the step's
end moved to its time. Events at exactly that time, the collision among them, are executed
(a step's last instant belongs to it). The next step rebuilds the grid for the new speeds.
"""
import taichi as ti

from . import launch
from .discrete import NLARGE
from .grid import PART_ITERATIONS, _part_range, count_parts
from .reductions import offer_speed, speed_of, speed_result
from .geometry import (NEVER, NO_EVENT, cell_coords, displacement, forward_fits, key_less, neighbour_range,
                       pairs_once, run_parts, wide_row)

#: Bound sweeps per launch (even: the two flag arrays swap roles each sweep).
SWEEPS_PER_LAUNCH = 4
#: The keys a bound carries besides an event's (`_bound_sweep`): below every event's, for a
#: bound that no event at its time may pass; n + BOUND_KEY_NONE, above every event's (no event
#: has more than n + 8), for a bound set by no event.
BOUND_KEY_LOW = -1
BOUND_KEY_NONE = 9

ndarr = ti.types.ndarray(ndim=1)


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
def _coarse_of(c, ncx, mx, my):
    """(gx, gy): the coarse cell that holds fine cell c of a walled grid (`build_coarse`)."""
    cx, cy = cell_coords(c, ncx)
    return cx // mx, cy // my


@ti.func
def _runs(i, radius: ti.template(), box, ncx, ncy, rows, segs, r_cut, margin, two_level: ti.template()):
    """(runs, kx, ky): the number of runs of slots (`_run`) that hold every circle that circle i
    can meet in the step, and the half-widths in cells of its block of fine cells.

    One level: the runs of the 3 x 3 cells. Two levels (`build_coarse`): a small circle's 3 x 3
    fine cells (kx = ky = 1) or a large circle's block of fine cells within its reach of any
    small circle (a whole cell more, against round-off), then the three rows of its 3 x 3
    coarse cells, which list the large circles only."""
    runs = rows * segs
    kx = 1
    ky = 1
    if ti.static(two_level):
        r = ti.cast(radius[i], ti.f64)
        if r > r_cut:
            reach = r + r_cut + margin
            kx = ti.cast(ti.floor(reach * ncx / ti.cast(box[0], ti.f64)), ti.i32) + 1
            ky = ti.cast(ti.floor(reach * ncy / ti.cast(box[1], ti.f64)), ti.i32) + 1
        runs = 2 * ky + 1 + 3
    return runs, kx, ky


@ti.func
def _run(r, c, kx, ky, cell_start: ti.template(), coarse_start: ti.template(), ncx, ncy, segs, ncx_c, ncy_c, mx,
         my, periodic: ti.template(), two_level: ti.template()):
    """(lo, hi, coarse): run r of `_runs` around fine cell c: slots [lo, hi) of the grid's
    `sorted_ids`, or of the coarse grid's `coarse_ids` when `coarse`."""
    lo = 0
    hi = 0
    coarse = False
    if ti.static(two_level):
        fine = 2 * ky + 1
        if r < fine:
            lo, hi = wide_row(c, r - ky, kx, cell_start, ncx, ncy)
        else:
            coarse = True
            gx, gy = _coarse_of(c, ncx, mx, my)
            y = gy + r - fine - 1
            if 0 <= y < ncy_c:
                base = y * ncx_c
                lo = coarse_start[base + ti.max(gx - 1, 0)]
                hi = coarse_start[base + ti.min(gx + 1, ncx_c - 1) + 1]
    else:
        row, seg = run_parts(r, segs, periodic)
        lo, hi = neighbour_range(c, row, seg, cell_start, ncx, ncy, periodic)
    return lo, hi, coarse


@ti.func
def _at(k, coarse, sorted_ids: ti.template(), coarse_ids: ti.template(), radius: ti.template(), r_cut,
        two_level: ti.template()):
    """The circle in slot k of a run (`_run`), or -1 for a large circle met in a fine run of a
    two-level grid (its coarse run lists it: each circle is met once)."""
    j = -1
    if ti.static(two_level):
        if coarse:
            j = coarse_ids[k]
        else:
            j = sorted_ids[k]
            if ti.cast(radius[j], ti.f64) > r_cut:
                j = -1
    else:
        j = sorted_ids[k]
    return j


@launch.kernel
def build_coarse(large: ndarr, work: ndarr, cell_of: ndarr, coarse_start: ndarr, coarse_ids: ndarr, ncx: ti.i32,
                 mx: ti.i32, my: ti.i32, ncx_c: ti.i32, ncy_c: ti.i32):
    """The coarse level of a two-level grid: the work[NLARGE] large circles listed in `large`,
    sorted into coarse cells of mx x my fine cells (so a circle's coarse cell follows from its
    fine cell, the one it started the step in); cell g holds coarse_ids[coarse_start[g]:
    coarse_start[g + 1]]. The coarse cells are as wide as two large radii and the reach of a
    step, so every large circle that a circle can meet lies in its 3 x 3 coarse cells.
    Serial counting sort: the large circles are few."""
    ncells = ncx_c * ncy_c
    for g in range(ncells + 1):
        coarse_start[g] = 0
    ti.loop_config(serialize=True)
    for _ in range(1):
        nl = work[NLARGE]
        for a in range(nl):
            gx, gy = _coarse_of(cell_of[large[a]], ncx, mx, my)
            coarse_start[gy * ncx_c + gx] += 1
        for g in range(1, ncells):
            coarse_start[g] += coarse_start[g - 1]
        # coarse_start[g] is now the end of cell g; counting down fills each cell to its start.
        for a in range(nl):
            i = large[a]
            gx, gy = _coarse_of(cell_of[i], ncx, mx, my)
            g = gy * ncx_c + gx
            coarse_start[g] -= 1
            coarse_ids[coarse_start[g]] = i
        coarse_start[ncells] = nl


@ti.func
def _earliest(i, full, pos: ti.template(), vel: ti.template(), radius: ti.template(), tau: ti.template(),
              ids: ti.template(), ev_t: ti.template(), ev_p: ti.template(), moved: ti.template(),
              cell_of: ti.template(), cell_start: ti.template(), sorted_ids: ti.template(), ncx, ncy, rows, segs, box,
              horizon, real: ti.template(), periodic: ti.template(), coarse_start: ti.template(),
              coarse_ids: ti.template(), ncx_c, ncy_c, mx, my, r_cut, margin, two_level: ti.template(),
              queue: ti.template(), code, size, changed_a, changed_b, pend_at, scale, nb, off, hb, part: ti.template()):
    """Circle i's earliest event in (tau_i, horizon], chosen by the key
    (time, lo, hi) (`event_key`): with `full`, over its walls and all its neighbours; else its
    stored event compared with its pairs with the circles that moved (see `_predict`).
    Neighbours: those of one grid level, or of two (`_runs`).

    With a `queue` (heap, where, heap_t, head, nxt, prv and pending of `queue_step`, and its
    calendar's scale and nb; else an empty tuple), `moved` holds the queue's stamps, and with
    `code` >= 0 i is a circle whose velocity an event changed (as changed_a, and changed_b when
    a pair's, else a value no partner has). A neighbour first met in this event (stamp below
    `code`) is stamped `code` + 1 when its event was with changed_a or changed_b (it must search
    again: listed in pending from `pend_at` on, and counted), else `code`. Each pair with a
    neighbour stamped `code` is offered to it: the neighbour takes the pair when it comes before
    its own event, and moves up the queue. So a pair's time of impact is computed once for both
    circles. With `code` < 0 nothing is stamped or offered. Returns (time, partner, queue size,
    neighbours listed); without a queue, size comes back as given and none are listed. `off` and
    `hb`: where the queue starts in its arrays (`_queue_put`). `part`: () or (label, touched,
    dirty), when the circles are split into parts (`split_parts`): then only neighbours of i's
    part are met, and a neighbour j in another part flags i touched and dirty and j dirty."""
    n = pos.shape[0]
    size_now = size
    pending = 0
    best_t = ti.cast(NEVER, real)
    best_lo = n + 8
    best_hi = n + 8
    best_p = NO_EVENT
    if not full:
        best_t, best_lo, best_hi = event_key(i, ev_t, ev_p, ids, n)
        best_p = ev_p[i]
    if ti.static(not periodic):
        if full:  # the wall events of a circle that did not move stand
            best_t, best_lo, best_hi, best_p = _wall_events(i, pos, vel, radius, tau, ids, box, horizon, real, best_t,
                                                            best_lo, best_hi, best_p)
    c = cell_of[i]
    mine = _own_part(i, part)
    own = own_values(i, pos, vel, radius, tau)
    runs, kx, ky = _runs(i, radius, box, ncx, ncy, rows, segs, r_cut, margin, two_level)
    for r in range(runs):
        k_lo, k_hi, coarse = _run(r, c, kx, ky, cell_start, coarse_start, ncx, ncy, segs, ncx_c, ncy_c, mx, my,
                                  periodic, two_level)
        for k in range(k_lo, k_hi):
            j = _at(k, coarse, sorted_ids, coarse_ids, radius, r_cut, two_level)
            if ti.static(len(part) > 1):
                if j >= 0 and _own_part(j, part) != mine:
                    # A neighbour in another part: i's search is not complete past the window,
                    # and i may have changed the pair (see `queue_parts`).
                    part[1][i] = 1
                    part[2][i] = 1
                    part[2][j] = 1
            if j >= 0 and j != i and _own_part(j, part) == mine and (full or moved[j] != 0):
                if ti.static(len(queue) > 0):
                    # First met in this event's searches: a neighbour whose event was with one of
                    # the changed circles must search again (`queue_step`); the others take offers.
                    if moved[j] < code:
                        jp = ev_p[j]
                        if jp == changed_a or jp == changed_b:
                            moved[j] = code + 1
                            queue[6][pend_at + pending] = j
                            pending += 1
                        else:
                            moved[j] = code
                # The same number as from j's side, bit for bit (`pair_time`).
                t = pair_time(i, own, j, pos, vel, radius, tau, box, horizon, real, periodic)
                if t <= horizon:
                    # The key (creation ids, so that ties break the same whatever the memory
                    # order), read only for the few pairs within the horizon.
                    klo = ti.min(ids[i], ids[j])
                    khi = ti.max(ids[i], ids[j])
                    if key_less(t, klo, khi, best_t, best_lo, best_hi):
                        best_t, best_lo, best_hi, best_p = t, klo, khi, j
                    if ti.static(len(queue) > 0):
                        if moved[j] == code:
                            if _offer(j, i, t, klo, khi, ev_t, ev_p, ids, n):
                                size_now = _queue_fix(j, size_now, scale, nb, queue, ev_t, ev_p, ids, n, off, hb)
    return best_t, best_p, size_now, pending


@ti.func
def _own_part(i, part: ti.template()):
    """The part of circle i (`split_parts`), or 0 when the circles are not split: part = (), or
    a tuple whose first array holds the labels. A label is the part k, or -1 - k for a circle
    claimed with its cluster (~x)."""
    k = 0
    if ti.static(len(part) > 0):
        x = part[0][i]
        k = x ^ (x >> 31)
    return k


@ti.func
def _wall_events(i, pos: ti.template(), vel: ti.template(), radius: ti.template(), tau: ti.template(),
                 ids: ti.template(), box, horizon, real: ti.template(), best_t, best_lo, best_hi, best_p):
    """The best (key, partner) so far, (best_t, best_lo, best_hi, best_p), updated with circle
    i's wall hits in (tau_i, horizon] (a walled box)."""
    n = pos.shape[0]
    ti_ = tau[i]
    xi = pos[i]
    vi = vel[i]
    ri = radius[i]
    for axis in ti.static(range(2)):
        # The wall it heads for, both gaps computed and one selected, with no branches (the
        # signs of the velocities are random); -v and |v| are the same number for v < 0.
        v = vi[axis]
        low = v < 0
        gap = ti.select(low, ti.max(xi[axis] - ri, 0.0), ti.max(box[axis] - ri - xi[axis], 0.0))
        t = ti.select(v != 0, ti_ + gap / ti.abs(v), ti.cast(NEVER, real))
        w = 2 * axis + ti.select(low, 0, 1)
        if t <= horizon and key_less(t, ids[i], n + w, best_t, best_lo, best_hi):
            best_t, best_lo, best_hi, best_p = t, ids[i], n + w, -1 - w
    return best_t, best_lo, best_hi, best_p


@ti.func
def _offer(j, i, t, klo, khi, ev_t: ti.template(), ev_p: ti.template(), ids: ti.template(), n):
    """Circle j takes the pair with i, of key (t, klo, khi), as its event when the pair comes
    before its stored one; returns whether it did."""
    jt, jlo, jhi = event_key(j, ev_t, ev_p, ids, n)
    taken = key_less(t, klo, khi, jt, jlo, jhi)
    if taken:
        ev_t[j] = t
        ev_p[j] = i
    return taken


@ti.func
def _pair_once(i, j, a: ti.template()):
    """The pair (i, j) offered to both circles (`_offer`) when it meets within the horizon, as
    `geometry.pairs_once` visits it; `a` holds (pos, vel, radius, tau, ids, ev_t, ev_p, box,
    horizon, real, periodic, i's `own_values`), the last read once for all of i's pairs."""
    n = a[0].shape[0]
    t = pair_time(i, a[11], j, a[0], a[1], a[2], a[3], a[7], a[8], a[9], a[10])
    if t <= a[8]:
        klo = ti.min(a[4][i], a[4][j])
        khi = ti.max(a[4][i], a[4][j])
        _offer(i, j, t, klo, khi, a[5], a[6], a[4], n)
        _offer(j, i, t, klo, khi, a[5], a[6], a[4], n)


@ti.func
def _first_events_once(pos: ti.template(), vel: ti.template(), radius: ti.template(), tau: ti.template(),
                       ids: ti.template(), ev_t: ti.template(), ev_p: ti.template(), cell_of: ti.template(),
                       cell_start: ti.template(), sorted_ids: ti.template(), ncx, ncy, rows, segs, box_w, box_h,
                       horizon, real: ti.template(), periodic: ti.template(), fresh: ti.template()):
    """On one thread, every circle's earliest event, as `_earliest` in full would find it, with
    each pair's time of impact computed once, not once from each circle: every circle takes
    its walls, then each pair is offered to both circles from the forward half of one circle's
    cells (`geometry.pairs_once`). The minimum of the keys does not depend on the order of the
    offers. One grid level. `fresh`: every circle holds no event (as `queue_step`'s finish on
    one thread leaves it), and takes its walls as the pairs' loop visits it
    (`_merge_wall_event`), after the offers of the circles before it, in one pass instead of two.

    (On several threads the offers of two threads could meet at one circle; there each circle
    searches all its cells, `queue_step`. Threads that take bands of rows of cells, even bands
    then odd ones, need no atomics, but measured no faster on 2 cores at 1e5 and 1e6; nor did
    one part of the slots per thread, then the pairs across the parts' ends on one thread, at
    1e5: see bench/PERFORMANCE.md.)"""
    n = pos.shape[0]
    if ti.static(not fresh):
        ti.loop_config(serialize=True)
        for i in range(n):
            box = ti.Vector([box_w, box_h], dt=real)
            _first_wall_event(i, pos, vel, radius, tau, ids, ev_t, ev_p, box, horizon, real, periodic)
    forward = forward_fits(ncx, ncy, periodic)
    ti.loop_config(serialize=True)
    for own in range(n):
        box = ti.Vector([box_w, box_h], dt=real)
        i = sorted_ids[own]
        if ti.static(fresh):
            _merge_wall_event(i, pos, vel, radius, tau, ids, ev_t, ev_p, box, horizon, real, periodic)
        pairs_once(own, i, cell_of[i], forward, cell_start, sorted_ids, ncx, ncy, rows, segs, periodic, _pair_once,
                   (pos, vel, radius, tau, ids, ev_t, ev_p, box, horizon, real, periodic,
                    own_values(i, pos, vel, radius, tau)))


@ti.func
def _first_wall_event(i, pos: ti.template(), vel: ti.template(), radius: ti.template(), tau: ti.template(),
                      ids: ti.template(), ev_t: ti.template(), ev_p: ti.template(), box, horizon,
                      real: ti.template(), periodic: ti.template()):
    """Circle i's event set to its earliest wall hit up to the horizon, or none (a periodic box
    has no walls): the start of a prediction whose pairs are offered to both circles."""
    n = pos.shape[0]
    t = ti.cast(NEVER, real)
    p = NO_EVENT
    if ti.static(not periodic):
        t, lo, hi, p = _wall_events(i, pos, vel, radius, tau, ids, box, horizon, real, t, n + 8, n + 8, p)
    ev_t[i] = t
    ev_p[i] = p


@ti.func
def _merge_wall_event(i, pos: ti.template(), vel: ti.template(), radius: ti.template(), tau: ti.template(),
                      ids: ti.template(), ev_t: ti.template(), ev_p: ti.template(), box, horizon,
                      real: ti.template(), periodic: ti.template()):
    """Circle i's earliest wall hit up to the horizon taken as its event when it comes before
    the event it holds (`_first_wall_event` where the pairs offered so far are kept: the
    minimum of the keys does not depend on the order of the offers); none in a periodic box."""
    if ti.static(not periodic):
        n = pos.shape[0]
        t0, lo0, hi0 = event_key(i, ev_t, ev_p, ids, n)
        t, lo, hi, p = _wall_events(i, pos, vel, radius, tau, ids, box, horizon, real, t0, lo0, hi0, ev_p[i])
        if p != ev_p[i]:
            ev_t[i] = t
            ev_p[i] = p


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


@ti.func
def _predict(pos: ti.template(), vel: ti.template(), radius: ti.template(), tau: ti.template(), ids: ti.template(),
             ev_t: ti.template(), ev_p: ti.template(), dirty: ti.template(), moved: ti.template(),
             cell_of: ti.template(), cell_start: ti.template(), sorted_ids: ti.template(), ncx, ncy, rows, segs, box_w,
             box_h, t_end, scalars: ti.template(), real: ti.template(), periodic: ti.template(),
             earliest: ti.template(), clear_moved: ti.template()):
    """Each dirty circle finds its earliest event; with `earliest`, scalars[0] = the earliest
    event of all.

    A circle that moved in the last round (or at the start of a step: all did), or whose
    partner did, searches all its neighbours. Any other dirty circle keeps its event, which
    is the earliest over neighbours whose paths have not changed, and compares it only with
    its pairs with the circles that moved: the same minimum as a full search, with the same
    arithmetic per pair, for a fraction of the work.
    """
    scalars[0] = ti.cast(NEVER, real)
    n = pos.shape[0]
    horizon = ti.cast(t_end, real)
    for i in range(n):
        box = ti.Vector([box_w, box_h], dt=real)
        if dirty[i] != 0:
            dirty[i] = 0
            old_p = ev_p[i]
            full = moved[i] != 0 or (old_p >= 0 and moved[old_p] != 0)
            t_i, p_i, unused, unused2 = _earliest(i, full, pos, vel, radius, tau, ids, ev_t, ev_p, moved, cell_of,
                                                  cell_start, sorted_ids, ncx, ncy, rows, segs, box, horizon, real,
                                                  periodic, cell_start, sorted_ids, 1, 1, 1, 1, 0.0, 0.0, False, (),
                                                  0, 0, 0, 0, 0, 0.0, 1, 0, 0, ())
            ev_t[i] = t_i
            ev_p[i] = p_i
    if ti.static(clear_moved):
        for i in range(n):
            moved[i] = 0
    if ti.static(earliest):
        for i in range(n):
            if ev_t[i] < scalars[0]:
                # Reading first leaves only the few new minima to the (contended) atomic.
                ti.atomic_min(scalars[0], ev_t[i])


@ti.func
def mark_neighbours_dirty(i, dirty: ti.template(), cell_of: ti.template(), cell_start: ti.template(),
                          sorted_ids: ti.template(), ncx, ncy, rows, segs, periodic: ti.template()):
    c = cell_of[i]
    for row, seg in ti.ndrange(rows, segs):
        k_lo, k_hi = neighbour_range(c, row, seg, cell_start, ncx, ncy, periodic)
        for k in range(k_lo, k_hi):
            dirty[sorted_ids[k]] = 1


@ti.func
def _seed_bounds(ev_t: ti.template(), d: ti.template(), d_key: ti.template(), active: ti.template(),
                 cell_of: ti.template(), cell_start: ti.template(), sorted_ids: ti.template(), ncx, ncy, rows, segs,
                 t_end, real: ti.template(), periodic: ti.template()):
    """Start the bound sweeps of a round: D = t_end everywhere, with a key above every event's
    (`BOUND_KEY_NONE`), and active only near events.

    With every D at t_end, a neighbour l can lower D_k only if its own event comes by t_end
    (at t_end, its key lowers D_k's), so the first sweep needs to visit only the circles next
    to a circle with an event in the step; circles whose D falls later activate their own
    neighbours. The fixed point is the same as from an all-active start.
    """
    horizon = ti.cast(t_end, real)
    n = d.shape[0]
    for i in range(n):
        d[i] = horizon
        d_key[i, 0] = n + BOUND_KEY_NONE
        d_key[i, 1] = n + BOUND_KEY_NONE
    for i in range(n):
        if ev_t[i] <= horizon:  # events at the step's end too: their keys order them (a step cut there)
            mark_neighbours_dirty(i, active, cell_of, cell_start, sorted_ids, ncx, ncy, rows, segs, periodic)


@ti.func
def _bound_sweep(pos: ti.template(), vel: ti.template(), radius: ti.template(), tau: ti.template(),
                 ev_t: ti.template(), ev_p: ti.template(), ids: ti.template(), d: ti.template(),
                 d_key: ti.template(), active_in: ti.template(), active_out: ti.template(), cell_of: ti.template(),
                 cell_start: ti.template(), sorted_ids: ti.template(), ncx, ncy, rows, segs, box_w, box_h, t_end, vlim,
                 real: ti.template(), periodic: ti.template()):
    """One in-place sweep of D_k = min_l F_kl(min(t_l, D_l)) over the active circles; returns how many D decreased.

    F_kl(s) is the earliest time at which k, on its straight path, can meet l when l leaves
    its straight path at s: with T = max(s, tau_k, tau_l), g the straight-path gap at T and
    dv their relative velocity, contact needs g - |dv| (t - T) <= 2 vlim (t - s), so
    F = s + (g + |dv| (T - s)) / (|dv| + 2 vlim) >= s. F is monotone in s, so the sweeps
    decrease D towards the unique fixed point whatever the order of updates. A circle whose
    D decreased marks its neighbours active for the next sweep (`active_out`); nothing else
    can change, so the sweeps end when no circle is active.

    D carries a key (`d_key`), so that events at one instant run in the order of their keys,
    as from the queue. Where F = s (k touches l when l's path changes), the change could
    reach k at that very instant, and D_k takes the key of the event that starts it (l's
    own, or the one D_l carries): an event of k at that time runs only when its key is not
    above it (`execute`), so not before an event of lower key at that instant whose outcome
    could make another with k first (a Newton's cradle of unequal masses ran its collisions
    in another order than the queue). Where F > s, D_k takes the lowest key (`BOUND_KEY_LOW`):
    an event of k at exactly F waits for the next round. The bounds compare as (time, key).
    """
    n = pos.shape[0]
    two_v = ti.cast(2.0 * vlim, real)
    changed = 0
    for k in range(n):
        box = ti.Vector([box_w, box_h], dt=real)
        if active_in[k] == 0:
            continue
        active_in[k] = 0
        xk = pos[k]
        vk = vel[k]
        rk = radius[k]
        tk = tau[k]
        dk = d[k]
        dk_lo = d_key[k, 0]
        dk_hi = d_key[k, 1]
        c = cell_of[k]
        for row, seg in ti.ndrange(rows, segs):
            k_lo, k_hi = neighbour_range(c, row, seg, cell_start, ncx, ncy, periodic)
            for m in range(k_lo, k_hi):
                l = sorted_ids[m]
                s = ti.min(ev_t[l], d[l])
                if l != k and s <= dk:
                    t0 = ti.max(s, ti.max(tk, tau[l]))
                    dx = displacement(xk + vk * (t0 - tk), pos[l] + vel[l] * (t0 - tau[l]), box, periodic)
                    reach = rk + radius[l]
                    gap = dx.norm() - reach
                    if dx.dot(dx) - reach * reach <= 0:
                        gap = 0.0  # in contact as a time of impact reads it (`_time_of_impact`)
                    dv = (vel[l] - vk).norm()
                    # F = s + (gap + |dv| (t0 - s)) / (|dv| + 2 vlim) >= s: exactly s for circles in
                    # contact at s (the form (g + |dv| t0 + 2 vlim s) / (|dv| + 2 vlim) rounds above
                    # it), so that such a bound carries the key of the event at s.
                    arrival = s + (ti.max(gap, 0.0) + dv * (t0 - s)) / (dv + two_v)
                    s_lo = BOUND_KEY_LOW
                    s_hi = BOUND_KEY_LOW
                    if arrival == s:  # in contact (rare): s's key, l's event's or its bound's, the lower
                        s_lo, s_hi = _tie_ids(l, ev_p, ids, n)
                        if key_less(d[l], d_key[l, 0], d_key[l, 1], ev_t[l], s_lo, s_hi):
                            s_lo = d_key[l, 0]
                            s_hi = d_key[l, 1]
                    if key_less(arrival, s_lo, s_hi, dk, dk_lo, dk_hi):
                        dk = arrival
                        dk_lo = s_lo
                        dk_hi = s_hi
        if key_less(dk, dk_lo, dk_hi, d[k], d_key[k, 0], d_key[k, 1]):
            d[k] = dk
            d_key[k, 0] = dk_lo
            d_key[k, 1] = dk_hi
            changed += 1
            mark_neighbours_dirty(k, active_out, cell_of, cell_start, sorted_ids, ncx, ncy, rows, segs, periodic)
    return changed


@ti.func
def _sweeps(pos: ti.template(), vel: ti.template(), radius: ti.template(), tau: ti.template(), ev_t: ti.template(),
            ev_p: ti.template(), ids: ti.template(), d: ti.template(), d_key: ti.template(), active_a: ti.template(),
            active_b: ti.template(), cell_of: ti.template(), cell_start: ti.template(), sorted_ids: ti.template(),
            ncx, ncy, rows, segs, box_w, box_h, t_end, vlim, real: ti.template(), periodic: ti.template()):
    """SWEEPS_PER_LAUNCH sweeps (an even number, so the flags end in `active_a` again); returns how
    many D decreased in the last one. A sweep after one that changed nothing finds no active circle."""
    changed = 0
    for _ in ti.static(range(SWEEPS_PER_LAUNCH // 2)):
        _bound_sweep(pos, vel, radius, tau, ev_t, ev_p, ids, d, d_key, active_a, active_b, cell_of, cell_start,
                     sorted_ids, ncx, ncy, rows, segs, box_w, box_h, t_end, vlim, real, periodic)
        changed = _bound_sweep(pos, vel, radius, tau, ev_t, ev_p, ids, d, d_key, active_b, active_a, cell_of,
                               cell_start, sorted_ids, ncx, ncy, rows, segs, box_w, box_h, t_end, vlim, real, periodic)
    return changed


@launch.kernel
def begin_round(pos: ndarr, vel: ndarr, radius: ndarr, tau: ndarr, ids: ndarr, ev_t: ndarr, ev_p: ndarr,
                dirty: ndarr, moved: ndarr, d: ndarr, d_key: ti.types.ndarray(ndim=2), active_a: ndarr, active_b: ndarr, cell_of: ndarr, cell_start: ndarr,
                sorted_ids: ndarr, ncx: ti.i32, ncy: ti.i32, rows: ti.i32, segs: ti.i32, box_w: ti.f64,
                box_h: ti.f64, t_end: ti.f64, vlim: ti.f64, scalars: ndarr, real: ti.template(),
                periodic: ti.template()) -> ti.f64:
    """Predict, seed the bounds and run the first sweeps, in one launch (launches cost tens of
    microseconds each). Returns the earliest event time when the bounds have settled (no event
    in the step when it exceeds t_end), or -1 when more sweeps are needed."""
    _predict(pos, vel, radius, tau, ids, ev_t, ev_p, dirty, moved, cell_of, cell_start, sorted_ids, ncx, ncy, rows,
             segs, box_w, box_h, t_end, scalars, real, periodic, True, True)
    _seed_bounds(ev_t, d, d_key, active_a, cell_of, cell_start, sorted_ids, ncx, ncy, rows, segs, t_end, real,
                 periodic)
    changed = _sweeps(pos, vel, radius, tau, ev_t, ev_p, ids, d, d_key, active_a, active_b, cell_of, cell_start,
                      sorted_ids, ncx, ncy, rows, segs, box_w, box_h, t_end, vlim, real, periodic)
    result = ti.cast(scalars[0], ti.f64)
    if changed != 0:
        result = -1.0
    return result


@launch.kernel
def more_sweeps(pos: ndarr, vel: ndarr, radius: ndarr, tau: ndarr, ev_t: ndarr, ev_p: ndarr, ids: ndarr, d: ndarr,
                d_key: ti.types.ndarray(ndim=2), active_a: ndarr, active_b: ndarr, cell_of: ndarr, cell_start: ndarr,
                sorted_ids: ndarr, ncx: ti.i32, ncy: ti.i32, rows: ti.i32, segs: ti.i32, box_w: ti.f64, box_h: ti.f64,
                t_end: ti.f64, vlim: ti.f64, real: ti.template(), periodic: ti.template()) -> ti.i32:
    return _sweeps(pos, vel, radius, tau, ev_t, ev_p, ids, d, d_key, active_a, active_b, cell_of, cell_start,
                   sorted_ids, ncx, ncy, rows, segs, box_w, box_h, t_end, vlim, real, periodic)


@launch.kernel
def begin_step(pos: ndarr, vel: ndarr, pair_count: ndarr, wall_count: ndarr, virial: ndarr, wall_impulse: ndarr,
               pos_b: ndarr, vel_b: ndarr, pair_count_b: ndarr, wall_count_b: ndarr, virial_b: ndarr,
               wall_impulse_b: ndarr, dirty: ndarr, moved: ndarr, scalars: ndarr, real: ti.template(),
               serial: ti.template()):
    """Back up what a step changes (a cut step is redone from it), and mark every circle to predict
    in full; with `serial`, on one thread (see backend.serial_loops)."""
    ti.loop_config(serialize=serial)
    for i in range(pos.shape[0]):
        copy_state(i, (pos, vel, pair_count, wall_count, virial, wall_impulse),
                   (pos_b, vel_b, pair_count_b, wall_count_b, virial_b, wall_impulse_b))
        dirty[i] = 1
        moved[i] = 1
    scalars[0] = ti.cast(NEVER, real)
    scalars[1] = ti.cast(NEVER, real)


@ti.func
def copy_state(i, arrays: ti.template(), copies: ti.template()):
    """Circle i's entries of each array in `arrays` into the array at the same place in `copies`."""
    for a in ti.static(range(len(arrays))):
        copies[a][i] = arrays[a][i]


@ti.func
def _wall_event(i, e, p, pos: ti.template(), vel: ti.template(), radius: ti.template(), inv_mass: ti.template(),
                tau: ti.template(), sums: ti.template(), box):
    """Circle i meets wall -1 - p at time e: placed exactly in contact (no round-off escape
    through the wall), its normal velocity reversed, its wall sums updated (sums: (wall_count,
    wall_impulse, entry), see `_add_sums`)."""
    w = -1 - p
    axis = w // 2
    x = pos[i] + vel[i] * (e - tau[i])
    v = vel[i]
    r = radius[i]
    if w % 2 == 0:
        x[axis] = r
    else:
        x[axis] = box[axis] - r
    vn = v[axis]
    v[axis] = -vn
    pos[i] = x
    vel[i] = v
    tau[i] = e
    _add_sums(i, -1 - i, 2.0 * ti.abs(ti.cast(vn, ti.f64)) / ti.cast(inv_mass[i], ti.f64), sums)


@ti.func
def _add_sums(i, code, amount, sums: ti.template()):
    """One more event for circle i's count, and `amount` (float64) more for its sum. sums:
    (count, sum, entry): with entry (sum_i, sum_s, x), the parts' sum log (`queue_parts`), its
    entry x takes `code` (i for a pair's sums, -1 - i for a wall's) and the amount, added when
    the step is done (`apply_sums`); with any shorter entry, the arrays count and sum now."""
    entry = ti.static(sums[2])
    if ti.static(len(entry) == 3):
        entry[0][entry[2]] = code
        entry[1][entry[2]] = amount
    else:
        sums[0][i] = sums[0][i] + 1
        sums[1][i] = sums[1][i] + amount


@ti.func
def _pair_event(i, j, e, horizon, vlim2, pos: ti.template(), vel: ti.template(), radius: ti.template(),
                inv_mass: ti.template(), tau: ti.template(), ids: ti.template(), sums: ti.template(), box,
                periodic: ti.template()):
    """Circles i and j collide at time e: both brought to e, the impulse applied when they
    approach, the pair's sums (to the circle of lower creation id; sums: (pair_count, virial,
    entry), see `_add_sums`) updated. Returns 1 when the
    impulse was applied, 2 when they touch without approaching (brought to e only), and 0 with
    nothing changed when the impulse would make one faster than the grid allows (vlim2 its
    square) before the horizon: the step must end there (see the module docstring)."""
    xi = pos[i] + vel[i] * (e - tau[i])
    xj = pos[j] + vel[j] * (e - tau[j])
    d = displacement(xi, xj, box, periodic)
    vi = vel[i]
    vj = vel[j]
    # The impulse along d itself, per unit of d (J / |d|), not along d / |d|: at contact |d| is
    # nearly the same at every collision of a pair of radii, so the rounding of d / |d| has
    # nearly the same sign each time, and |n|^2 - 1 of about one unit in the last place, always
    # of that sign, changed the energy by about one unit in the last place at every collision,
    # always the same way (a drift that grew with the collisions: 7e-5 after 262 collisions a
    # circle in f32 at radius 0.5). Without the square root, what is left rounds either way.
    dd = d.dot(d)
    vd = (vj - vi).dot(d)
    wi = inv_mass[i]
    wj = inv_mass[j]
    status = 2
    if vd < 0:
        # Two quotients of numbers that vary from collision to collision, not one by the product
        # (wi + wj) dd, which is nearly the same at every collision of equal circles: its
        # rounding, nearly the same each time, would again change every collision's energy
        # the same way.
        jmp = (2.0 * vd / dd) / (wi + wj)
        # One expression for both circles, each with the normal towards its partner, so
        # the rounding (fused or not) does not depend on which circle is i.
        vi_new = vi + (wi * jmp) * d
        vj_new = vj + (wj * jmp) * (-d)
        if (vi_new.norm_sqr() > vlim2 or vj_new.norm_sqr() > vlim2) and e < horizon:
            status = 0
        else:
            status = 1
            vi = vi_new
            vj = vj_new
            # Plain updates, not atomics: a circle is in at most one executed pair at a time.
            owner = i if ids[i] < ids[j] else j
            # (r_i + r_j) |J| with |d| = r_i + r_j at contact: |J / |d|| d.d.
            _add_sums(owner, owner, ti.abs(ti.cast(jmp, ti.f64)) * ti.cast(dd, ti.f64), sums)
    if status != 0:
        pos[i] = xi
        pos[j] = xj
        vel[i] = vi
        vel[j] = vj
        tau[i] = e
        tau[j] = e
    return status


@ti.func
def _log(e, a, b, t_offset, counters: ti.template(), log_t: ti.template(), log_i: ti.template(),
         log_j: ti.template()):
    """Record an executed collision (time, a, b) when the log has room (counters[1] counts all)."""
    slot = ti.atomic_add(counters[1], 1)
    if slot < log_t.shape[0]:
        log_t[slot] = t_offset + ti.cast(e, ti.f64)
        log_i[slot] = a
        log_j[slot] = b


@launch.kernel
def execute(pos: ndarr, vel: ndarr, radius: ndarr, inv_mass: ndarr, tau: ndarr, ids: ndarr, ev_t: ndarr, ev_p: ndarr,
            bound_t: ndarr, bound_key: ti.types.ndarray(ndim=2), dirty: ndarr, moved: ndarr, pair_count: ndarr, wall_count: ndarr, virial: ndarr, wall_impulse: ndarr,
            cell_of: ndarr, cell_start: ndarr, sorted_ids: ndarr, ncx: ti.i32, ncy: ti.i32, rows: ti.i32, segs: ti.i32,
            box_w: ti.f64, box_h: ti.f64, t_end: ti.f64, vlim: ti.f64, t_offset: ti.f64, scalars: ndarr, counters: ndarr,
            log_t: ndarr, log_i: ndarr, log_j: ndarr,
            real: ti.template(), periodic: ti.template(), record: ti.template()) -> ti.i32:
    n = pos.shape[0]
    counters[0] = 0
    horizon = ti.cast(t_end, real)
    vlim2 = ti.cast(vlim, real) ** 2
    for i in range(n):
        box = ti.Vector([box_w, box_h], dt=real)
        e = ev_t[i]
        p = ev_p[i]
        lo, hi = _tie_ids(i, ev_p, ids, n)
        # At or before the bound, by (time, key): see `_bound_sweep`.
        if e <= horizon and not key_less(bound_t[i], bound_key[i, 0], bound_key[i, 1], e, lo, hi):
            if p < 0 and p != NO_EVENT:
                if ti.static(not periodic):
                    _wall_event(i, e, p, pos, vel, radius, inv_mass, tau, (wall_count, wall_impulse, ()), box)
                    moved[i] = 1
                    mark_neighbours_dirty(i, dirty, cell_of, cell_start, sorted_ids, ncx, ncy, rows, segs, periodic)
                    if counters[0] == 0:
                        counters[0] = 1  # progress flag: a plain store, written once
                    if ti.static(record):
                        _log(e, ids[i], p, t_offset, counters, log_t, log_i, log_j)
            elif p > i and ev_p[p] == i and ev_t[p] == e and not key_less(bound_t[p], bound_key[p, 0],
                                                                          bound_key[p, 1], e, lo, hi):
                j = p
                status = _pair_event(i, j, e, horizon, vlim2, pos, vel, radius, inv_mass, tau, ids,
                                     (pair_count, virial, ()), box, periodic)
                if status == 0:
                    ti.atomic_min(scalars[1], e)  # the step is cut here
                else:
                    if ti.static(record):
                        if status == 1:
                            _log(e, ti.min(ids[i], ids[j]), ti.max(ids[i], ids[j]), t_offset, counters, log_t,
                                 log_i, log_j)
                    moved[i] = 1
                    moved[j] = 1
                    mark_neighbours_dirty(i, dirty, cell_of, cell_start, sorted_ids, ncx, ncy, rows, segs, periodic)
                    mark_neighbours_dirty(j, dirty, cell_of, cell_start, sorted_ids, ncx, ncy, rows, segs, periodic)
                    if counters[0] == 0:
                        counters[0] = 1  # progress flag: a plain store, written once
    result = counters[0]
    if scalars[1] < horizon:
        result = -1  # a collision would outrun the grid: the step is cut at scalars[1]
    return result


# ------------------------------------------------------------------ one queue (CPU)
#
# On a CPU a step can run its events one at a time from a queue instead: one full prediction
# (in parallel), then the earliest event of all, always safe, executed and its neighbourhood
# predicted again, until none is left before the step's end. The events, their order and the
# arithmetic of each are those of the rounds (independent events touch disjoint circles and
# commute bit for bit), so the state is the same bit for bit; what goes is the rounds' cost:
# the bound sweeps, and every round's passes over all circles. A GPU runs the rounds.
#
# After an event only pairs with its circles changed. Their own searches compute each of those
# pairs once and offer it to the neighbour (`_earliest` with a queue); only a neighbour whose
# event was with one of them searches again in full.
#
# The queue is a calendar of buckets with a small heap in front: the step [0, t_end] is cut
# into `nb` buckets of equal width, each a doubly linked list of the circles whose event falls
# in it, in no order; the heap holds the events of the buckets already reached (the current
# one and any event that came back into it), ordered by key. Taking the earliest event takes
# the heap's top; when the heap runs empty, the next bucket's list is poured into it. A bucket
# holds a few events, so the heap stays small enough to live in the cache and a changed event
# costs a few stores, where one heap of every event would take a cache miss at each of its
# twenty levels at 1e6. The order is the keys' order, the same as one heap's.

#: Circles per bucket of the queue's calendar (see above).
QUEUE_BUCKET_CIRCLES = 4
#: A step that executes more events than this per circle (the queue: at most 2**30 in all) stops
#: with an error, on the queue and in the rounds: circles jammed in a chain across the box
#: collide without end at one instant. Every step may execute MOST_EVENTS_ANY_STEP, so that a few
#: circles can make many collisions of their own in a step (a circle 1e10 times as heavy as a light
#: one pressing it against a wall makes 314159).
MOST_EVENTS_PER_CIRCLE = 10_000
MOST_EVENTS_ANY_STEP = 1_000_000


def most_events(n):
    """The events a step of n circles may execute before it stops as jammed (see above)."""
    return min(max(n * MOST_EVENTS_PER_CIRCLE, MOST_EVENTS_ANY_STEP), 1 << 30)
#: head[b] of a bucket already poured into the heap: its events go to the heap directly.
POURED = -2


@ti.func
def _before(x, t, y, u, ev_p: ti.template(), ids: ti.template(), n):
    """Whether circle x's event, at time t, comes before circle y's, at u, by the key of
    `event_key`; the ids are read only for equal times (the two circles of a pair, mostly)."""
    less = t < u
    if t == u:
        xl, xh = _tie_ids(x, ev_p, ids, n)
        yl, yh = _tie_ids(y, ev_p, ids, n)
        less = key_less(t, xl, xh, u, yl, yh)
    return less


@ti.func
def _heap_put(k, x, t, heap: ti.template(), where: ti.template(), heap_t: ti.template(), off):
    """Circle x, whose event is at time t, into heap slot k (of the heap from `off`)."""
    heap[off + k] = x
    heap_t[off + k] = t
    where[x] = k


@ti.func
def _sift_up(k, heap: ti.template(), where: ti.template(), heap_t: ti.template(), ev_p: ti.template(),
             ids: ti.template(), n, off):
    """Move the event in heap slot k up to its place; returns its new slot. The parents it passes
    move down one level each, and it is written once, at its place (a hole moves up, not a
    swapped pair: half the stores)."""
    x = heap[off + k]
    t = heap_t[off + k]
    while k > 0:
        parent = (k - 1) // 2
        y = heap[off + parent]
        if _before(x, t, y, heap_t[off + parent], ev_p, ids, n):
            _heap_put(k, y, heap_t[off + parent], heap, where, heap_t, off)
            k = parent
        else:
            break
    _heap_put(k, x, t, heap, where, heap_t, off)
    return k


@ti.func
def _sift_down(k, size, heap: ti.template(), where: ti.template(), heap_t: ti.template(), ev_p: ti.template(),
               ids: ti.template(), n, off):
    """Move the event in heap slot k down to its place, the earlier of its two children moving
    up each level (the hole of `_sift_up`, downwards)."""
    x = heap[off + k]
    t = heap_t[off + k]
    while 2 * k + 1 < size:
        m = 2 * k + 1
        if m + 1 < size and _before(heap[off + m + 1], heap_t[off + m + 1], heap[off + m], heap_t[off + m], ev_p,
                                    ids, n):
            m += 1
        y = heap[off + m]
        if _before(y, heap_t[off + m], x, t, ev_p, ids, n):
            _heap_put(k, y, heap_t[off + m], heap, where, heap_t, off)
            k = m
        else:
            break
    _heap_put(k, x, t, heap, where, heap_t, off)


@ti.func
def _bucket(t, scale, nb):
    """The calendar bucket of time t in [0, t_end] (scale = nb / t_end, float64, at most 1e30):
    monotone in t, so the buckets' order agrees with the times'. In float64 and clamped before
    the conversion, so that a step of 1e-36 (nb / t_end past float32's range, times 0 at a
    touch) still gives a bucket in range."""
    return ti.cast(ti.min(ti.max(ti.cast(t, ti.f64) * scale, 0.0), ti.cast(nb - 1, ti.f64)), ti.i32)


@ti.func
def _queue_put(x, size, scale, nb, q: ti.template(), ev_t: ti.template(), ev_p: ti.template(), ids: ti.template(),
               n, off, hb):
    """Circle x, which has an event and is not in the queue, into it: into the heap when its
    bucket was poured, else at the front of its bucket's list. Returns the heap's size.
    q: (heap, where, heap_t, head, nxt, prv, pending); the queue's heap starts at slot `off` of
    its arrays and its nb buckets at `hb` of `head` (one queue of several, `queue_parts`)."""
    t = ev_t[x]
    b = _bucket(t, scale, nb)
    first = q[3][hb + b]
    if first == POURED:
        q[0][off + size] = x
        q[2][off + size] = t
        _sift_up(size, q[0], q[1], q[2], ev_p, ids, n, off)
        size += 1
    else:
        q[4][x] = first
        q[5][x] = -1
        if first >= 0:
            q[5][first] = x
        q[3][hb + b] = x
        q[1][x] = -2 - b
    return size


@ti.func
def _queue_fix(x, size, scale, nb, q: ti.template(), ev_t: ti.template(), ev_p: ti.template(), ids: ti.template(),
               n, off, hb):
    """Put circle x where its (changed) event belongs in the queue, which holds each circle with
    an event once: in it when it has an event, out of it when not. Returns the heap's size."""
    k = q[1][x]
    has = ev_p[x] != NO_EVENT
    b = -1
    if has:
        b = _bucket(ev_t[x], scale, nb)
    if k >= 0:  # in the heap
        if has and q[3][hb + b] == POURED:  # stays there, moved to its place
            q[2][off + k] = ev_t[x]
            k = _sift_up(k, q[0], q[1], q[2], ev_p, ids, n, off)
            _sift_down(k, size, q[0], q[1], q[2], ev_p, ids, n, off)
        else:
            size -= 1
            q[1][x] = -1
            if k < size:  # the last event fills the hole
                q[0][off + k] = q[0][off + size]
                q[2][off + k] = q[2][off + size]
                k = _sift_up(k, q[0], q[1], q[2], ev_p, ids, n, off)
                _sift_down(k, size, q[0], q[1], q[2], ev_p, ids, n, off)
            if has:
                size = _queue_put(x, size, scale, nb, q, ev_t, ev_p, ids, n, off, hb)
    elif k <= -2:  # in bucket -2 - k's list
        old = -2 - k
        if b != old:
            nx = q[4][x]
            pv = q[5][x]
            if pv >= 0:
                q[4][pv] = nx
            else:
                q[3][hb + old] = nx
            if nx >= 0:
                q[5][nx] = pv
            q[1][x] = -1
            if has:
                size = _queue_put(x, size, scale, nb, q, ev_t, ev_p, ids, n, off, hb)
    elif has:
        size = _queue_put(x, size, scale, nb, q, ev_t, ev_p, ids, n, off, hb)
    return size


@ti.func
def _drain(size, horizon, until, reached, most, scale, nb, off, hb, queue: ti.template(), state: ti.template(),
           sums: ti.template(), grid: ti.template(), log: ti.template(), ncx, ncy, rows, segs, ncx_c, ncy_c, mx, my,
           r_cut, margin, t_offset, box, vlim2, real: ti.template(), periodic: ti.template(), record: ti.template(),
           two_level: ti.template(), part: ti.template(), log_sums: ti.template()):
    """Execute a filled queue's events in key order up to `horizon` (see above), each followed
    by the searches it calls for; returns (reached, horizon): as `queue_step` returns, and the
    step's end, moved to the time of a collision that would outrun the grid. state: (pos, vel,
    radius, inv_mass, tau, ids, ev_t, ev_p, stamp); sums: (pair_count, virial, wall_count,
    wall_impulse); grid: (cell_of, cell_start, sorted_ids, coarse_start, coarse_ids); log:
    (counters, log_t, log_i, log_j); `most`: the events allowed; off, hb, part: see `_earliest`;
    log_sums: () or (sum_i, sum_s, sum_at, chunk), the log to which each event writes what it
    adds to the counts and sums instead (`_add_sums`, one entry an event, taken before it); when
    the log is full the queue stops before the event, and returns reached = -3. Events after
    `until` (at most the horizon) are left in the queue."""
    pos, vel, radius, inv_mass, tau, ids, ev_t, ev_p, stamp = ti.static(state)
    heap, where, heap_t, head, nxt, prv, pending = ti.static(queue)
    n = pos.shape[0]
    cur = -1  # the last bucket poured into the heap
    executed = 0
    u_at = 0  # the sum log's next entry and the end of the chunk it is in
    u_end = 0
    x_sum = 0  # the event's entry
    while True:
        while size == 0 and cur < nb - 1:
            cur += 1
            x = head[hb + cur]
            head[hb + cur] = POURED
            while x >= 0:
                _heap_put(size, x, ev_t[x], heap, where, heap_t, off)
                size += 1
                x = nxt[x]
            k = size // 2 - 1
            while k >= 0:
                _sift_down(k, size, heap, where, heap_t, ev_p, ids, n, off)
                k -= 1
        if size == 0:
            break
        c = heap[off]
        e = ev_t[c]
        if e > horizon or e > until:
            break  # the queue holds events up to the end the step had before it was cut
        p = ev_p[c]
        changed = 1
        if ti.static(len(log_sums) > 0):
            if u_at == u_end:
                u_at = ti.atomic_add(log_sums[2][0], log_sums[3])
                u_end = u_at + log_sums[3]
                if u_end > log_sums[0].shape[0]:
                    reached = -3.0
                    break
            x_sum = u_at
            u_at += 1
            log_sums[0][x_sum] = -1 - n  # no sums, unless the event writes them
        # Where the event adds to its sums (`_add_sums`): the log's entry x_sum, or the arrays.
        entry = ti.static(log_sums[0:2] + (x_sum,))  # (sum_i, sum_s, x_sum), or (x_sum,): no log
        if p >= 0:
            if ev_p[p] != c or ev_t[p] != e:
                reached = -1.0
                break
            status = _pair_event(c, p, e, horizon, vlim2, pos, vel, radius, inv_mass, tau, ids,
                                 (sums[0], sums[1], entry), box, periodic)
            if status == 0:
                # It would outrun the grid: the step ends at e, which it executes (e is not
                # before the new end). Later predictions look no further than e.
                horizon = e
                reached = ti.cast(e, ti.f64)
                status = _pair_event(c, p, e, horizon, vlim2, pos, vel, radius, inv_mass, tau, ids,
                                     (sums[0], sums[1], entry), box, periodic)
            if ti.static(record):
                if status == 1:
                    _log(e, ti.min(ids[c], ids[p]), ti.max(ids[c], ids[p]), t_offset, log[0], log[1], log[2],
                         log[3])
            changed = 2
        else:
            if ti.static(not periodic):
                _wall_event(c, e, p, pos, vel, radius, inv_mass, tau, (sums[2], sums[3], entry), box)
                if ti.static(record):
                    _log(e, ids[c], p, t_offset, log[0], log[1], log[2], log[3])
        executed += 1
        if executed > most:
            reached = -2.0
            break
        # Only pairs with c (and p) changed. Stamps of this event: `base` for a neighbour
        # that keeps its event unless a pair with c or p comes first, base + 1 for c and p and
        # for a neighbour whose event was with c or p (it searches again in full).
        base = 2 * executed
        stamp[c] = base + 1
        other = -(1 << 30)  # no partner is this
        if changed == 2:
            stamp[p] = base + 1
            other = p
        # The searches of c, p, then of the neighbours listed as having had their event with
        # c or p; c's and p's stamp their neighbours and offer each pair to them.
        subjects = changed
        m = 0
        while m < subjects:
            y = c
            code = base
            if m == 1 and changed == 2:
                y = p
            elif m >= changed:
                y = pending[off + m - changed]
                code = -1  # a full search, as c's and p's, without offers
            ev_t[y], ev_p[y], size, more = _earliest(y, True, pos, vel, radius, tau, ids, ev_t, ev_p, stamp, grid[0],
                                                     grid[1], grid[2], ncx, ncy, rows, segs, box, horizon, real,
                                                     periodic, grid[3], grid[4], ncx_c, ncy_c, mx, my, r_cut, margin,
                                                     two_level, queue, code, size, c, other,
                                                     off + subjects - changed, scale, nb, off, hb, part)
            subjects += more
            size = _queue_fix(y, size, scale, nb, queue, ev_t, ev_p, ids, n, off, hb)
            m += 1
    if ti.static(len(log_sums) > 0):
        for x in range(u_at, ti.min(u_end, log_sums[0].shape[0])):
            log_sums[0][x] = -1 - n  # the chunk's entries left empty
    return reached, horizon


@launch.kernel
def apply_sums(sum_i: ndarr, sum_s: ndarr, sum_at: ndarr, pair_count: ndarr, virial: ndarr, wall_count: ndarr,
               wall_impulse: ndarr):
    """What the events of a step in parts wrote to the sum log (`queue_parts`) added to the
    circles' counts and sums: an entry k >= 0 adds one pair to circle k's count and its amount
    to its virial, an entry -1 - k (k < n) one wall hit and its impulse to circle k's; an entry
    below -n is empty. Each thread takes a range of the circles and reads the whole log in
    order: a circle's entries lie in the order of its events (the parts of a window take chunks
    of the log in turn, and the windows run in turn), so its sums are the same numbers, bit for
    bit, as when each event added to them."""
    n = pair_count.shape[0]
    threads = ti.static(max(count_parts(), 1))
    for it in range(threads * PART_ITERATIONS):
        if it % PART_ITERATIONS == 0:
            lo, hi = _part_range(n, it // PART_ITERATIONS, threads)
            for x in range(ti.min(sum_at[0], sum_i.shape[0])):
                e = sum_i[x]
                i = ti.select(e >= 0, e, -1 - e)
                if lo <= i and i < hi:
                    if e >= 0:
                        pair_count[i] = pair_count[i] + 1
                        virial[i] = virial[i] + sum_s[x]
                    else:
                        wall_count[i] = wall_count[i] + 1
                        wall_impulse[i] = wall_impulse[i] + sum_s[x]


@ti.func
def _first_predictions(pos: ti.template(), vel: ti.template(), radius: ti.template(), tau: ti.template(),
                       ids: ti.template(), ev_t: ti.template(), ev_p: ti.template(), stamp: ti.template(),
                       cell_of: ti.template(), cell_start: ti.template(), sorted_ids: ti.template(), ncx, ncy, rows,
                       segs, box_w, box_h, horizon, coarse_start: ti.template(), coarse_ids: ti.template(), ncx_c,
                       ncy_c, mx, my, r_cut, margin, real: ti.template(), periodic: ti.template(),
                       two_level: ti.template(), serial: ti.template(), fresh: ti.template()):
    """Every circle's earliest event of the step (`queue_step`), from the clocks `tau` (or
    `STEP_START`): on one thread each pair computed once (`_first_events_once`, one grid level;
    `fresh`: see there), else each circle's search in full."""
    n = pos.shape[0]
    if ti.static(serial and not two_level):
        _first_events_once(pos, vel, radius, tau, ids, ev_t, ev_p, cell_of, cell_start, sorted_ids, ncx, ncy, rows,
                           segs, box_w, box_h, horizon, real, periodic, fresh)
    else:
        ti.loop_config(serialize=serial)
        for i in range(n):
            box = ti.Vector([box_w, box_h], dt=real)
            t_i, p_i, unused, unused2 = _earliest(i, True, pos, vel, radius, tau, ids, ev_t, ev_p, stamp, cell_of,
                                                  cell_start, sorted_ids, ncx, ncy, rows, segs, box, horizon, real,
                                                  periodic, coarse_start, coarse_ids, ncx_c, ncy_c, mx, my, r_cut,
                                                  margin, two_level, (), 0, 0, 0, 0, 0, 0.0, 1, 0, 0, ())
            ev_t[i] = t_i
            ev_p[i] = p_i


@launch.kernel
def queue_step(pos: ndarr, vel: ndarr, radius: ndarr, inv_mass: ndarr, tau: ndarr, ids: ndarr, ev_t: ndarr,
               ev_p: ndarr, stamp: ndarr, heap: ndarr, where: ndarr, heap_t: ndarr, head: ndarr, nxt: ndarr,
               prv: ndarr, pending: ndarr, pair_count: ndarr, wall_count: ndarr,
               virial: ndarr, wall_impulse: ndarr, cell_of: ndarr, cell_start: ndarr, sorted_ids: ndarr, ncx: ti.i32,
               ncy: ti.i32, rows: ti.i32, segs: ti.i32, box_w: ti.f64, box_h: ti.f64, t_end: ti.f64, vlim: ti.f64,
               t_offset: ti.f64, counters: ndarr, log_t: ndarr, log_i: ndarr, log_j: ndarr, speed_out: ndarr,
               coarse_start: ndarr, coarse_ids: ndarr, ncx_c: ti.i32, ncy_c: ti.i32, mx: ti.i32, my: ti.i32,
               r_cut: ti.f64, margin: ti.f64, most: ti.i32, per_bucket: ti.i32, r_same: ti.f64, w_same: ti.f64,
               real: ti.template(), periodic: ti.template(), record: ti.template(), two_level: ti.template(),
               serial: ti.template(), at_start: ti.template(), same: ti.template()) -> ti.f64:
    """A whole step from one queue (see above), every circle moved to its end at the last
    (`finish`, in the same launch). Returns the time the step reached: t_end, or the time of a
    collision that would outrun the grid, where the step ends (see the module's docstring);
    -1 when the earliest event is not its partner's (an internal error); -2 when the step
    executed more than `most` events (`most_events`: jammed circles). The finish
    leaves the largest speed of the state in speed_out (as `reductions.speed_result` reads it).

    `two_level`: the grid's cells are sized for the small circles and the large ones are also
    listed in coarse cells (`build_coarse`, `_runs`); circles with radius above r_cut are
    large, and `margin` is the most two circles can close in on each other in the step. With
    `serial`, the first predictions too run on one thread (see backend.serial_loops), each pair's
    time computed once (`_first_events_once`, one grid level). `at_start`: every circle's clock
    is 0, as at a step's start, and the first predictions read none (`STEP_START`); and, with
    `serial`, every circle holds no event, as this kernel's finish leaves it on one thread (and
    the set-up), so that the circles take their walls in the pairs' pass (`_first_events_once`
    with `fresh`). A simulation whose loops run on one thread steps only here. With `same`,
    every circle's radius and inverse mass are r_same and w_same (`Same`)."""
    n = pos.shape[0]
    rad, wmass = ti.static((Same(ti.cast(r_same, real)), Same(ti.cast(w_same, real))) if same else
                           (radius, inv_mass))
    horizon = ti.cast(t_end, real)
    vlim2 = ti.cast(vlim, real) ** 2
    reached = t_end
    if ti.static(at_start):
        _first_predictions(pos, vel, rad, STEP_START, ids, ev_t, ev_p, stamp, cell_of, cell_start, sorted_ids, ncx,
                           ncy, rows, segs, box_w, box_h, horizon, coarse_start, coarse_ids, ncx_c, ncy_c, mx, my,
                           r_cut, margin, real, periodic, two_level, serial, True)
    else:
        _first_predictions(pos, vel, rad, tau, ids, ev_t, ev_p, stamp, cell_of, cell_start, sorted_ids, ncx, ncy,
                           rows, segs, box_w, box_h, horizon, coarse_start, coarse_ids, ncx_c, ncy_c, mx, my, r_cut,
                           margin, real, periodic, two_level, serial, False)
    # Buckets: one per `per_bucket` circles (QUEUE_BUCKET_CIRCLES when the head array was made),
    # and at most n, so that the loop below resets every one (the parts' calendars, which share
    # the array, take more of it).
    nb = ti.min(head.shape[0], ti.max(n // per_bucket, 1))
    scale = ti.min(nb / t_end, 1e30)  # float64 (see `_bucket`)
    ti.loop_config(serialize=serial)
    for i in range(n):
        where[i] = -1
        stamp[i] = 0
        if i < nb:
            head[i] = -1
    queue = ti.static((heap, where, heap_t, head, nxt, prv, pending))
    ti.loop_config(serialize=True)
    for _ in range(1):
        box = ti.Vector([box_w, box_h], dt=real)
        size = 0  # of the heap; every bucket is still a list
        for i in range(n):
            if ev_p[i] != NO_EVENT:
                size = _queue_put(i, size, scale, nb, queue, ev_t, ev_p, ids, n, 0, 0)
        reached, horizon = _drain(size, horizon, horizon, reached, most, scale, nb, 0, 0, queue,
                                  (pos, vel, rad, wmass, tau, ids, ev_t, ev_p, stamp),
                                  (pair_count, virial, wall_count, wall_impulse),
                                  (cell_of, cell_start, sorted_ids, coarse_start, coarse_ids),
                                  (counters, log_t, log_i, log_j), ncx, ncy, rows, segs, ncx_c, ncy_c, mx, my, r_cut,
                                  margin, t_offset, box, vlim2, real, periodic, record, two_level, (), ())
    # A top-level loop (one inside a branch would run on one thread); the largest speed of the
    # state it leaves in speed_out, and on one thread no event held (`_finish`), for the next step.
    _finish(pos, vel, tau, horizon, box_w, box_h, real, periodic, serial, speed_out, True,
            (ev_t, ev_p) if ti.static(serial) else ())
    return reached


# ------------------------------------------------------------------ parts (CPU, several threads)
#
# No circle moves faster than vlim within a step, so none travels farther than vlim W in a
# window [t0, t1] of it (W = t1 - t0). Most travel much less: until its first collision a
# circle keeps its own speed s, and that collision cannot come before its nearest neighbour,
# at a gap g at t0, could close in at vlim: not before t0 + f, f = g / (s + vlim). So circle i
# travels at most its reach R_i = s f + vlim (W - f), with f at most W (`_reach_of`), and two
# circles can meet within the window only if at t0 they are within the sum of their radii and
# of their reaches of each other. The nearest circle is looked for in the 3 x 3 cells: the
# cells are at least 2 rmax + 2 vlim h wide (h the step), and no circle has moved more than
# vlim t0 since they were built, so a circle beyond them is at a gap of at least
# 2 vlim (h - t0) >= 2 vlim W, for which f is W anyway. Call such circles linked. In the
# bench scene at 1e6 the reaches are about half vlim W on average, and the clusters across
# the borders of a split hold 4.5 times fewer circles than with 2 vlim W for every pair
# (22000 to 27000 circles against 83000 to 130000 at each split, windows of half a step). A
# set of circles closed under links (a cluster and its like) evolves through the window on
# its own: no event outside it touches its circles or changes a time
# of impact that comes due in the window. `split_parts` cuts the box into strips of rows of
# cells and gives each strip's circles a part, except that every cluster that crosses the
# border between two strips goes whole to the lower one (in a periodic box the border
# between the last strip and the first is the last one's). `queue_parts` then runs one queue
# per part, the threads taking parts in turn: the events of the window in the same order with
# the same arithmetic as one queue for all (events of different parts touch disjoint circles
# and commute), and a part's arrays are a fraction of the whole (tens of thousands of circles)
# while its events run, so they are mostly in the cache.
#
# Over a whole step the clusters can span the box (at the bench's density and step, with 2 vlim
# W for every pair, links reach 1.7 diameters and the clusters across borders hold 92% of 1e6
# circles; with the reaches, the clusters of a whole step still span the box): the step runs
# in windows, each split anew (see `Simulation._queue_parts_step`). A part's searches meet
# only its own circles, so a circle's event past the window can miss a pair with another
# part: a search that meets a neighbour in another part flags the circle (`_earliest`,
# `_pair_in_part`), and before the next window the flagged circles search again over all
# their neighbours (`repredict`). A collision that would outrun the grid ends the step at its
# time for every circle, but the other parts may have gone past it: every circle is put back
# to the step's start and the step runs again up to that time. Each part copies its circles'
# positions and velocities as its first window begins, while they are in the cache for their
# first predictions. Such steps are rare once the speeds have spread from their start (the
# speed limit has a margin, simulation.SPEED_MARGIN). The counts and sums (pair_count, virial,
# wall_count, wall_impulse), which only an event's one or two circles change, are not changed
# in the step at all: each event writes what it adds to them to a sum log, in chunks each part
# takes in turn, and `apply_sums` adds the log once the step is done, so a redone step only
# drops it. An event then touches no line of the sums, which no search reads: their first load
# in an event was its costliest miss (about 9% of the samples of a step at 1e6, `perf`). A
# whole copy of the sums at each step's start, one pass over 24 more bytes a circle, cost
# about 5% of a step at 1e6; a copy of each circle at its first change in the step, about 8%
# (bench/PERFORMANCE.md).

#: Circles per part (`split_parts`): enough for the borders' clusters to be a small share, few
#: enough that a part's arrays mostly stay in the cache.
PART_CIRCLES = 65536
#: Rows of cells per part at least (a cluster that crosses a border reaches a row or two in).
PART_MIN_ROWS = 4
#: Parts at most.
MOST_PARTS = 1024
def part_info_size(parts: int) -> int:
    """Entries of `split_parts`' info array for `parts` parts: part k's first slot in the
    queues' arrays (info[k], k <= parts, info[parts] = n), the start and end of its claimed
    circles in `claimed` (at parts + 1 + k and 2 parts + 1 + k), the threads' counter of borders
    or parts taken (at 3 parts + 1) and whether the split holds (at 3 parts + 2)."""
    return 3 * parts + 3


@ti.func
def _place_at(x, t, pos: ti.template(), vel: ti.template(), tau: ti.template()):
    """Where circle x is at time t (after its clock tau), in float64."""
    return ti.cast(pos[x], ti.f64) + ti.cast(vel[x], ti.f64) * (t - ti.cast(tau[x], ti.f64))


@ti.func
def _reach_of(i, xi, t, box, pos: ti.template(), vel: ti.template(), tau: ti.template(), radius: ti.template(),
              links: ti.template(), periodic: ti.template()):
    """How far circle i, at xi at time t, can travel in the window from t (float64, see above;
    with the 1% allowance). links: (window, vlim, reach, cell_of, cell_start, sorted_ids, ncx,
    ncy, rows, segs, allowance); the value is computed at its first use in a split and kept in
    reach[i], rounded up to reach's precision (below 0: not computed yet)."""
    window, vlim, reach, cell_of, cell_start, sorted_ids, ncx, ncy, rows, segs, unused = ti.static(links)
    d_i = ti.cast(reach[i], ti.f64)
    if d_i < 0:
        ri = ti.cast(radius[i], ti.f64)
        # Beyond i's 3 x 3 cells a circle is too far to meet i in the window: the gap to it is
        # at least 2 vlim window, and `free` below comes out as the window.
        gap = ti.cast(NEVER, ti.f64)
        for r in range(rows * segs):
            row, seg = run_parts(r, segs, periodic)
            k_lo, k_hi = neighbour_range(cell_of[i], row, seg, cell_start, ncx, ncy, periodic)
            for k in range(k_lo, k_hi):
                j = sorted_ids[k]
                if j != i:
                    d = displacement(xi, _place_at(j, t, pos, vel, tau), box, periodic)
                    gap = ti.min(gap, d.norm() - ri - ti.cast(radius[j], ti.f64))
        speed = ti.cast(vel[i], ti.f64).norm()
        # No pair event of i before t + free: a neighbour closes in at vlim at most.
        free = ti.min(ti.max(gap, 0.0) / (speed + vlim), window)
        d_i = (speed * free + vlim * (window - free)) * 1.01
        # Stored from a value a little above, rounded to nearest in float32 or float64: not
        # below d_i; read back, so that its first use takes the value its later ones read.
        reach[i] = d_i * (1.0 + 2.0 ** -20)
        d_i = ti.cast(reach[i], ti.f64)
    return d_i


@ti.func
def _linked(xp, rx, j, t, box, pos: ti.template(), vel: ti.template(), tau: ti.template(), radius: ti.template(),
            links: ti.template(), periodic: ti.template()):
    """Whether circle j at time t lies within rx + its radius + its reach (`_reach_of`) of xp
    (float64; the nearest image in a periodic box). No circle's stored reach is above 1.02
    vlim times the window (1.01 with the allowance, the rounding up of the store and a speed
    over vlim by round-off inside): that is tested first, and most pairs fail it, so their
    second circle's reach is not computed."""
    xj = _place_at(j, t, pos, vel, tau)
    d = displacement(xp, xj, box, periodic)
    d2 = d.dot(d)
    q = rx + ti.cast(radius[j], ti.f64)
    linked = False
    if d2 < (q + 1.02 * links[1] * links[0]) ** 2:
        q += _reach_of(j, xj, t, box, pos, vel, tau, radius, links, periodic)
        linked = d2 < q * q
    return linked


@ti.func
def _link_origin(x, t, box, pos: ti.template(), vel: ti.template(), tau: ti.template(), radius: ti.template(),
                 links: ti.template(), periodic: ti.template()):
    """(xp, rx): circle x's place at time t, and its radius, reach and the split's allowance
    (links[10]), for `_linked` to test its neighbours against."""
    xp = _place_at(x, t, pos, vel, tau)
    rx = ti.cast(radius[x], ti.f64) + _reach_of(x, xp, t, box, pos, vel, tau, radius, links, periodic) + links[10]
    return xp, rx


@ti.func
def _row_start(y, ncx, periodic: ti.template()):
    """The first cell of row y of the grid (`geometry.cell_index`; a walled grid's rows begin
    with an empty frame cell, below row 0 lies an empty row)."""
    c = y * ncx
    if ti.static(not periodic):
        c = (y + 1) * (ncx + 1)
    return c


@ti.func
def _strip_slots(k, rows_per, parts, ncx, ncy, cell_start: ti.template(), periodic: ti.template()):
    """Slots [lo, hi) of `sorted_ids` that hold the circles of strip k (its rows of cells, the
    last strip's up to the top row)."""
    y1 = ti.select(k == parts - 1, ncy, (k + 1) * rows_per)
    return cell_start[_row_start(k * rows_per, ncx, periodic)], cell_start[_row_start(y1, ncx, periodic)]


@ti.func
def _strip_of(c, ncx, rows_per, parts, periodic: ti.template()):
    """The strip of rows_per rows of cells that holds cell c (`split_parts`). By products with
    reciprocals, not integer divisions (tens of cycles each): (c + 1/2) / (cells per row) and
    (cy + 1/2) / rows_per have fractional parts of at least half their divisor's reciprocal,
    far above float64's rounding."""
    stride = ncx
    if ti.static(not periodic):
        stride = ncx + 1
    cy = ti.cast((ti.cast(c, ti.f64) + 0.5) * (1.0 / stride), ti.i32)
    if ti.static(not periodic):
        cy -= 1
    return ti.min(ti.cast((cy + 0.5) * (1.0 / rows_per), ti.i32), parts - 1)


@ti.func
def _claim_cluster(i, s, b, t, lo, hi, box, pos: ti.template(), vel: ti.template(), tau: ti.template(),
                   radius: ti.template(), label: ti.template(), claimed: ti.template(), cell_of: ti.template(),
                   cell_start: ti.template(), sorted_ids: ti.template(), ncx, ncy, rows, segs, links: ti.template(),
                   periodic: ti.template()):
    """Claim for border b the cluster of circle i (in slot s): every circle linked to a claimed
    one, breadth first, each labelled -1 - b with an atomic minimum and its slot listed in
    claimed[lo:hi]. Returns the end of the list, or -1 when it runs out of room or meets a
    circle that another border claimed (a cluster across two borders)."""
    top = lo
    # Within the border's share: past it lies the next border's list (or the array's end).
    if ti.atomic_min(label[i], -1 - b) >= 0 and top < hi:
        claimed[top] = s
        top += 1
    else:
        top = -1
    m = lo
    while 0 <= m and m < top:
        x = sorted_ids[claimed[m]]
        m += 1
        xp, rx = _link_origin(x, t, box, pos, vel, tau, radius, links, periodic)
        for r in range(rows * segs):
            row, seg = run_parts(r, segs, periodic)
            k_lo, k_hi = neighbour_range(cell_of[x], row, seg, cell_start, ncx, ncy, periodic)
            for k in range(k_lo, k_hi):
                j = sorted_ids[k]
                if top >= 0 and label[j] != -1 - b:
                    if _linked(xp, rx, j, t, box, pos, vel, tau, radius, links, periodic):
                        old = ti.atomic_min(label[j], -1 - b)
                        if old >= 0 and top < hi:
                            claimed[top] = k
                            top += 1
                        elif old != -1 - b:
                            top = -1
                            m = -1
    return top


@launch.kernel
def split_parts(pos: ndarr, vel: ndarr, tau: ndarr, radius: ndarr, label: ndarr, claimed: ndarr, reach: ndarr,
                touched: ndarr, dirty: ndarr, info: ndarr, cell_of: ndarr, cell_start: ndarr, sorted_ids: ndarr,
                ncx: ti.i32, ncy: ti.i32, rows: ti.i32, segs: ti.i32, rows_per: ti.i32, parts: ti.i32, box_w: ti.f64,
                box_h: ti.f64, t: ti.f64, window: ti.f64, vlim: ti.f64, allowance: ti.f64, r_same: ti.f64,
                real: ti.template(), periodic: ti.template(), same: ti.template()) -> ti.i32:
    """Split the circles into `parts` parts (see above): strips of `rows_per` rows of cells (the
    last takes the rest), circle i of strip k labelled k, except the clusters of linked
    circles (see above: at time t, for the window of length `window` that the parts run, the
    circles no faster than vlim; the reaches with a 1% allowance and `allowance` more,
    `reach` their store) that cross a border: each goes whole to the strip below the border (in a
    periodic box, the border between the last strip and the first is the last strip's), its
    circles labelled -1 - k and their slots listed in `claimed`, part k's from
    info[parts + 1 + k] to info[2 parts + 1 + k] (each border has an equal share of `claimed`;
    the threads take the borders in turn). Fills `info` (`part_info_size`). Returns 0 when a
    border's clusters outgrow its share, or a cluster crosses two borders (linked circles that
    span the box, as in a dense packing): then the caller runs shorter windows, or one queue.
    (rows, segs): see `geometry.spans`. Clears every circle's flags `touched` and `dirty` for the
    window's searches (`queue_parts`; in its pass over every circle, not a pass of its own)."""
    n = pos.shape[0]
    rad, = ti.static((Same(ti.cast(r_same, real)),) if same else (radius,))  # `Same` with `same`
    for i in range(n):
        label[i] = _strip_of(cell_of[i], ncx, rows_per, parts, periodic)
        reach[i] = -1.0
        touched[i] = 0
        dirty[i] = 0
    taken = 3 * parts + 1
    ok = 3 * parts + 2
    borders = parts - 1
    if ti.static(periodic):
        borders = parts
    info[taken] = 0
    info[ok] = 1
    share = claimed.shape[0] // ti.max(borders, 1)
    for it in range(ti.static(max(count_parts(), 1)) * PART_ITERATIONS):
        if it % PART_ITERATIONS == 0:
            box = ti.Vector([box_w, box_h], dt=ti.f64)
            links = ti.static((window, vlim, reach, cell_of, cell_start, sorted_ids, ncx, ncy, rows, segs,
                               allowance))
            while True:
                b = ti.atomic_add(info[taken], 1)
                if b >= borders:
                    break
                top = b * share
                info[parts + 1 + b] = top
                y = ti.select(b == parts - 1, ncy, (b + 1) * rows_per) - 1  # the last row of strip b
                c_lo = _row_start(y, ncx, periodic)
                for s in range(cell_start[c_lo], cell_start[_row_start(y + 1, ncx, periodic)]):
                    if top < 0:
                        break
                    i = sorted_ids[s]
                    if label[i] >= 0:  # else claimed with its cluster already
                        xp, rx = _link_origin(i, t, box, pos, vel, tau, rad, links, periodic)
                        crosses = False
                        for seg in range(segs):
                            a_lo, a_hi = neighbour_range(cell_of[i], 2, seg, cell_start, ncx, ncy, periodic)
                            for k in range(a_lo, a_hi):
                                if not crosses:
                                    if _linked(xp, rx, sorted_ids[k], t, box, pos, vel, tau, rad, links,
                                               periodic):
                                        crosses = True
                        if crosses:
                            top = _claim_cluster(i, s, b, t, top, (b + 1) * share, box, pos, vel, tau, rad,
                                                 label, claimed, cell_of, cell_start, sorted_ids, ncx, ncy, rows,
                                                 segs, links, periodic)
                if top < 0:
                    info[ok] = 0
                    top = b * share
                info[2 * parts + 1 + b] = top
    ti.loop_config(serialize=True)
    for _ in range(1):
        if ti.static(not periodic):
            info[2 * parts] = 0  # the last strip has no border above it
            info[3 * parts] = 0
        # Part sizes: a strip's slots, less its circles claimed by any part, plus the part's claims.
        for k in range(parts):
            s_lo, s_hi = _strip_slots(k, rows_per, parts, ncx, ncy, cell_start, periodic)
            info[k] = s_hi - s_lo
        for k in range(parts):
            for m in range(info[parts + 1 + k], info[2 * parts + 1 + k]):
                info[_strip_of(cell_of[sorted_ids[claimed[m]]], ncx, rows_per, parts, periodic)] -= 1
        for k in range(parts):
            info[k] += info[2 * parts + 1 + k] - info[parts + 1 + k]
        running = 0
        for k in range(parts):
            size = info[k]
            info[k] = running
            running += size
        info[parts] = running
    return info[ok]


@ti.func
def _member(q, k, s_hi, c0, label: ti.template(), claimed: ti.template(), sorted_ids: ti.template()):
    """(slot, circle, whether in part k) of item q of part k's loop over its strip's slots (q <
    s_hi; the strip's circles labelled k) and then its claimed circles (from claimed[c0])."""
    s = q
    if q >= s_hi:
        s = claimed[c0 + q - s_hi]
    i = sorted_ids[s]
    take = q >= s_hi or label[i] == k
    return s, i, take


@ti.func
def _pair_in_part(i, j, a: ti.template()):
    """`_pair_once` for a pair within part a[13] (labels a[12]); a pair across two parts, which
    cannot meet within the window, flags both circles touched and dirty, a[14] and a[15]
    (`repredict` searches them in full before the next window)."""
    if _own_part(j, (a[12],)) == a[13]:
        _pair_once(i, j, a)
    else:
        for f in ti.static(range(14, 16)):
            a[f][i] = 1
            a[f][j] = 1


@launch.kernel
def repredict(pos: ndarr, vel: ndarr, radius: ndarr, tau: ndarr, ids: ndarr, ev_t: ndarr, ev_p: ndarr,
              dirty: ndarr, touched: ndarr, cell_of: ndarr, cell_start: ndarr, sorted_ids: ndarr, ncx: ti.i32,
              ncy: ti.i32, rows: ti.i32, segs: ti.i32, box_w: ti.f64, box_h: ti.f64, t_end: ti.f64, scalars: ndarr,
              r_same: ti.f64, real: ti.template(), periodic: ti.template(), same: ti.template()):
    """The events up to t_end of the circles flagged dirty (a touched circle, or one whose
    partner is, searches all its neighbours; see `_predict`), with one grid level, before a
    later window of a step in parts: the circles whose searches met a neighbour in another part
    (`_earliest`, `_pair_in_part`). The dirty flags are cleared as they are read; the touched
    ones are left for the next split to clear (`split_parts`), which comes before any other
    reader. With `same`, every radius is r_same (`Same`)."""
    rad, = ti.static((Same(ti.cast(r_same, real)),) if same else (radius,))
    _predict(pos, vel, rad, tau, ids, ev_t, ev_p, dirty, touched, cell_of, cell_start, sorted_ids, ncx, ncy, rows,
             segs, box_w, box_h, t_end, scalars, real, periodic, False, False)


@launch.kernel
def queue_parts(pos: ndarr, vel: ndarr, radius: ndarr, inv_mass: ndarr, tau: ndarr, ids: ndarr, ev_t: ndarr,
                ev_p: ndarr, stamp: ndarr, heap: ndarr, where: ndarr, heap_t: ndarr, head: ndarr, nxt: ndarr,
                prv: ndarr, pending: ndarr, pair_count: ndarr, wall_count: ndarr, virial: ndarr,
                wall_impulse: ndarr, touched: ndarr, dirty: ndarr, b_pos: ndarr, b_vel: ndarr,
                sum_i: ndarr, sum_s: ndarr, sum_at: ndarr, sum_chunk: ti.i32,
                label: ndarr, claimed: ndarr, info: ndarr, result: ndarr, speed_out: ndarr, cell_of: ndarr,
                cell_start: ndarr,
                sorted_ids: ndarr, ncx: ti.i32, ncy: ti.i32, rows: ti.i32, segs: ti.i32, rows_per: ti.i32,
                parts: ti.i32, box_w: ti.f64,
                box_h: ti.f64, t_end: ti.f64, until: ti.f64, vlim: ti.f64, t_offset: ti.f64, first: ti.i32, counters: ndarr, log_t: ndarr, log_i: ndarr, log_j: ndarr, per_bucket: ti.i32,
                most_per_circle: ti.i32, r_same: ti.f64, w_same: ti.f64, real: ti.template(),
                record: ti.template(), periodic: ti.template(), same: ti.template()):
    """The events up to `until` of a step over [0, t_end] of circles split into parts
    (`split_parts`, one grid level), from the events the circles hold (`repredict`), or with
    `first` (the step's first window) from the events each part predicts for its circles
    (each pair once, as `_first_events_once`; a pair across two parts flags both circles
    touched, for the next window to search in full): each part's queue filled and run
    (`_drain`) by one thread, the threads taking parts in turn. With `first`, each part also
    copies its circles' positions and velocities at the step's start (every clock 0) into the
    backup (b_pos, b_vel) before its events run, as it reads them for their walls, and the
    step's sum log starts empty; every event in any window writes what it adds to the counts
    and sums to the log instead (sum_i, sum_s from sum_at[0] on, `sum_chunk` entries taken at a
    time; see above), and `apply_sums` adds them once the step is done. A collision that would
    outrun the grid, in any window, redoes the step from the backup, the log dropped
    (`Simulation._queue_parts_step`); a part that finds the log full stops before the event
    with result -3 (`Simulation._sum_log_full`).
    Circles stay at their clocks (but see the last window, below). result[k]: what
    `queue_step` returns, for part k. In the step's last window (`until` = `t_end`) a part that
    reached the end (no collision that would outrun the grid) also moves its circles there and
    measures their largest speed (`finish`, while its arrays are in the cache), into speed_out as
    `finish` leaves it. Part k's queue uses the slots info[k] to info[k + 1] of
    heap, heap_t and pending, and the buckets from info[k] // per_bucket + k of head (one per
    `per_bucket` circles, the width the head array was made for); a part stops after
    `most_per_circle` events a circle. Both come as arguments, not as the module's constants
    (QUEUE_BUCKET_CIRCLES, MOST_EVENTS_PER_CIRCLE), which a kernel reads once, when it compiles:
    a head array made for another width than the compiled one was written past its end."""
    n = pos.shape[0]
    queue = ti.static((heap, where, heap_t, head, nxt, prv, pending))
    # With `same`, every circle's radius and inverse mass are r_same and w_same (`Same`).
    rad, wmass = ti.static((Same(ti.cast(r_same, real)), Same(ti.cast(w_same, real))) if same else
                           (radius, inv_mass))
    info[3 * parts + 1] = 0  # parts taken
    if first != 0:
        sum_at[0] = 0  # the step's sum log starts empty
    speed_out[0] = 0.0
    speed_out[1] = 0.0
    for it in range(ti.static(max(count_parts(), 1)) * PART_ITERATIONS):
        if it % PART_ITERATIONS == 0:
            box = ti.Vector([box_w, box_h], dt=real)
            horizon = ti.cast(t_end, real)
            stop = ti.cast(until, real)
            vlim2 = ti.cast(vlim, real) ** 2
            while True:
                k = ti.atomic_add(info[3 * parts + 1], 1)
                if k >= parts:
                    break
                off = info[k]
                size_k = info[k + 1] - off
                c0 = info[parts + 1 + k]
                s_lo, s_hi = _strip_slots(k, rows_per, parts, ncx, ncy, cell_start, periodic)
                items = s_hi + info[2 * parts + 1 + k] - c0
                hb = off // per_bucket + k
                nb = ti.max(size_k // per_bucket, 1)
                scale = ti.min(nb / t_end, 1e30)
                for b in range(nb):
                    head[hb + b] = -1
                if first != 0:
                    for q in range(s_lo, items):
                        s, i, take = _member(q, k, s_hi, c0, label, claimed, sorted_ids)
                        if take:
                            copy_state(i, (pos, vel), (b_pos, b_vel))
                            _first_wall_event(i, pos, vel, rad, STEP_START, ids, ev_t, ev_p, box, horizon, real,
                                              periodic)
                    for q in range(s_lo, items):
                        s, i, take = _member(q, k, s_hi, c0, label, claimed, sorted_ids)
                        if take:
                            pairs_once(s, i, cell_of[i], True, cell_start, sorted_ids, ncx, ncy, rows, segs,
                                       periodic, _pair_in_part, (pos, vel, rad, STEP_START, ids, ev_t, ev_p,
                                                                 box, horizon, real, periodic,
                                                                 own_values(i, pos, vel, rad, STEP_START), label,
                                                                 k, touched, dirty))
                size = 0
                for q in range(s_lo, items):
                    s, i, take = _member(q, k, s_hi, c0, label, claimed, sorted_ids)
                    if take:
                        where[i] = -1
                        stamp[i] = 0
                        if ev_p[i] != NO_EVENT:
                            size = _queue_put(i, size, scale, nb, queue, ev_t, ev_p, ids, n, off, hb)
                most = ti.cast(ti.min(ti.cast(size_k, ti.i64) * most_per_circle, 1 << 30), ti.i32)
                reached, unused = _drain(size, horizon, stop, t_end, most, scale, nb, off, hb, queue,
                                         (pos, vel, rad, wmass, tau, ids, ev_t, ev_p, stamp),
                                         (pair_count, virial, wall_count, wall_impulse),
                                         (cell_of, cell_start, sorted_ids, cell_start, sorted_ids),
                                         (counters, log_t, log_i, log_j), ncx, ncy, rows, segs, 1, 1, 1, 1, 0.0,
                                         0.0, t_offset, box, vlim2, real, periodic, record, False,
                                         (label, touched, dirty), (sum_i, sum_s, sum_at, sum_chunk))
                result[k] = reached
                if until >= t_end and reached >= t_end:
                    for q in range(s_lo, items):
                        s, i, take = _member(q, k, s_hi, c0, label, claimed, sorted_ids)
                        if take:
                            _finish_one(i, pos, vel, tau, horizon, box, periodic, speed_out, True)

@launch.kernel
def finish(pos: ndarr, vel: ndarr, tau: ndarr, t_end: ti.f64, box_w: ti.f64, box_h: ti.f64, speed_out: ndarr,
           real: ti.template(), periodic: ti.template(), serial: ti.template(), speed: ti.template()) -> ti.f64:
    """Every circle moved to the step's end (from its own time tau); with `serial`, on one thread.
    With `speed`, also the largest speed of the state it leaves, as `reductions.max_speed`
    measures it (returned squared; see `_finish`), else 0."""
    _finish(pos, vel, tau, ti.cast(t_end, real), box_w, box_h, real, periodic, serial, speed_out, speed, ())
    result = ti.cast(0.0, ti.f64)  # a bare 0.0 would make it float32
    if ti.static(speed):
        result = speed_result(speed_out)
    return result


@ti.func
def _finish(pos: ti.template(), vel: ti.template(), tau: ti.template(), horizon, box_w, box_h, real: ti.template(),
            periodic: ti.template(), serial: ti.template(), speed_out: ti.template(), speed: ti.template(),
            clear: ti.template()):
    """`finish` to the step's end `horizon` (of type real), as a loop of the calling kernel.
    With `speed`, the largest |v|^2 (float64) goes to speed_out[0] and the count of circles whose
    new position or velocity is not finite to speed_out[1], so that the next step needs no pass
    of `reductions.max_speed` (the same values it reads, from registers). `clear`: () or the
    events (ev_t, ev_p), each circle's then cleared (NEVER, NO_EVENT), as one queue's next first
    predictions on one thread take them (`_first_events_once` with `fresh`)."""
    if ti.static(speed):
        speed_out[0] = 0.0
        speed_out[1] = 0.0
    ti.loop_config(serialize=serial)
    for i in range(pos.shape[0]):
        box = ti.Vector([box_w, box_h], dt=real)
        _finish_one(i, pos, vel, tau, horizon, box, periodic, speed_out, speed)
        if ti.static(len(clear) > 0):
            clear[0][i] = ti.cast(NEVER, real)  # as `_first_wall_event` and the set-up write it
            clear[1][i] = NO_EVENT


@ti.func
def _finish_one(i, pos: ti.template(), vel: ti.template(), tau: ti.template(), horizon, box,
                periodic: ti.template(), speed_out: ti.template(), speed: ti.template()):
    """Circle i of `_finish`: moved to `horizon` (wrapped into the box when periodic), its clock
    0, and with `speed` its |v|^2 offered to speed_out."""
    v = vel[i]
    x = pos[i] + v * (horizon - tau[i])
    if ti.static(periodic):
        x -= box * ti.floor(x / box)
        # x / box can round up to exactly 1 for x a hair below 0.
        for a in ti.static(range(2)):
            if x[a] >= box[a]:
                x[a] -= box[a]
    pos[i] = x
    tau[i] = 0.0
    if ti.static(speed):
        s, bad = speed_of(x, v)
        offer_speed(speed_out, s, bad)
