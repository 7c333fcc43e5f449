"""The parallel rounds of an event step: predict, bound, execute (see `circles.event`)."""
import taichi as ti

from .. import launch
from ..geometry import displacement, key_less, neighbour_range, NEVER, NO_EVENT
from .search import _earliest
from .time_of_impact import _tie_ids

#: Bound sweeps per launch (even: the two flag arrays swap roles each sweep).
SWEEPS_PER_LAUNCH = 4
#: The keys a bound carries besides an event's (`_bound_sweep`): below every event's, for a
#: bound that no event at its time may pass; n + BOUND_KEY_NONE, above every event's (no event
#: has more than n + 8), for a bound set by no event.
BOUND_KEY_LOW = -1
BOUND_KEY_NONE = 9

ndarr = ti.types.ndarray(ndim=1)


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
                                                  0, 0, 0, 0, 0, 0.0, 1, 0, 0, (), ())
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
