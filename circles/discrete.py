"""Scheme "discrete": the fast approximate baseline (the original assignment's method).

A step moves every circle by v dt, then resolves overlapping approaching pairs with the exact
elastic impulse, then reflects circles that crossed a wall by mirroring their position.
Pairs are resolved race-free and deterministically: in each round every circle picks, among
its overlapping approaching neighbours, the pair that touched first (largest overlap over
approach speed, ties by ids), and mutual picks are resolved together. The pair with the
smallest key overall is always mutual, so each round resolves at least one pair. After the
first round only circles overlapping a resolved circle pick again; the others' picks still hold.

What a step touches: every circle once to move and once to sort into the grid and search the
forward half of its neighbour cells for overlaps (each pair is tested once); the first round
reads a mark of every circle and works on those with an approaching overlap (on a CPU each
thread first lists its part's marked circles, `_first_round_in_parts`), later rounds
visit only the circles listed as overlapping a resolved one, and the walls only the circles
the move left reaching past a wall.

On a CPU with several threads the step runs as one team (`team_step`, `circles.team`): the
same stages in one parallel loop, each cut into chunks that the threads take, with one start
of the thread pool a step instead of one per loop (a dozen or more, each as long as a step of
tens of thousands of circles on some hosts).

Radius spread: cells as wide as the largest diameter would hold hundreds of small circles
when a few circles are much larger. In a walled box with a few large circles (see
simulation.LARGE_RADIUS_RATIO) the grid has two levels: cells sized for the small circles,
which search their neighbour cells for each other, and the large circles, each of which
searches the block of cells its reach spans for all its pairs (`wide_row`). Both levels find
the same pairs, so the state is the same bit for bit as with one level.

Known errors of the method, which the benchmark measures: a circle faster than about a
diameter per step can pass through another (tunnelling), overlap is left behind, and
collisions can be missed or counted twice.
"""
import taichi as ti

from . import launch
from .geometry import (NEVER, displacement, forward_fits, forward_range, neighbour_range, pairs_once, run_parts,
                       wide_row)
from .grid import (CPU_GROUP, PART_ITERATIONS, _part_range, _scan_shape, chunk_ends, chunk_starts, chunk_total,
                   count_part, count_parts, count_strays, enter_cells, finish_cells, owned_starts, scatter_group)
from .geometry import cells_in
from .team import STAGES, chunks_of, clear, loop_iterations, member_of, span, stage, value_slot

ndarr = ti.types.ndarray(ndim=1)


#: Slots of the `work` array: the round number, the lengths of the two work lists, the
#: number of circles reaching past a wall, the number of large circles (two-level grid), and
#: from PART_PICKS on, one per CPU part, the picks of the part's first round (`_first_round_in_parts`).
ROUND, LIST0, LIST1, WALLED, NLARGE, PART_PICKS = 0, 1, 2, 3, 4, 5
#: The longest contact list a circle may have (simulation.DISCRETE_CONTACTS is its length):
#: `_enlist_overlapping` keeps a circle and its contacts in a local vector.
MOST_CONTACTS = 7
#: Entries of the `spread` array of a two-level grid: the largest radius of a small circle and
#: the largest radius.
R_CUT, R_MAX = 0, 1


@ti.func
def per_circle(i, radius: ti.template(), uniform: ti.template()):
    """Circle i's entry of `radius` (or of any per-circle array that `uniform` covers: the
    inverse masses too); with `uniform` (every circle has the same radius and mass) the first
    circle's, which stays in the cache: a scene of equal circles reads none per circle."""
    k = i
    if ti.static(uniform):
        k = 0
    return radius[k]


@ti.func
def _moved(i, a: ti.template()):
    """Where circle i is after its move by v dt (wrapped into the box when periodic); a circle
    that ends up reaching past a wall is listed in `walled`. a = (pos, vel, radius, n_contacts,
    walled, work, h, box_w, box_h, real, periodic, uniform)."""
    box = ti.Vector([a[7], a[8]], dt=a[9])
    x = a[0][i] + a[1][i] * a[6]
    if ti.static(a[10]):
        x -= box * ti.floor(x / box)
        for k in ti.static(range(2)):
            if x[k] >= box[k]:
                x[k] -= box[k]
    else:
        r = per_circle(i, a[2], a[11])
        if x[0] < r or x[0] > box[0] - r or x[1] < r or x[1] > box[1] - r:
            a[4][ti.atomic_add(a[5][WALLED], 1)] = i
    return x


@ti.func
def _keep_moved(i, x, a: ti.template()):
    """The stores of circle i's move to x: its position, and its contact list emptied."""
    a[0][i] = x
    a[3][i] = 0


@ti.func
def _move(pos: ti.template(), vel: ti.template(), radius: ti.template(), n_contacts: ti.template(),
          walled: ti.template(), work: ti.template(), cell_of: ti.template(), slot: ti.template(),
          cell_count: ti.template(), stray: ti.template(), parts: ti.template(), ncx, ncy, inv_cw, inv_ch, transposed,
          dt, box_w,
          box_h, real: ti.template(), periodic: ti.template(), uniform: ti.template(), serial: ti.template()):
    """x += v dt (wrapped into the box when periodic), counted into its grid cell; contact lists
    emptied in the same pass (see grid.enter_cells).

    In a walled box the circles that end up reaching past a wall are listed in `walled`
    (work[WALLED] of them): only they can need a wall reflection at the end of the step.
    """
    work[WALLED] = 0
    enter_cells(pos.shape[0], _moved, _keep_moved,
                (pos, vel, radius, n_contacts, walled, work, ti.cast(dt, real), box_w, box_h, real, periodic, uniform),
                cell_of, slot, cell_count, stray, parts, ncx, ncy, inv_cw, inv_ch, transposed, real, periodic,
                serial)


@ti.func
def _claim(k, rnd, marked: ti.template()):
    """Whether this thread is the first to mark k for round `rnd` (and must list it): marked[k]
    is the last round k was listed for, and round numbers only grow."""
    first = False
    if marked[k] < rnd:
        first = ti.atomic_max(marked[k], rnd) < rnd
    return first


@ti.func
def _enlist(k, rnd, marked: ti.template(), lists: ti.template(), work: ti.template(), side):
    """Put k on the work list of round `rnd` (list `side`), once (`_claim`)."""
    if _claim(k, rnd, marked):
        lists[side, ti.atomic_add(work[LIST0 + side], 1)] = k


@ti.func
def _listed(a, rnd, flag: ti.template(), lists: ti.template(), side, every: ti.template()):
    """(circle, whether it takes part) for item a of a round's loop: the a-th entry of the
    round's work list, or with `every` circle a itself when flag[a] is the round's number
    (`marked` in the pick pass, `picked` in the resolve pass, which changes `marked`).

    A step's first round loops over every circle: it reads them in memory order, and the scan
    that marks them builds no list, whose one counter every listing thread would add to (on a
    GPU those adds to one address cost more than the loop; on a CPU the loop is no slower).
    Later rounds list the few circles whose picks a resolution changed."""
    i = a
    take = True
    if ti.static(every):
        take = flag[a] == rnd
    else:
        i = lists[side, a]
    return i, take


@ti.func
def _round_items(work: ti.template(), side, n, every: ti.template()):
    """The length of a round's loop (`_listed`): the round's list, or every circle."""
    items = n
    if ti.static(not every):
        items = work[LIST0 + side]
    return items


@ti.func
def is_large(i, radius: ti.template(), spread: ti.template(), two_level: ti.template()):
    """Whether circle i is one of the few large circles of a two-level grid (see `wide_row`)."""
    large = False
    if ti.static(two_level):
        large = radius[i] > spread[R_CUT]
    return large


