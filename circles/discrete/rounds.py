"""The discrete scheme's rounds: pick, resolve and the walls, and the kernels of a step."""
import taichi as ti

from .. import launch
from ..geometry import NEVER, displacement
from ..grid import PART_ITERATIONS, _part_range, count_parts, finish_cells
from .contacts import (LIST0, MOST_CONTACTS, NLARGE, PART_PICKS, ROUND, WALLED, _claim, _enlist, _listed, _move,
                       _round_items, _scan_contacts, _search_run, _search_runs, per_circle)

ndarr = ti.types.ndarray(ndim=1)


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
    parallel; the rounds from `serial_from` on (see `stepper.DISCRETE_PARALLEL_ROUNDS`) run
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
