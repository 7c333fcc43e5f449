"""A circle's earliest event: the search of its neighbours' times of impact and of its walls,
the ordering of events by key, and the move of every circle to the step's end."""
import taichi as ti

from .. import launch
from ..geometry import displacement, forward_fits, key_less, NEVER, NO_EVENT, pairs_once
from ..reductions import offer_speed, speed_of, speed_result
from .calendar import _queue_fix
from .time_of_impact import event_key, own_values, pair_time
from .two_level import _at, _run, _runs

ndarr = ti.types.ndarray(ndim=1)

#: Neighbours listed a circle at most (`_first_events_once`): in a dense fluid a circle has
#: about 5 within a step's reach, so a list holds them several times over; a circle with
#: more (a large one among small ones, a long step) searches its cells.
LIST_SLOTS = 16


@ti.func
def _earliest(i, full, pos: ti.template(), vel: ti.template(), radius: ti.template(), tau: ti.template(),
              ids: ti.template(), ev_t: ti.template(), ev_p: ti.template(), moved: ti.template(),
              cell_of: ti.template(), cell_start: ti.template(), sorted_ids: ti.template(), ncx, ncy, rows, segs, box,
              horizon, real: ti.template(), periodic: ti.template(), coarse_start: ti.template(),
              coarse_ids: ti.template(), ncx_c, ncy_c, mx, my, r_cut, margin, two_level: ti.template(),
              queue: ti.template(), code, size, changed_a, changed_b, pend_at, scale, nb, off, hb, part: ti.template(),
              lists: ti.template()):
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
    part are met, and a neighbour j in another part flags i touched and dirty and j dirty.
    `lists`: () or (count, slots) of `_first_events_once`: i's neighbours within the step's
    reach, read in place of its cells when its list did not overflow (count >= 0)."""
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
    listed = False
    if ti.static(len(lists) > 0):
        m = lists[0][i]
        if m >= 0:
            listed = True
            for s in range(m):
                j = lists[1][i * LIST_SLOTS + s]
                best_t, best_lo, best_hi, best_p, size_now, pending = _meet(
                    i, j, own, mine, full, pos, vel, radius, tau, ids, ev_t, ev_p, moved, box, horizon, real,
                    periodic, queue, code, changed_a, changed_b, pend_at, scale, nb, off, hb, part, best_t, best_lo,
                    best_hi, best_p, size_now, pending)
    if not listed:
        runs, kx, ky = _runs(i, radius, box, ncx, ncy, rows, segs, r_cut, margin, two_level)
        for r in range(runs):
            k_lo, k_hi, coarse = _run(r, c, kx, ky, cell_start, coarse_start, ncx, ncy, segs, ncx_c, ncy_c, mx, my,
                                      periodic, two_level)
            for k in range(k_lo, k_hi):
                j = _at(k, coarse, sorted_ids, coarse_ids, radius, r_cut, two_level)
                best_t, best_lo, best_hi, best_p, size_now, pending = _meet(
                    i, j, own, mine, full, pos, vel, radius, tau, ids, ev_t, ev_p, moved, box, horizon, real,
                    periodic, queue, code, changed_a, changed_b, pend_at, scale, nb, off, hb, part, best_t, best_lo,
                    best_hi, best_p, size_now, pending)
    return best_t, best_p, size_now, pending


@ti.func
def _meet(i, j, own: ti.template(), mine, full, pos: ti.template(), vel: ti.template(), radius: ti.template(),
          tau: ti.template(), ids: ti.template(), ev_t: ti.template(), ev_p: ti.template(), moved: ti.template(),
          box, horizon, real: ti.template(), periodic: ti.template(), queue: ti.template(), code, changed_a, changed_b,
          pend_at, scale, nb, off, hb, part: ti.template(), best_t, best_lo, best_hi, best_p, size_now, pending):
    """Neighbour j (-1: none) met by circle i's search (`_earliest`, whose arguments these are):
    returns the best (key, partner), the queue's size and the neighbours listed, updated."""
    n = pos.shape[0]
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
    return best_t, best_lo, best_hi, best_p, size_now, pending


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
def _pair_listed(i, j, a: ti.template()):
    """`_pair_once`, and the pair listed in both circles' neighbours (a[12], a[13]) when their
    distance squared at the step's start is at most a[14] (`_first_events_once`)."""
    _pair_once(i, j, a)
    d = displacement(a[0][i], a[0][j], a[7], a[10])
    if d.dot(d) <= a[14]:
        _list_add(i, j, a[12], a[13])
        _list_add(j, i, a[12], a[13])


@ti.func
def _list_add(i, j, count: ti.template(), slots: ti.template()):
    """j into i's list of neighbours, or i's list marked overflowed (-1) when full."""
    m = count[i]
    if m >= 0:
        if m < LIST_SLOTS:
            slots[i * LIST_SLOTS + m] = j
            count[i] = m + 1
        else:
            count[i] = -1


@ti.func
def _first_events_once(pos: ti.template(), vel: ti.template(), radius: ti.template(), tau: ti.template(),
                       ids: ti.template(), ev_t: ti.template(), ev_p: ti.template(), cell_of: ti.template(),
                       cell_start: ti.template(), sorted_ids: ti.template(), ncx, ncy, rows, segs, box_w, box_h,
                       horizon, real: ti.template(), periodic: ti.template(), fresh: ti.template(),
                       lists: ti.template(), list_r2):
    """On one thread, every circle's earliest event, as `_earliest` in full would find it, with
    each pair's time of impact computed once, not once from each circle: every circle takes
    its walls, then each pair is offered to both circles from the forward half of one circle's
    cells (`geometry.pairs_once`). The minimum of the keys does not depend on the order of the
    offers. One grid level. `fresh`: every circle holds no event (as `queue_step`'s finish on
    one thread leaves it), and takes its walls as the pairs' loop visits it
    (`_merge_wall_event`), after the offers of the circles before it, in one pass instead of two.

    With `lists` (count, slots), each circle's neighbours within distance sqrt(list_r2) at the
    step's start are listed as the pairs are visited, at most LIST_SLOTS a circle (count -1 when
    more: its searches read its cells). Every pair that can meet within the step is that close
    (the grid's reach), so a search of the list meets the pairs that a search of the cells would
    and skips the cells' other circles, which cannot meet before the horizon.

    (On several threads the offers of two threads could meet at one circle; there each circle
    searches all its cells, `queue_step`.)"""
    n = pos.shape[0]
    if ti.static(len(lists) > 0):
        ti.loop_config(serialize=True)
        for i in range(n):
            lists[0][i] = 0
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
        if ti.static(len(lists) > 0):
            pairs_once(own, i, cell_of[i], forward, cell_start, sorted_ids, ncx, ncy, rows, segs, periodic,
                       _pair_listed, (pos, vel, radius, tau, ids, ev_t, ev_p, box, horizon, real, periodic,
                                      own_values(i, pos, vel, radius, tau), lists[0], lists[1],
                                      ti.cast(list_r2, real)))
        else:
            pairs_once(own, i, cell_of[i], forward, cell_start, sorted_ids, ncx, ncy, rows, segs, periodic,
                       _pair_once, (pos, vel, radius, tau, ids, ev_t, ev_p, box, horizon, real, periodic,
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