@ti.func
def wide_reach(i, radius: ti.template(), spread: ti.template(), box, ncx, ncy):
    """(kx, ky): the cells along x and y within which a circle of i's radius plus the largest
    radius lies (a whole cell more than the reach, so round-off cannot cut it short)."""
    reach = ti.cast(radius[i], ti.f64) + ti.cast(spread[R_MAX], ti.f64)
    return (ti.cast(ti.floor(reach * ncx / ti.cast(box[0], ti.f64)), ti.i32) + 1,
            ti.cast(ti.floor(reach * ncy / ti.cast(box[1], ti.f64)), ti.i32) + 1)


@ti.func
def _search_runs(i, radius: ti.template(), spread: ti.template(), box, ncx, ncy, rows, segs,
                 two_level: ti.template()):
    """(kx, ky, runs): the runs of slots that hold every circle i can overlap, for a circle that
    searches its cells (its contact list overflowed, or it is a large circle): the rows of its
    block on a two-level grid (`wide_row`), else the runs of its 3 x 3 cells
    (`geometry.neighbour_range`)."""
    kx = 1
    ky = 1
    runs = rows * segs
    if ti.static(two_level):
        kx, ky = wide_reach(i, radius, spread, box, ncx, ncy)
        runs = 2 * ky + 1
    return kx, ky, runs


@ti.func
def _search_run(c, r, kx, ky, cell_start: ti.template(), ncx, ncy, segs, periodic: ti.template(),
                two_level: ti.template()):
    """Slots [lo, hi) of run r of `_search_runs` around cell c."""
    lo = 0
    hi = 0
    if ti.static(two_level):
        lo, hi = wide_row(c, r - ky, kx, cell_start, ncx, ncy)
    else:
        row, seg = run_parts(r, segs, periodic)
        lo, hi = neighbour_range(c, row, seg, cell_start, ncx, ncy, periodic)
    return lo, hi


@ti.func
def _record_contact(i, j, pos: ti.template(), vel: ti.template(), radius: ti.template(), contacts: ti.template(),
                    n_contacts: ti.template(), marked: ti.template(), rnd, box, periodic: ti.template(),
                    uniform: ti.template()):
    """Add j to i's contact list and i to j's when the two overlap (the test `_consider` makes);
    when they also approach, both are marked for the first round (`_listed`)."""
    lo = ti.min(i, j)
    hi = ti.max(i, j)
    d = displacement(pos[lo], pos[hi], box, periodic)
    s = per_circle(lo, radius, uniform) + per_circle(hi, radius, uniform)
    if d.dot(d) < s * s:
        _record_overlap(lo, hi, d, vel, contacts, n_contacts, marked, rnd)


@ti.func
def _record_overlap(i, j, d, vel: ti.template(), contacts: ti.template(), n_contacts: ti.template(),
                    marked: ti.template(), rnd):
    """`_record_contact` of a pair found overlapping, d = x_j - x_i. (A difference of two floats
    is exactly the negated difference the other way, and the products and sums below are the
    same for either sign, so the outcome does not depend on which circle is i.)"""
    # Other threads add to the same lists: atomic counts. The order in a list follows thread
    # timing, which no pick depends on (keys break ties by ids); a count above the capacity
    # sends the circle back to searching its cells.
    a = ti.atomic_add(n_contacts[i], 1)
    if a < contacts.shape[0]:
        contacts[a, i] = j
    b = ti.atomic_add(n_contacts[j], 1)
    if b < contacts.shape[0]:
        contacts[b, j] = i
    # Approaching: the sign of the normal speed `_consider` divides by the distance. A pair
    # whose quotient rounds to -0 is listed too; listing more circles changes no pick.
    if (vel[j] - vel[i]).dot(d) < 0:
        # Every thread that marks a circle here writes the same number: plain stores.
        marked[i] = rnd
        marked[j] = rnd


@ti.func
def _contact_of(i, j, a: ti.template()):
    """`_record_contact` of the pair (i, j) as `geometry.pairs_once` visits it; `a` holds the
    other arguments."""
    _record_contact(i, j, a[0], a[1], a[2], a[3], a[4], a[5], a[6], a[7], a[8], a[9])


@ti.func
def _scan_contacts(pos: ti.template(), vel: ti.template(), radius: ti.template(), contacts: ti.template(),
                   n_contacts: ti.template(), marked: ti.template(), work: ti.template(),
                   cell_of: ti.template(), cell_start: ti.template(), sorted_ids: ti.template(), ncx, ncy, rows, segs,
                   box_w, box_h, spread: ti.template(), large: ti.template(), real: ti.template(),
                   periodic: ti.template(), two_level: ti.template(), uniform: ti.template(), serial: ti.template()):
    """Fill the contact lists and mark the circles of the first round (`_listed`): every
    overlapping pair, found once, from the forward half of the cells of one of its circles
    (half the pair tests of a full 3 x 3 search). Contact lists start empty; this step's first
    round number is work[ROUND] + 1.

    Two-level grid (`wide_row`): the pairs of two small circles as above, and every pair with
    a large circle from the large circle's block (a pair of two large ones from its lower slot)."""
    work[ROUND] += 1
    work[LIST0] = 0
    work[LIST1] = 0
    ti.loop_config(serialize=serial)
    for own in range(pos.shape[0]):
        _scan_slot(own, pos, vel, radius, contacts, n_contacts, marked, work, cell_of, cell_start, sorted_ids, ncx,
                   ncy, rows, segs, box_w, box_h, spread, real, periodic, two_level, uniform)
    if ti.static(two_level):
        ti.loop_config(serialize=serial)
        for a in range(work[NLARGE]):
            _scan_large(a, pos, vel, radius, contacts, n_contacts, marked, work, cell_of, cell_start, sorted_ids, ncx,
                        ncy, rows, segs, box_w, box_h, spread, large, real, periodic, two_level, uniform)


@ti.func
def _scan_slot(own, pos: ti.template(), vel: ti.template(), radius: ti.template(), contacts: ti.template(),
               n_contacts: ti.template(), marked: ti.template(), work: ti.template(), cell_of: ti.template(),
               cell_start: ti.template(), sorted_ids: ti.template(), ncx, ncy, rows, segs, box_w, box_h,
               spread: ti.template(), real: ti.template(), periodic: ti.template(), two_level: ti.template(),
               uniform: ti.template()):
    """`_scan_contacts` of the circle in slot `own`: its pairs with the forward half of its cells."""
    # In slot order: the circle's own slot is the loop index, and its forward slots follow.
    rnd = work[ROUND]
    i = sorted_ids[own]
    c = cell_of[i]
    if ti.static(not periodic):
        # Two runs of slots (`forward_range`) walked as one loop: one exit branch, not two.
        a_hi = cell_start[c + 2]
        b_lo, b_hi = forward_range(1, c, 0, 0, own, cell_start, ncx, ncy, periodic)
        n_a = a_hi - own - 1
        count = n_a + b_hi - b_lo
        if is_large(i, radius, spread, two_level):
            count = 0  # no forward search: its pairs come from its block, below
        # i's own values read once (a walled box: no images), each neighbour's straight
        # from its slot, with no min and max of the two before the loads.
        xi = pos[i]
        ri = per_circle(i, radius, uniform)
        for m in range(count):
            k = own + 1 + m if m < n_a else b_lo + m - n_a
            j = sorted_ids[k]
            if not is_large(j, radius, spread, two_level):
                d = pos[j] - xi
                s = ri + per_circle(j, radius, uniform)
                if d.dot(d) < s * s:
                    _record_overlap(i, j, d, vel, contacts, n_contacts, marked, rnd)
    else:
        # A periodic box: the forward cells and the box for the images, which a walled one needs not.
        box = ti.Vector([box_w, box_h], dt=real)
        pairs_once(own, i, c, forward_fits(ncx, ncy, periodic), cell_start, sorted_ids, ncx, ncy, rows, segs, periodic,
                   _contact_of, (pos, vel, radius, contacts, n_contacts, marked, rnd, box, periodic, uniform))


