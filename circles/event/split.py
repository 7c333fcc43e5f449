"""A step's queue split into parts, in windows of the step (several threads on a CPU)."""
import taichi as ti

from .. import launch
from ..geometry import displacement, neighbour_range, NEVER, NO_EVENT, pairs_once, run_parts
from ..grid import count_parts, PART_ITERATIONS
from .calendar import _queue_put
from .queue import _drain
from .rounds import _predict, copy_state
from .search import _finish_one, _first_wall_event, _own_part, _pair_once
from .time_of_impact import own_values, Same, STEP_START

ndarr = ti.types.ndarray(ndim=1)


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
# 2 vlim (h - t0) >= 2 vlim W, for which f is W anyway. Call such circles linked. The reaches
# are well below vlim W for most circles, so the clusters across the borders of a split are
# several times smaller than with 2 vlim W for every pair. A set of circles closed under links (a cluster and its like) evolves through the window on
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
# Over a whole step the clusters can span the box: the step runs in windows, each split anew
# (see `EventStepper._queue_parts_step`). A part's searches meet
# only its own circles, so a circle's event past the window can miss a pair with another
# part: a search that meets a neighbour in another part flags the circle (`_earliest`,
# `_pair_in_part`), and before the next window the flagged circles search again over all
# their neighbours (`repredict`). A collision that would outrun the grid ends the step at its
# time for every circle, but the other parts may have gone past it: every circle is put back
# to the step's start and the step runs again up to that time. Each part copies its circles'
# positions and velocities as its first window begins, while they are in the cache for their
# first predictions. Such steps are rare once the speeds have spread from their start (the
# speed limit has a margin, stepper.SPEED_MARGIN). The counts and sums (pair_count, virial,
# wall_count, wall_impulse), which only an event's one or two circles change, are not changed
# in the step at all: each event writes what it adds to them to a sum log, in chunks each part
# takes in turn, and `apply_sums` adds the log once the step is done, so a redone step only
# drops it. An event then touches no line of the sums, which no search reads (their first load
# in an event would be its costliest cache miss), and a step takes no copy of them.


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
    (`EventStepper._queue_parts_step`); a part that finds the log full stops before the event
    with result -3 (`EventStepper._sum_log_full`).
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
                                         (label, touched, dirty), (sum_i, sum_s, sum_at, sum_chunk), ())
                result[k] = reached
                if until >= t_end and reached >= t_end:
                    for q in range(s_lo, items):
                        s, i, take = _member(q, k, s_hi, c0, label, claimed, sorted_ids)
                        if take:
                            _finish_one(i, pos, vel, tau, horizon, box, periodic, speed_out, True)
