"""One queue of events and its calendar: a step's events one at a time, in time order."""
import taichi as ti

from .. import launch
from ..geometry import NO_EVENT
from ..grid import _part_range, count_parts, PART_ITERATIONS
from .calendar import _heap_put, _queue_fix, _queue_put, _sift_down, POURED
from .rounds import _log, _pair_event, _wall_event
from .search import _earliest, _finish, _first_events_once
from .time_of_impact import Same, STEP_START

ndarr = ti.types.ndarray(ndim=1)


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

@ti.func
def _drain(size, horizon, until, reached, most, scale, nb, off, hb, queue: ti.template(), state: ti.template(),
           sums: ti.template(), grid: ti.template(), log: ti.template(), ncx, ncy, rows, segs, ncx_c, ncy_c, mx, my,
           r_cut, margin, t_offset, box, vlim2, real: ti.template(), periodic: ti.template(), record: ti.template(),
           two_level: ti.template(), part: ti.template(), log_sums: ti.template(), lists: ti.template()):
    """Execute a filled queue's events in key order up to `horizon` (see above), each followed
    by the searches it calls for; returns (reached, horizon): as `queue_step` returns, and the
    step's end, moved to the time of a collision that would outrun the grid. state: (pos, vel,
    radius, inv_mass, tau, ids, ev_t, ev_p, stamp); sums: (pair_count, virial, wall_count,
    wall_impulse); grid: (cell_of, cell_start, sorted_ids, coarse_start, coarse_ids); log:
    (counters, log_t, log_i, log_j); `most`: the events allowed; off, hb, part: see `_earliest`;
    log_sums: () or (sum_i, sum_s, sum_at, chunk), the log to which each event writes what it
    adds to the counts and sums instead (`_add_sums`, one entry an event, taken before it); when
    the log is full the queue stops before the event, and returns reached = -3. Events after
    `until` (at most the horizon) are left in the queue. lists: () or the neighbour lists of the
    step's first predictions (`_first_events_once`), which the searches read."""
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
                                                     off + subjects - changed, scale, nb, off, hb, part, lists)
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
                       two_level: ti.template(), serial: ti.template(), fresh: ti.template(),
                       lists: ti.template(), list_r2):
    """Every circle's earliest event of the step (`queue_step`), from the clocks `tau` (or
    `STEP_START`): on one thread each pair computed once (`_first_events_once`, one grid level;
    `fresh`: see there; `lists`, `list_r2`: the neighbour lists it makes, or ()), else each
    circle's search in full."""
    n = pos.shape[0]
    if ti.static(serial and not two_level):
        _first_events_once(pos, vel, radius, tau, ids, ev_t, ev_p, cell_of, cell_start, sorted_ids, ncx, ncy, rows,
                           segs, box_w, box_h, horizon, real, periodic, fresh, lists, list_r2)
    else:
        ti.loop_config(serialize=serial)
        for i in range(n):
            box = ti.Vector([box_w, box_h], dt=real)
            t_i, p_i, unused, unused2 = _earliest(i, True, pos, vel, radius, tau, ids, ev_t, ev_p, stamp, cell_of,
                                                  cell_start, sorted_ids, ncx, ncy, rows, segs, box, horizon, real,
                                                  periodic, coarse_start, coarse_ids, ncx_c, ncy_c, mx, my, r_cut,
                                                  margin, two_level, (), 0, 0, 0, 0, 0, 0.0, 1, 0, 0, (), ())
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
               list_count: ndarr, list_slots: ndarr, list_r2: ti.f64, real: ti.template(), periodic: ti.template(),
               record: ti.template(), two_level: ti.template(), serial: ti.template(), at_start: ti.template(),
               same: ti.template(), listed: ti.template()) -> ti.f64:
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
    every circle's radius and inverse mass are r_same and w_same (`Same`). With `listed` (on one
    thread, one grid level, at the step's start), the first predictions list each circle's
    neighbours within sqrt(list_r2), the grid's reach, in list_count and list_slots, and the
    searches after each event read those lists instead of the cells (`_first_events_once`)."""
    n = pos.shape[0]
    rad, wmass = ti.static((Same(ti.cast(r_same, real)), Same(ti.cast(w_same, real))) if same else
                           (radius, inv_mass))
    horizon = ti.cast(t_end, real)
    vlim2 = ti.cast(vlim, real) ** 2
    reached = t_end
    lists = ti.static((list_count, list_slots) if listed and at_start and serial and not two_level else ())
    if ti.static(at_start):
        _first_predictions(pos, vel, rad, STEP_START, ids, ev_t, ev_p, stamp, cell_of, cell_start, sorted_ids, ncx,
                           ncy, rows, segs, box_w, box_h, horizon, coarse_start, coarse_ids, ncx_c, ncy_c, mx, my,
                           r_cut, margin, real, periodic, two_level, serial, True, lists, list_r2)
    else:
        _first_predictions(pos, vel, rad, tau, ids, ev_t, ev_p, stamp, cell_of, cell_start, sorted_ids, ncx, ncy,
                           rows, segs, box_w, box_h, horizon, coarse_start, coarse_ids, ncx_c, ncy_c, mx, my, r_cut,
                           margin, real, periodic, two_level, serial, False, (), 0.0)
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
                                  margin, t_offset, box, vlim2, real, periodic, record, two_level, (), (), lists)
    # A top-level loop (one inside a branch would run on one thread); the largest speed of the
    # state it leaves in speed_out, and on one thread no event held (`_finish`), for the next step.
    _finish(pos, vel, tau, horizon, box_w, box_h, real, periodic, serial, speed_out, True,
            (ev_t, ev_p) if ti.static(serial) else ())
    return reached