@ti.func
def _scan_large(a, pos: ti.template(), vel: ti.template(), radius: ti.template(), contacts: ti.template(),
                n_contacts: ti.template(), marked: ti.template(), work: ti.template(), cell_of: ti.template(),
                cell_start: ti.template(), sorted_ids: ti.template(), ncx, ncy, rows, segs, box_w, box_h,
                spread: ti.template(), large: ti.template(), real: ti.template(), periodic: ti.template(),
                two_level: ti.template(), uniform: ti.template()):
    """`_scan_contacts` of large circle `a` of a two-level grid: its pairs from its block."""
    box = ti.Vector([box_w, box_h], dt=real)
    rnd = work[ROUND]
    i = large[a]
    c = cell_of[i]
    kx, ky, runs = _search_runs(i, radius, spread, box, ncx, ncy, rows, segs, two_level)
    for r in range(runs):
        k_lo, k_hi = _search_run(c, r, kx, ky, cell_start, ncx, ncy, segs, periodic, two_level)
        for k in range(k_lo, k_hi):
            j = sorted_ids[k]
            if j != i and (j > i or not is_large(j, radius, spread, two_level)):
                _record_contact(i, j, pos, vel, radius, contacts, n_contacts, marked, rnd, box, periodic, uniform)


@ti.func
def _consider(i, j, pos: ti.template(), vel: ti.template(), radius: ti.template(), ids: ti.template(), box,
              best, best_p, periodic: ti.template(), uniform: ti.template()):
    """The pick of i updated with its pair with j; returns (key, partner).

    Pairs order by (key, lower id, higher id) (`geometry.key_less`). For pairs of the same
    circle i that is the order of (key, partner's id), so ids are read only on a tie of keys.
    """
    lo = ti.min(i, j)
    hi = ti.max(i, j)
    d = displacement(pos[lo], pos[hi], box, periodic)
    s = per_circle(lo, radius, uniform) + per_circle(hi, radius, uniform)
    dist2 = d.dot(d)
    overlapping = dist2 < s * s
    if overlapping:
        dist = ti.sqrt(dist2)
        vn = (vel[hi] - vel[lo]).dot(d) / ti.max(dist, s * 1e-30)
        if vn < 0:
            # -(time since first contact at the current speeds): earliest first.
            key = -(s - dist) / (-vn)
            take = False
            if key < best:
                take = True
            elif key == best:
                if best_p >= 0:
                    take = ids[j] < ids[best_p]
            if take:
                best, best_p = key, j
    return best, best_p


@ti.func
def _pick_one(i, pos: ti.template(), vel: ti.template(), radius: ti.template(), inv_mass: ti.template(),
              ids: ti.template(), pair_count: ti.template(), virial: ti.template(), contacts: ti.template(),
              n_contacts: ti.template(), cell_of: ti.template(), cell_start: ti.template(), sorted_ids: ti.template(),
              ncx, ncy, rows, segs, box, spread: ti.template(), real: ti.template(), periodic: ti.template(),
              two_level: ti.template(), uniform: ti.template()):
    """Circle i's pick (`_pick`): the partner of its overlapping approaching pair of smallest
    key, or -1 (none, or one of an isolated pair, which is resolved here)."""
    cap = contacts.shape[0]
    best = ti.cast(NEVER, real)
    best_p = -1
    listed = n_contacts[i]
    first = -1
    if listed == 1:
        first = contacts[0, i]
        if n_contacts[first] != 1:
            first = -1
    if first >= 0:
        # An isolated pair (each circle overlaps only the other; most pairs are): the two
        # picks are each other exactly when they approach, so the lower slot resolves the
        # pair here, as `_resolve` would, and neither circle needs a pick for later rounds
        # (no other circle overlaps them, so none reads their picks this step).
        if i < first:
            _, p = _consider(i, first, pos, vel, radius, ids, box, best, best_p, periodic, uniform)
            if p == first:
                _collide(i, first, pos, vel, radius, inv_mass, ids, pair_count, virial, box, periodic,
                         uniform)
    elif listed <= cap:
        for m in range(listed):
            best, best_p = _consider(i, contacts[m, i], pos, vel, radius, ids, box, best, best_p, periodic,
                                     uniform)
    else:
        c = cell_of[i]
        kx, ky, runs = _search_runs(i, radius, spread, box, ncx, ncy, rows, segs, two_level)
        for r in range(runs):
            k_lo, k_hi = _search_run(c, r, kx, ky, cell_start, ncx, ncy, segs, periodic, two_level)
            for k in range(k_lo, k_hi):
                j = sorted_ids[k]
                if j != i:
                    best, best_p = _consider(i, j, pos, vel, radius, ids, box, best, best_p, periodic,
                                             uniform)
    return best_p


@ti.func
def _pick(pos: ti.template(), vel: ti.template(), radius: ti.template(), inv_mass: ti.template(), ids: ti.template(),
          partner: ti.template(), picked: ti.template(), pair_count: ti.template(), virial: ti.template(),
          contacts: ti.template(), n_contacts: ti.template(),
          lists: ti.template(), work: ti.template(), cell_of: ti.template(), cell_start: ti.template(),
          sorted_ids: ti.template(), ncx, ncy, rows, segs, box_w, box_h, spread: ti.template(),
          real: ti.template(), periodic: ti.template(), two_level: ti.template(), uniform: ti.template(), side,
          marked: ti.template(), every: ti.template(), serial: ti.template()):
    """Each circle on this round's work list picks its overlapping approaching pair of smallest key.

    The candidates are the circle's contact list (`_scan_contacts`): positions do not change
    within a step. A circle with more contacts than the list holds searches its cells (`_search_runs`).
    Circles off the list keep their picks: nothing about their pairs changed (see `_resolve`).
    """
    ti.loop_config(serialize=serial)
    for a in range(_round_items(work, side, pos.shape[0], every)):
        _pick_item(a, pos, vel, radius, inv_mass, ids, partner, picked, pair_count, virial, contacts, n_contacts,
                   lists, work, cell_of, cell_start, sorted_ids, ncx, ncy, rows, segs, box_w, box_h, spread, real,
                   periodic, two_level, uniform, side, marked, every)


@ti.func
def _pick_item(a, pos: ti.template(), vel: ti.template(), radius: ti.template(), inv_mass: ti.template(),
               ids: ti.template(), partner: ti.template(), picked: ti.template(), pair_count: ti.template(),
               virial: ti.template(), contacts: ti.template(), n_contacts: ti.template(), lists: ti.template(),
               work: ti.template(), cell_of: ti.template(), cell_start: ti.template(), sorted_ids: ti.template(), ncx,
               ncy, rows, segs, box_w, box_h, spread: ti.template(), real: ti.template(), periodic: ti.template(),
               two_level: ti.template(), uniform: ti.template(), side, marked: ti.template(), every: ti.template()):
    """Item a of `_pick`'s loop."""
    box = ti.Vector([box_w, box_h], dt=real)
    i, take = _listed(a, work[ROUND], marked, lists, side, every)
    if take:
        best_p = _pick_one(i, pos, vel, radius, inv_mass, ids, pair_count, virial, contacts, n_contacts, cell_of,
                           cell_start, sorted_ids, ncx, ncy, rows, segs, box, spread, real, periodic, two_level,
                           uniform)
        # In the first round a circle that picked no partner (one of an isolated pair, or
        # one with no approaching overlap: most of them) writes nothing. That round's resolve
        # takes only circles whose `picked` is the round, and no circle picks it then. A
        # later round can pick it only after a resolution changed its velocity (which
        # writes its pick) or that of a circle it overlaps (which lists it to pick again).
        # Half the stores of the pass, and the resolve reads no partner it does not use.
        if not ti.static(every) or best_p >= 0:
            partner[i] = best_p
            picked[i] = work[ROUND]


