"""The discrete scheme's move and its search for overlapping pairs: the shared work slots,
each circle's contact list, the two-level grid's large circles."""
import taichi as ti

from ..geometry import displacement, forward_fits, forward_range, neighbour_range, pairs_once, run_parts, wide_row
from ..grid import enter_cells

#: Slots of the `work` array: the round number, the lengths of the two work lists, the
#: number of circles reaching past a wall, the number of large circles (two-level grid), and
#: from PART_PICKS on, one per CPU part, the picks of the part's first round (`_first_round_in_parts`).
ROUND, LIST0, LIST1, WALLED, NLARGE, PART_PICKS = 0, 1, 2, 3, 4, 5
#: The longest contact list a circle may have (stepper.DISCRETE_CONTACTS is its length):
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