@ti.func
def _enlist_overlapping(i, rnd, pos: ti.template(), radius: ti.template(), marked: ti.template(),
                        lists: ti.template(), work: ti.template(), contacts: ti.template(), n_contacts: ti.template(),
                        cell_of: ti.template(), cell_start: ti.template(), sorted_ids: ti.template(), ncx, ncy, rows,
                        segs, box, spread: ti.template(), periodic: ti.template(), two_level: ti.template(),
                        uniform: ti.template(), side):
    """List i and every circle overlapping it for a new pick in round `rnd`.

    Positions do not move between rounds, so only pairs with i can change their key when i's
    velocity changes, and only overlapping pairs have a key: other circles' picks still hold.
    """
    listed = n_contacts[i]
    if listed <= contacts.shape[0]:
        # The newly listed ones taken together: one add to the list's length, not one each
        # (the two threads' adds to it were most of a round's resolve).
        got = ti.Vector.zero(ti.i32, MOST_CONTACTS + 1)
        m = 0
        for a in range(listed + 1):
            k = i if a == 0 else contacts[a - 1, i]
            if _claim(k, rnd, marked):
                got[m] = k
                m += 1
        if m > 0:
            at = ti.atomic_add(work[LIST0 + side], m)
            for a in range(m):
                lists[side, at + a] = got[a]
    else:
        _enlist(i, rnd, marked, lists, work, side)
        c = cell_of[i]
        kx, ky, runs = _search_runs(i, radius, spread, box, ncx, ncy, rows, segs, two_level)
        for r in range(runs):
            k_lo, k_hi = _search_run(c, r, kx, ky, cell_start, ncx, ncy, segs, periodic, two_level)
            for k in range(k_lo, k_hi):
                j = sorted_ids[k]
                d = displacement(pos[i], pos[j], box, periodic)
                s = per_circle(i, radius, uniform) + per_circle(j, radius, uniform)
                if d.dot(d) < s * s:
                    _enlist(j, rnd, marked, lists, work, side)


@ti.func
def _after_resolution(x, y, rnd, pos: ti.template(), vel: ti.template(), radius: ti.template(), ids: ti.template(),
                      partner: ti.template(), marked: ti.template(), lists: ti.template(), work: ti.template(),
                      contacts: ti.template(), n_contacts: ti.template(), cell_of: ti.template(),
                      cell_start: ti.template(), sorted_ids: ti.template(), ncx, ncy, rows, segs, box,
                      spread: ti.template(), real: ti.template(), periodic: ti.template(),
                      two_level: ti.template(), uniform: ti.template(), side):
    """x's velocity changed in its pair with y: list what must pick again in round `rnd`.

    Most circles overlap only their partner. Such a circle's next pick is made here, from that
    one pair (the same pick round `rnd` would make: no other circle's velocity it depends on
    changes before then), and it is not listed; its partner lists what it overlaps.
    """
    if n_contacts[x] == 1:
        _, p = _consider(x, y, pos, vel, radius, ids, box, ti.cast(NEVER, real), -1, periodic, uniform)
        partner[x] = p
    else:
        _enlist_overlapping(x, rnd, pos, radius, marked, lists, work, contacts, n_contacts, cell_of, cell_start,
                            sorted_ids, ncx, ncy, rows, segs, box, spread, periodic, two_level, uniform, side)


@ti.func
def _collide(i, j, pos: ti.template(), vel: ti.template(), radius: ti.template(), inv_mass: ti.template(),
             ids: ti.template(), pair_count: ti.template(), virial: ti.template(), box, periodic: ti.template(),
             uniform: ti.template()):
    """The elastic impulse of the pair (i, j), i its lower slot, when it approaches; returns
    whether it did. Plain updates, not atomics: a circle is in at most one executed pair per
    round."""
    d = displacement(pos[i], pos[j], box, periodic)
    nrm = d.normalized()
    vn = (vel[j] - vel[i]).dot(nrm)
    hit = vn < 0
    if hit:
        wi = per_circle(i, inv_mass, uniform)
        wj = per_circle(j, inv_mass, uniform)
        jmp = 2.0 * vn / (wi + wj)
        # Same expression for both circles: rounding does not depend on which one is i.
        vel[i] = vel[i] + (wi * jmp) * nrm
        vel[j] = vel[j] + (wj * jmp) * (-nrm)
        owner = i if ids[i] < ids[j] else j
        pair_count[owner] = pair_count[owner] + 1
        s = per_circle(i, radius, uniform) + per_circle(j, radius, uniform)
        virial[owner] = virial[owner] + ti.cast(s, ti.f64) * ti.abs(ti.cast(jmp, ti.f64))
    return hit


@ti.func
def _resolve_one(i, rnd, pos: ti.template(), vel: ti.template(), radius: ti.template(), inv_mass: ti.template(),
                 ids: ti.template(), partner: ti.template(), picked: ti.template(), pair_count: ti.template(),
                 virial: ti.template(), marked: ti.template(), contacts: ti.template(), n_contacts: ti.template(),
                 lists: ti.template(), work: ti.template(), cell_of: ti.template(), cell_start: ti.template(),
                 sorted_ids: ti.template(), ncx, ncy, rows, segs, box, spread: ti.template(), real: ti.template(),
                 periodic: ti.template(), two_level: ti.template(), uniform: ti.template(), side):
    """`_resolve` of circle i, which picked in round `rnd`: its pair resolved when the pick is
    mutual, by its lower index when both picked this round, else by the one that did (the
    other's pick is older and still holds)."""
    j = partner[i]
    if j >= 0 and partner[j] == i and (j > i or picked[j] != rnd):
        if _collide(i, j, pos, vel, radius, inv_mass, ids, pair_count, virial, box, periodic, uniform):
            _after_resolution(i, j, rnd + 1, pos, vel, radius, ids, partner, marked, lists, work, contacts,
                              n_contacts, cell_of, cell_start, sorted_ids, ncx, ncy, rows, segs, box, spread, real,
                              periodic, two_level, uniform, 1 - side)
            _after_resolution(j, i, rnd + 1, pos, vel, radius, ids, partner, marked, lists, work, contacts,
                              n_contacts, cell_of, cell_start, sorted_ids, ncx, ncy, rows, segs, box, spread, real,
                              periodic, two_level, uniform, 1 - side)


@ti.func
def _first_round_in_parts(pos: ti.template(), vel: ti.template(), radius: ti.template(), inv_mass: ti.template(),
                          ids: ti.template(), partner: ti.template(), picked: ti.template(), pair_count: ti.template(),
                          virial: ti.template(), marked: ti.template(), contacts: ti.template(),
                          n_contacts: ti.template(), lists: ti.template(), work: ti.template(), cell_of: ti.template(),
                          cell_start: ti.template(), sorted_ids: ti.template(), ncx, ncy, rows, segs, box_w, box_h,
                          spread: ti.template(), real: ti.template(), periodic: ti.template(),
                          two_level: ti.template(), uniform: ti.template()):
    """A step's first round (list 0) on a CPU, in one part of the circles per thread
    (`grid.count_parts`): each part lists its circles marked for the round (a store per
    circle, and a length that grows by the mark's test, with no branch), picks for them
    (`_pick_one`) and keeps in place the ones that picked a partner (work[PART_PICKS + k] of
    them); then each part resolves its kept ones (`_resolve_one`). The same picks and the same
    resolutions as `_pick` and `_resolve` over every circle, which took each circle's mark
    through a branch."""
    args = ti.static((pos, vel, radius, inv_mass, ids, partner, picked, pair_count, virial, marked, contacts,
                      n_contacts, lists, work, cell_of, cell_start, sorted_ids, ncx, ncy, rows, segs, box_w, box_h,
                      spread, real, periodic, two_level, uniform))
    for it in range(ti.static(count_parts()) * PART_ITERATIONS):
        if it % PART_ITERATIONS == 0:
            _first_pick_part(it // PART_ITERATIONS, *args)
    for it in range(ti.static(count_parts()) * PART_ITERATIONS):
        if it % PART_ITERATIONS == 0:
            _first_resolve_part(it // PART_ITERATIONS, *args)
    work[ROUND] += 1
    work[LIST0] = 0


@ti.func
def _first_pick_part(k, pos: ti.template(), vel: ti.template(), radius: ti.template(), inv_mass: ti.template(),
                     ids: ti.template(), partner: ti.template(), picked: ti.template(), pair_count: ti.template(),
                     virial: ti.template(), marked: ti.template(), contacts: ti.template(), n_contacts: ti.template(),
                     lists: ti.template(), work: ti.template(), cell_of: ti.template(), cell_start: ti.template(),
                     sorted_ids: ti.template(), ncx, ncy, rows, segs, box_w, box_h, spread: ti.template(),
                     real: ti.template(), periodic: ti.template(), two_level: ti.template(), uniform: ti.template()):
    """The picks of part k of `_first_round_in_parts`."""
    lo, hi = _part_range(pos.shape[0], k, ti.static(count_parts()))
    rnd = work[ROUND]
    m = lo
    for a in range(lo, hi):
        lists[0, m] = a
        m += ti.select(marked[a] == rnd, 1, 0)
    kept = lo
    for q in range(lo, m):
        box = ti.Vector([box_w, box_h], dt=real)  # built in the loop (tests/test_gpu_rules.py)
        i = lists[0, q]
        p = _pick_one(i, pos, vel, radius, inv_mass, ids, pair_count, virial, contacts, n_contacts, cell_of,
                      cell_start, sorted_ids, ncx, ncy, rows, segs, box, spread, real, periodic, two_level, uniform)
        if p >= 0:
            partner[i] = p
            picked[i] = rnd
            lists[0, kept] = i
            kept += 1
    work[PART_PICKS + k] = kept - lo


@ti.func
def _first_resolve_part(k, pos: ti.template(), vel: ti.template(), radius: ti.template(), inv_mass: ti.template(),
                        ids: ti.template(), partner: ti.template(), picked: ti.template(), pair_count: ti.template(),
                        virial: ti.template(), marked: ti.template(), contacts: ti.template(),
                        n_contacts: ti.template(), lists: ti.template(), work: ti.template(), cell_of: ti.template(),
                        cell_start: ti.template(), sorted_ids: ti.template(), ncx, ncy, rows, segs, box_w, box_h,
                        spread: ti.template(), real: ti.template(), periodic: ti.template(), two_level: ti.template(),
                        uniform: ti.template()):
    """The resolutions of part k of `_first_round_in_parts` (after every part's picks)."""
    lo = _part_range(pos.shape[0], k, ti.static(count_parts()))[0]
    rnd = work[ROUND]
    for q in range(lo, lo + work[PART_PICKS + k]):
        box = ti.Vector([box_w, box_h], dt=real)  # built in the loop (tests/test_gpu_rules.py)
        _resolve_one(lists[0, q], rnd, pos, vel, radius, inv_mass, ids, partner, picked, pair_count, virial, marked,
                     contacts, n_contacts, lists, work, cell_of, cell_start, sorted_ids, ncx, ncy, rows, segs, box,
                     spread, real, periodic, two_level, uniform, 0)


@ti.func
def _resolve(pos: ti.template(), vel: ti.template(), radius: ti.template(), inv_mass: ti.template(),
             ids: ti.template(), partner: ti.template(), picked: ti.template(), pair_count: ti.template(),
             virial: ti.template(), marked: ti.template(), contacts: ti.template(), n_contacts: ti.template(),
             lists: ti.template(), work: ti.template(), cell_of: ti.template(), cell_start: ti.template(),
             sorted_ids: ti.template(), ncx, ncy, rows, segs, box_w, box_h, spread: ti.template(),
             real: ti.template(), periodic: ti.template(), two_level: ti.template(), uniform: ti.template(), side,
             every: ti.template(), serial: ti.template()):
    """Resolve the mutual approaching picks that involve a circle of this round's list, and list
    the circles whose picks that changes for the next round (the other list, which is empty on
    entry); this round's list is emptied after."""
    ti.loop_config(serialize=serial)
    for a in range(_round_items(work, side, pos.shape[0], every)):
        _resolve_item(a, pos, vel, radius, inv_mass, ids, partner, picked, pair_count, virial, marked, contacts,
                      n_contacts, lists, work, cell_of, cell_start, sorted_ids, ncx, ncy, rows, segs, box_w, box_h,
                      spread, real, periodic, two_level, uniform, side, every)
    # One serial statement group between rounds (each group is a task of its own).
    work[ROUND] += 1
    work[LIST0 + side] = 0


@ti.func
def _resolve_item(a, pos: ti.template(), vel: ti.template(), radius: ti.template(), inv_mass: ti.template(),
                  ids: ti.template(), partner: ti.template(), picked: ti.template(), pair_count: ti.template(),
                  virial: ti.template(), marked: ti.template(), contacts: ti.template(), n_contacts: ti.template(),
                  lists: ti.template(), work: ti.template(), cell_of: ti.template(), cell_start: ti.template(),
                  sorted_ids: ti.template(), ncx, ncy, rows, segs, box_w, box_h, spread: ti.template(),
                  real: ti.template(), periodic: ti.template(), two_level: ti.template(), uniform: ti.template(), side,
                  every: ti.template()):
    """Item a of `_resolve`'s loop."""
    box = ti.Vector([box_w, box_h], dt=real)
    rnd = work[ROUND]
    i, take = _listed(a, rnd, picked, lists, side, every)
    if take:
        _resolve_one(i, rnd, pos, vel, radius, inv_mass, ids, partner, picked, pair_count, virial, marked, contacts,
                     n_contacts, lists, work, cell_of, cell_start, sorted_ids, ncx, ncy, rows, segs, box, spread, real,
                     periodic, two_level, uniform, side)


@ti.func
def _wall(i, pos: ti.template(), vel: ti.template(), radius: ti.template(), inv_mass: ti.template(),
          wall_count: ti.template(), wall_impulse: ti.template(), box, uniform: ti.template()):
    """Reflect circle i off the walls it reaches past: mirror the position, and flip the normal
    velocity when it points outwards."""
    x = pos[i]
    v = vel[i]
    r = per_circle(i, radius, uniform)
    for a in ti.static(range(2)):
        lo = r
        hi = box[a] - r
        hit = False
        if x[a] < lo:
            x[a] = ti.min(2 * lo - x[a], hi)
            hit = v[a] < 0
            if hit:
                v[a] = -v[a]
        elif x[a] > hi:
            x[a] = ti.max(2 * hi - x[a], lo)
            hit = v[a] > 0
            if hit:
                v[a] = -v[a]
        if hit:
            wall_count[i] = wall_count[i] + 1
            wall_impulse[i] = wall_impulse[i] + (2.0 * ti.abs(ti.cast(v[a], ti.f64))
                                                 / ti.cast(per_circle(i, inv_mass, uniform), ti.f64))
    pos[i] = x
    vel[i] = v


@ti.func
def _walls(pos: ti.template(), vel: ti.template(), radius: ti.template(), inv_mass: ti.template(),
           wall_count: ti.template(), wall_impulse: ti.template(), walled: ti.template(), work: ti.template(),
           box_w, box_h, real: ti.template(), uniform: ti.template(), settled_only: ti.template(),
           serial: ti.template()):
    """The wall reflections of the listed circles; with `settled_only`, only when the rounds are
    over (the next round's list, list 0 after an even number of rounds, is empty; otherwise
    more rounds come first)."""
    ti.loop_config(serialize=serial)
    for k in range(work[WALLED]):
        box = ti.Vector([box_w, box_h], dt=real)
        if not ti.static(settled_only) or work[LIST0] == 0:
            _wall(walled[k], pos, vel, radius, inv_mass, wall_count, wall_impulse, box, uniform)


@launch.kernel
def walls(pos: ndarr, vel: ndarr, radius: ndarr, inv_mass: ndarr, wall_count: ndarr, wall_impulse: ndarr,
          walled: ndarr, work: ndarr, box_w: ti.f64, box_h: ti.f64, real: ti.template(), uniform: ti.template()):
    """The wall reflections after rounds that stopped at the round limit."""
    _walls(pos, vel, radius, inv_mass, wall_count, wall_impulse, walled, work, box_w, box_h, real, uniform, False,
           False)


@ti.func
def _rounds(pos: ti.template(), vel: ti.template(), radius: ti.template(), inv_mass: ti.template(),
            ids: ti.template(), partner: ti.template(), picked: ti.template(),
            marked: ti.template(), contacts: ti.template(), n_contacts: ti.template(), lists: ti.template(),
            work: ti.template(), pair_count: ti.template(), virial: ti.template(), cell_of: ti.template(),
            cell_start: ti.template(), sorted_ids: ti.template(), ncx, ncy, rows, segs, box_w, box_h,
            spread: ti.template(), real: ti.template(), periodic: ti.template(), two_level: ti.template(),
            uniform: ti.template(), rounds: ti.template(), first_every: ti.template(), serial_from: ti.template(),
            first_parts: ti.template()):
    """`rounds` rounds of pick and resolve, alternating between the two work lists (`rounds` is
    even, so every launch starts on list 0); a round after one that listed nothing has an
    empty list, so it costs two empty loops. With `first_every` the first round loops over
    every circle instead of its list (`_listed`).

    Rounds before `serial_from` (counted within this launch) are top-level loops, which run in
    parallel; the rounds from `serial_from` on (see `simulation.DISCRETE_PARALLEL_ROUNDS`) run
    on one thread, as one serial loop over the rounds, so their code is compiled once, not
    once per round (a step of a small scene is all serial: its kernel compiles in a fraction
    of the time). With `first_parts` (a CPU, the first round parallel) the first round runs in
    parts (`_first_round_in_parts`)."""
    # The first round of a step loops over every circle: always a code of its own.
    unrolled = ti.static(max(min(serial_from, rounds), 1 if first_every else 0))
    for r in ti.static(range(unrolled)):
        every = ti.static(first_every and r == 0)
        serial = ti.static(r >= serial_from)
        if ti.static(every and first_parts and not serial):
            _first_round_in_parts(pos, vel, radius, inv_mass, ids, partner, picked, pair_count, virial, marked,
                                  contacts, n_contacts, lists, work, cell_of, cell_start, sorted_ids, ncx, ncy, rows,
                                  segs, box_w, box_h, spread, real, periodic, two_level, uniform)
        else:
            _pick(pos, vel, radius, inv_mass, ids, partner, picked, pair_count, virial, contacts, n_contacts, lists,
                  work, cell_of, cell_start, sorted_ids, ncx, ncy, rows, segs, box_w, box_h, spread, real, periodic,
                  two_level, uniform, r % 2, marked, every, serial)
            _resolve(pos, vel, radius, inv_mass, ids, partner, picked, pair_count, virial, marked, contacts,
                     n_contacts, lists, work, cell_of, cell_start, sorted_ids, ncx, ncy, rows, segs, box_w, box_h,
                     spread, real, periodic, two_level, uniform, r % 2, every, serial)
    if ti.static(unrolled < rounds):
        ti.loop_config(serialize=True)
        for r in range(unrolled, rounds):
            _pick(pos, vel, radius, inv_mass, ids, partner, picked, pair_count, virial, contacts, n_contacts, lists,
                  work, cell_of, cell_start, sorted_ids, ncx, ncy, rows, segs, box_w, box_h, spread, real, periodic,
                  two_level, uniform, r % 2, marked, False, True)
            _resolve(pos, vel, radius, inv_mass, ids, partner, picked, pair_count, virial, marked, contacts,
                     n_contacts, lists, work, cell_of, cell_start, sorted_ids, ncx, ncy, rows, segs, box_w, box_h,
                     spread, real, periodic, two_level, uniform, r % 2, False, True)


@ti.func
def _rounds_then_walls(pos: ti.template(), vel: ti.template(), radius: ti.template(), inv_mass: ti.template(),
                       ids: ti.template(), partner: ti.template(), picked: ti.template(), marked: ti.template(),
                       contacts: ti.template(), n_contacts: ti.template(), lists: ti.template(), work: ti.template(),
                       pair_count: ti.template(), virial: ti.template(), wall_count: ti.template(),
                       wall_impulse: ti.template(), walled: ti.template(), cell_of: ti.template(),
                       cell_start: ti.template(), sorted_ids: ti.template(), ncx, ncy, rows, segs, box_w, box_h,
                       spread: ti.template(), real: ti.template(), periodic: ti.template(), two_level: ti.template(),
                       uniform: ti.template(), rounds: ti.template(), first_every: ti.template(),
                       serial_from: ti.template(), first_parts: ti.template()):
    """`rounds` rounds, then the wall reflections if they settled (the end of both launches);
    the walls' loop is serial when the last round's is (a few circles per thousand reach a wall)."""
    _rounds(pos, vel, radius, inv_mass, ids, partner, picked, marked, contacts, n_contacts, lists, work,
            pair_count, virial, cell_of, cell_start, sorted_ids, ncx, ncy, rows, segs, box_w, box_h, spread, real,
            periodic, two_level, uniform, rounds, first_every, serial_from, first_parts)
    if ti.static(not periodic):
        _walls(pos, vel, radius, inv_mass, wall_count, wall_impulse, walled, work, box_w, box_h, real, uniform, True,
               serial_from < rounds)


@launch.kernel
def begin_step(pos: ndarr, vel: ndarr, radius: ndarr, inv_mass: ndarr, ids: ndarr, partner: ndarr, picked: ndarr,
               marked: ndarr, contacts: ti.types.ndarray(ndim=2), n_contacts: ndarr,
               lists: ti.types.ndarray(ndim=2), work: ndarr, pair_count: ndarr, virial: ndarr, wall_count: ndarr,
               wall_impulse: ndarr, walled: ndarr, cell_of: ndarr, slot: ndarr, cell_count: ndarr, cell_start: ndarr,
               sorted_ids: ndarr, ncx: ti.i32, ncy: ti.i32, inv_cw: ti.f64, inv_ch: ti.f64, transposed: ti.i32,
               rows: ti.i32,
               segs: ti.i32, dt: ti.f64, box_w: ti.f64, box_h: ti.f64, spread: ndarr, large: ndarr, parts: ndarr,
               real: ti.template(), periodic: ti.template(), two_level: ti.template(), uniform: ti.template(),
               rounds: ti.template(), serial_from: ti.template(), first_parts: ti.template()) -> ti.i32:
    """Move, grid, the first `rounds` rounds of pair resolution and, when they settle, the walls,
    in one launch (launches cost tens of microseconds each, which is the whole step for a few
    thousand circles). Returns the length of the next round's work list: not 0 when more
    rounds are needed (the walls wait for them). With `uniform`, every circle has the radius
    and the mass of the first (`per_circle`); with `first_parts`, the first round runs in parts
    (`_first_round_in_parts`)."""
    # serial_from = 0: the whole step on one thread (see backend.serial_loops).
    serial = ti.static(serial_from == 0)
    _move(pos, vel, radius, n_contacts, walled, work, cell_of, slot, cell_count, sorted_ids, parts, ncx, ncy, inv_cw,
          inv_ch, transposed, dt, box_w, box_h, real, periodic, uniform, serial)
    finish_cells(cell_of, slot, cell_count, cell_start, sorted_ids, ncx, ncy, periodic, serial)
    _scan_contacts(pos, vel, radius, contacts, n_contacts, marked, work, cell_of, cell_start,
                   sorted_ids, ncx, ncy, rows, segs, box_w, box_h, spread, large, real, periodic, two_level, uniform,
                   serial)
    _rounds_then_walls(pos, vel, radius, inv_mass, ids, partner, picked, marked, contacts, n_contacts, lists, work,
                       pair_count, virial, wall_count, wall_impulse, walled, cell_of, cell_start, sorted_ids, ncx, ncy,
                       rows, segs, box_w, box_h, spread, real, periodic, two_level, uniform, rounds, True, serial_from,
                       first_parts)
    return work[LIST0]


@launch.kernel
def serial_steps(pos: ndarr, vel: ndarr, radius: ndarr, inv_mass: ndarr, ids: ndarr, partner: ndarr, picked: ndarr,
                 marked: ndarr, contacts: ti.types.ndarray(ndim=2), n_contacts: ndarr,
                 lists: ti.types.ndarray(ndim=2), work: ndarr, pair_count: ndarr, virial: ndarr, wall_count: ndarr,
                 wall_impulse: ndarr, walled: ndarr, cell_of: ndarr, slot: ndarr, cell_count: ndarr,
                 cell_start: ndarr, sorted_ids: ndarr, ncx: ti.i32, ncy: ti.i32, inv_cw: ti.f64, inv_ch: ti.f64,
                 transposed: ti.i32, rows: ti.i32, segs: ti.i32, dt: ti.f64, box_w: ti.f64, box_h: ti.f64,
                 spread: ndarr, large: ndarr,
                 parts: ndarr, steps: ti.i32, real: ti.template(), periodic: ti.template(),
                 two_level: ti.template(), uniform: ti.template(), rounds: ti.template()) -> ti.i32:
    """Up to `steps` steps of `begin_step` on one thread (`serial_from` 0), in one launch: a
    launch and its call cost some 20 microseconds, the whole step of a few hundred circles and
    a tenth of one of 1e4. The steps are `begin_step`'s, one after another, bit for bit. It
    stops after a step whose `rounds` rounds did not settle. Returns the steps begun, negated
    when the last of them needs more rounds (`more_rounds`; its walls wait for them)."""
    done = 0
    busy = 0
    ti.loop_config(serialize=True)
    for _ in range(steps):
        _move(pos, vel, radius, n_contacts, walled, work, cell_of, slot, cell_count, sorted_ids, parts, ncx, ncy,
              inv_cw, inv_ch, transposed, dt, box_w, box_h, real, periodic, uniform, True)
        finish_cells(cell_of, slot, cell_count, cell_start, sorted_ids, ncx, ncy, periodic, True)
        _scan_contacts(pos, vel, radius, contacts, n_contacts, marked, work, cell_of, cell_start,
                       sorted_ids, ncx, ncy, rows, segs, box_w, box_h, spread, large, real, periodic, two_level,
                       uniform, True)
        _rounds_then_walls(pos, vel, radius, inv_mass, ids, partner, picked, marked, contacts, n_contacts, lists,
                           work, pair_count, virial, wall_count, wall_impulse, walled, cell_of, cell_start,
                           sorted_ids, ncx, ncy, rows, segs, box_w, box_h, spread, real, periodic, two_level,
                           uniform, rounds, True, 0, False)
        done += 1
        if work[LIST0] != 0:
            busy = 1
            break
    return ti.select(busy != 0, -done, done)


@launch.kernel
def more_rounds(pos: ndarr, vel: ndarr, radius: ndarr, inv_mass: ndarr, ids: ndarr, partner: ndarr, picked: ndarr,
                marked: ndarr, contacts: ti.types.ndarray(ndim=2), n_contacts: ndarr,
                lists: ti.types.ndarray(ndim=2), work: ndarr, pair_count: ndarr, virial: ndarr, wall_count: ndarr,
                wall_impulse: ndarr, walled: ndarr, cell_of: ndarr, cell_start: ndarr, sorted_ids: ndarr,
                ncx: ti.i32, ncy: ti.i32, rows: ti.i32, segs: ti.i32, box_w: ti.f64, box_h: ti.f64, spread: ndarr,
                real: ti.template(), periodic: ti.template(), two_level: ti.template(), uniform: ti.template(),
                rounds: ti.template(), serial_from: ti.template()) -> ti.i32:
    """`rounds` more rounds, then the walls when they settle; returns as `begin_step`."""
    _rounds_then_walls(pos, vel, radius, inv_mass, ids, partner, picked, marked, contacts, n_contacts, lists, work,
                       pair_count, virial, wall_count, wall_impulse, walled, cell_of, cell_start, sorted_ids, ncx, ncy,
                       rows, segs, box_w, box_h, spread, real, periodic, two_level, uniform, rounds, False, serial_from,
                       False)
    return work[LIST0]


@launch.kernel
def list_large(radius: ndarr, r_cut: ti.f64, large: ndarr, work: ndarr):
    """The slots of the circles larger than r_cut (in any order), work[NLARGE] of them."""
    work[NLARGE] = 0
    for i in range(radius.shape[0]):
        if ti.cast(radius[i], ti.f64) > r_cut:
            large[ti.atomic_add(work[NLARGE], 1)] = i


#: Items per chunk of a team step's stages (`team_step`): slots of the overlap search and the
#: scatter, and entries of a round's work list or of the walls' list.
TEAM_SLOTS = 2048
TEAM_LIST = 64


@ti.func
def _team_move(c, a: ti.template()):
    count_part(c, a[0][0].shape[0], _moved, _keep_moved, *a)


@ti.func
def _team_strays(c, a: ti.template()):
    count_strays(a[0].shape[0], *a)


@ti.func
def _team_totals(c, a: ti.template()):
    chunk_total(c, *a)


@ti.func
def _team_ends(c, a: ti.template()):
    chunk_ends(*a)
    a[0][0] = 0


@ti.func
def _team_starts(c, a: ti.template()):
    chunk_starts(c, *a)


@ti.func
def _team_scatter(c, a: ti.template()):
    g = ti.static(CPU_GROUP)
    lo, hi = span(c, chunks_of(a[0].shape[0], g), TEAM_SLOTS // g)
    for q in range(lo, hi):
        scatter_group(q, *a)


@ti.func
def _team_scan(c, a: ti.template()):
    lo, hi = span(c, a[0].shape[0], TEAM_SLOTS)
    for own in range(lo, hi):
        _scan_slot(own, *a)


@ti.func
def _team_scan_large(c, a: ti.template()):
    lo, hi = span(c, a[6][NLARGE], TEAM_LIST)
    for k in range(lo, hi):
        _scan_large(k, *a)


@ti.func
def _team_first_pick(c, a: ti.template()):
    _first_pick_part(c, *a)


@ti.func
def _team_first_resolve(c, a: ti.template()):
    _first_resolve_part(c, *a)


@ti.func
def _team_pick(c, a: ti.template()):
    lo, hi = span(c, a[0], TEAM_LIST)
    for q in range(lo, hi):
        _pick_item(q, *a[1:])


@ti.func
def _team_resolve(c, a: ti.template()):
    lo, hi = span(c, a[0], TEAM_LIST)
    for q in range(lo, hi):
        _resolve_item(q, *a[1:])


@ti.func
def _team_next_round(c, a: ti.template()):
    """The statements between rounds (`_resolve`'s last), and the length of the next round's
    list kept in the team's values for its stages' counts (the list's own counter changes
    within the next round)."""
    work, sync, side, r = ti.static(a)
    work[ROUND] += 1
    work[LIST0 + side] = 0
    sync[value_slot(r + 1)] = work[LIST0 + 1 - side]


@ti.func
def _team_walls(c, a: ti.template()):
    walled, work, pos, vel, radius, inv_mass, wall_count, wall_impulse, box_w, box_h, real, uniform = ti.static(a)
    lo, hi = span(c, work[WALLED], TEAM_LIST)
    if work[LIST0] == 0:  # the rounds settled
        for k in range(lo, hi):
            box = ti.Vector([box_w, box_h], dt=real)
            _wall(walled[k], pos, vel, radius, inv_mass, wall_count, wall_impulse, box, uniform)


@launch.kernel
def team_step(pos: ndarr, vel: ndarr, radius: ndarr, inv_mass: ndarr, ids: ndarr, partner: ndarr, picked: ndarr,
              marked: ndarr, contacts: ti.types.ndarray(ndim=2), n_contacts: ndarr,
              lists: ti.types.ndarray(ndim=2), work: ndarr, pair_count: ndarr, virial: ndarr, wall_count: ndarr,
              wall_impulse: ndarr, walled: ndarr, cell_of: ndarr, slot: ndarr, cell_count: ndarr, cell_start: ndarr,
              sorted_ids: ndarr, ncx: ti.i32, ncy: ti.i32, inv_cw: ti.f64, inv_ch: ti.f64, transposed: ti.i32,
              rows: ti.i32, segs: ti.i32, dt: ti.f64, box_w: ti.f64, box_h: ti.f64, spread: ndarr, large: ndarr,
              parts: ndarr, sync: ndarr, real: ti.template(), periodic: ti.template(), two_level: ti.template(),
              uniform: ti.template(), rounds: ti.template(), serial: ti.template()) -> ti.i32:
    """`begin_step` on a CPU's threads as one team (`circles.team`): the same stages, the same
    state bit for bit, with one start of the thread pool instead of one per loop. The first
    round runs in parts (`_first_round_in_parts`), the later `rounds` - 1 in chunks of their
    lists. `sync`: the team's counters (team.sync_slots()). With `serial` the team's loop runs on the
    calling thread, its members one after another (the first does every chunk, the others find
    them done): for tests of that claim of `circles.team`."""
    ti.static_assert(11 + 3 * rounds <= STAGES)
    n = pos.shape[0]
    ncells = cells_in(ncx, ncy, periodic)
    ti.loop_config(serialize=True)
    for _ in range(1):
        clear(sync)
        work[WALLED] = 0
        # As `_scan_contacts` begins.
        work[ROUND] += 1
        work[LIST0] = 0
        work[LIST1] = 0
        owned_starts(n, cell_of, parts, ncx, ncy, periodic)
    ti.loop_config(serialize=serial)
    for it in range(ti.static(loop_iterations())):
        me = member_of(it)
        if me >= 0:
            np_ = ti.static(count_parts())
            moved = ti.static((pos, vel, radius, n_contacts, walled, work, ti.cast(dt, real), box_w, box_h, real,
                               periodic, uniform))
            stage(sync, 0, np_, _team_move, (moved, cell_of, slot, cell_count, sorted_ids, parts, ncx, ncy, inv_cw,
                                             inv_ch, transposed, real, periodic), me)
            stage(sync, 1, 1, _team_strays, (cell_of, slot, cell_count, sorted_ids, parts), me)
            nchunks = chunks_of(ncells, ti.static(_scan_shape()[0]))
            stage(sync, 2, nchunks, _team_totals, (cell_count, cell_start, ncells), me)
            stage(sync, 3, 1, _team_ends, (cell_start, ncells), me)
            stage(sync, 4, nchunks, _team_starts, (cell_count, cell_start, ncells), me)
            stage(sync, 5, chunks_of(n, TEAM_SLOTS), _team_scatter, (cell_of, slot, cell_start, sorted_ids), me)
            stage(sync, 6, chunks_of(n, TEAM_SLOTS), _team_scan,
                  (pos, vel, radius, contacts, n_contacts, marked, work, cell_of, cell_start, sorted_ids, ncx, ncy,
                   rows, segs, box_w, box_h, spread, real, periodic, two_level, uniform), me)
            if ti.static(two_level):
                stage(sync, 7, chunks_of(work[NLARGE], TEAM_LIST), _team_scan_large,
                      (pos, vel, radius, contacts, n_contacts, marked, work, cell_of, cell_start, sorted_ids, ncx,
                       ncy, rows, segs, box_w, box_h, spread, large, real, periodic, two_level, uniform), me)
            first = ti.static((pos, vel, radius, inv_mass, ids, partner, picked, pair_count, virial, marked, contacts,
                     n_contacts, lists, work, cell_of, cell_start, sorted_ids, ncx, ncy, rows, segs, box_w, box_h,
                     spread, real, periodic, two_level, uniform))
            stage(sync, 8, np_, _team_first_pick, first, me)
            stage(sync, 9, np_, _team_first_resolve, first, me)
            stage(sync, 10, 1, _team_next_round, (work, sync, 0, 0), me)
            for r in range(1, rounds):
                side = r % 2
                s = 11 + 3 * (r - 1)
                items = sync[value_slot(r)]
                chunks = chunks_of(items, TEAM_LIST)
                stage(sync, s, chunks, _team_pick,
                      (items, pos, vel, radius, inv_mass, ids, partner, picked, pair_count, virial, contacts,
                       n_contacts, lists, work, cell_of, cell_start, sorted_ids, ncx, ncy, rows, segs, box_w, box_h,
                       spread, real, periodic, two_level, uniform, side, marked, False), me)
                stage(sync, s + 1, chunks, _team_resolve,
                      (items, pos, vel, radius, inv_mass, ids, partner, picked, pair_count, virial, marked, contacts,
                       n_contacts, lists, work, cell_of, cell_start, sorted_ids, ncx, ncy, rows, segs, box_w, box_h,
                       spread, real, periodic, two_level, uniform, side, False), me)
                stage(sync, s + 2, 1, _team_next_round, (work, sync, side, r), me)
            if ti.static(not periodic):
                stage(sync, ti.static(11 + 3 * (rounds - 1)), chunks_of(work[WALLED], TEAM_LIST), _team_walls,
                      (walled, work, pos, vel, radius, inv_mass, wall_count, wall_impulse, box_w, box_h, real,
                       uniform), me)
    return work[LIST0]
