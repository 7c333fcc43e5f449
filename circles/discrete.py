"""Scheme "discrete": the fast approximate baseline (the original assignment's method).

A step moves every circle by v dt, then resolves overlapping approaching pairs with the exact
elastic impulse, then reflects circles that crossed a wall by mirroring their position.
Pairs are resolved race-free and deterministically: in each round every circle picks, among
its overlapping approaching neighbours, the pair that touched first (largest overlap over
approach speed, ties by ids), and mutual picks are resolved together. The pair with the
smallest key overall is always mutual, so each round resolves at least one pair. After the
first round only circles overlapping a resolved circle pick again; the others' picks still hold.

Known errors of the method, which the benchmark measures: a circle faster than about a
diameter per step can pass through another (tunnelling), overlap is left behind, and
collisions can be missed or counted twice.
"""
import taichi as ti

from .geometry import NEVER, displacement, key_less, neighbour_range
from .grid import build_cells

ndarr = ti.types.ndarray(ndim=1)


@ti.func
def _move(pos: ti.template(), vel: ti.template(), dt, box_w, box_h, real: ti.template(), periodic: ti.template()):
    box = ti.Vector([box_w, box_h], dt=real)
    h = ti.cast(dt, real)
    for i in range(pos.shape[0]):
        x = pos[i] + vel[i] * h
        if ti.static(periodic):
            x -= box * ti.floor(x / box)
            for a in ti.static(range(2)):
                if x[a] >= box[a]:
                    x[a] -= box[a]
        pos[i] = x


@ti.func
def _consider(i, j, pos: ti.template(), vel: ti.template(), radius: ti.template(), ids: ti.template(), box,
              best, best_lo, best_hi, best_p, periodic: ti.template()):
    """The pick of i updated with its pair with j; returns (key, lo id, hi id, partner, overlapping)."""
    lo = ti.min(i, j)
    hi = ti.max(i, j)
    d = displacement(pos[lo], pos[hi], box, periodic)
    s = radius[lo] + radius[hi]
    dist2 = d.dot(d)
    overlapping = dist2 < s * s
    if overlapping:
        dist = ti.sqrt(dist2)
        vn = (vel[hi] - vel[lo]).dot(d) / ti.max(dist, s * 1e-30)
        if vn < 0:
            # -(time since first contact at the current speeds): earliest first.
            key = -(s - dist) / (-vn)
            klo = ti.min(ids[i], ids[j])
            khi = ti.max(ids[i], ids[j])
            if key_less(key, klo, khi, best, best_lo, best_hi):
                best, best_lo, best_hi, best_p = key, klo, khi, j
    return best, best_lo, best_hi, best_p, overlapping


@ti.func
def _pick(pos: ti.template(), vel: ti.template(), radius: ti.template(), ids: ti.template(), partner: ti.template(),
          key_t: ti.template(), dirty: ti.template(), contacts: ti.template(), n_contacts: ti.template(),
          cell_of: ti.template(), cell_start: ti.template(), sorted_ids: ti.template(), ncx, ncy, rows, segs, box_w,
          box_h, counters: ti.template(), real: ti.template(), periodic: ti.template(), scan: ti.template()):
    """Each dirty circle picks its overlapping approaching pair of smallest key.

    With `scan` (the first round of a step) every circle searches its 3 x 3 cells and keeps
    its overlapping neighbours in `contacts` (up to contacts.shape[1]; more is marked by
    a count above that, and such a circle searches its cells again in later rounds). Later
    rounds only look through the contact lists: positions do not change within a step.
    """
    n = pos.shape[0]
    cap = contacts.shape[1]
    box = ti.Vector([box_w, box_h], dt=real)
    counters[0] = 0
    for i in range(n):
        # A circle keeps its pick unless a circle overlapping it was resolved (see resolve).
        if dirty[i] == 0:
            continue
        dirty[i] = 0
        best = ti.cast(NEVER, real)
        best_lo = n
        best_hi = n
        best_p = -1
        listed = n_contacts[i]
        if ti.static(scan):
            listed = 0
        if not ti.static(scan) and listed <= cap:
            for m in range(listed):
                best, best_lo, best_hi, best_p, _ = _consider(i, contacts[i, m], pos, vel, radius, ids, box, best,
                                                              best_lo, best_hi, best_p, periodic)
        else:
            c = cell_of[i]
            for row, seg in ti.ndrange(rows, segs):
                k_lo, k_hi = neighbour_range(c, row, seg, cell_start, ncx, ncy, periodic)
                for k in range(k_lo, k_hi):
                    j = sorted_ids[k]
                    if j != i:
                        best, best_lo, best_hi, best_p, overlapping = _consider(
                            i, j, pos, vel, radius, ids, box, best, best_lo, best_hi, best_p, periodic)
                        if ti.static(scan):
                            if overlapping:
                                if listed < cap:
                                    contacts[i, listed] = j
                                listed += 1
            if ti.static(scan):
                n_contacts[i] = ti.min(listed, cap + 1)
        partner[i] = best_p
        key_t[i] = best


@ti.func
def mark_overlapping_dirty(i, pos: ti.template(), radius: ti.template(), dirty: ti.template(),
                           contacts: ti.template(), n_contacts: ti.template(), cell_of: ti.template(),
                           cell_start: ti.template(), sorted_ids: ti.template(), ncx, ncy, rows, segs, box,
                           periodic: ti.template()):
    """Mark i and every circle overlapping it for a new pick.

    Positions do not move between rounds, so only pairs with i can change their key when i's
    velocity changes, and only overlapping pairs have a key: other circles' picks still hold.
    """
    dirty[i] = 1
    listed = n_contacts[i]
    if listed <= contacts.shape[1]:
        for m in range(listed):
            dirty[contacts[i, m]] = 1
    else:
        c = cell_of[i]
        for row, seg in ti.ndrange(rows, segs):
            k_lo, k_hi = neighbour_range(c, row, seg, cell_start, ncx, ncy, periodic)
            for k in range(k_lo, k_hi):
                j = sorted_ids[k]
                d = displacement(pos[i], pos[j], box, periodic)
                s = radius[i] + radius[j]
                if d.dot(d) < s * s:
                    dirty[j] = 1


@ti.func
def _resolve(pos: ti.template(), vel: ti.template(), radius: ti.template(), inv_mass: ti.template(),
             ids: ti.template(), partner: ti.template(), pair_count: ti.template(), virial: ti.template(),
             dirty: ti.template(), contacts: ti.template(), n_contacts: ti.template(), cell_of: ti.template(),
             cell_start: ti.template(), sorted_ids: ti.template(), ncx, ncy, rows, segs, box_w, box_h,
             counters: ti.template(), real: ti.template(), periodic: ti.template()):
    box = ti.Vector([box_w, box_h], dt=real)
    for i in range(pos.shape[0]):
        j = partner[i]
        if j > i and partner[j] == i:
            d = displacement(pos[i], pos[j], box, periodic)
            nrm = d.normalized()
            vn = (vel[j] - vel[i]).dot(nrm)
            if vn < 0:
                wi = inv_mass[i]
                wj = inv_mass[j]
                jmp = 2.0 * vn / (wi + wj)
                # Same expression for both circles: rounding does not depend on which one is i.
                vel[i] = vel[i] + (wi * jmp) * nrm
                vel[j] = vel[j] + (wj * jmp) * (-nrm)
                # Plain updates, not atomics: a circle is in at most one executed pair per round.
                owner = i if ids[i] < ids[j] else j
                pair_count[owner] = pair_count[owner] + 1
                virial[owner] = virial[owner] + ti.cast(radius[i] + radius[j], ti.f64) * ti.abs(ti.cast(jmp, ti.f64))
                if counters[0] == 0:
                    # "Something was resolved": a plain store, read first so the shared cache line
                    # is written once, not bounced between cores for every pair.
                    counters[0] = 1
                mark_overlapping_dirty(i, pos, radius, dirty, contacts, n_contacts, cell_of, cell_start, sorted_ids,
                                       ncx, ncy, rows, segs, box, periodic)
                mark_overlapping_dirty(j, pos, radius, dirty, contacts, n_contacts, cell_of, cell_start, sorted_ids,
                                       ncx, ncy, rows, segs, box, periodic)


@ti.kernel
def walls(pos: ndarr, vel: ndarr, radius: ndarr, inv_mass: ndarr, wall_count: ndarr, wall_impulse: ndarr,
          box_w: ti.f64, box_h: ti.f64, real: ti.template()):
    box = ti.Vector([box_w, box_h], dt=real)
    for i in range(pos.shape[0]):
        x = pos[i]
        v = vel[i]
        r = radius[i]
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
                wall_impulse[i] = wall_impulse[i] + 2.0 * ti.abs(ti.cast(v[a], ti.f64)) / ti.cast(inv_mass[i], ti.f64)
        pos[i] = x
        vel[i] = v


@ti.func
def _rounds(pos: ti.template(), vel: ti.template(), radius: ti.template(), inv_mass: ti.template(),
            ids: ti.template(), partner: ti.template(), key_t: ti.template(), dirty: ti.template(),
            contacts: ti.template(), n_contacts: ti.template(), pair_count: ti.template(), virial: ti.template(),
            cell_of: ti.template(), cell_start: ti.template(), sorted_ids: ti.template(), ncx, ncy, rows, segs,
            box_w, box_h, counters: ti.template(), real: ti.template(), periodic: ti.template(),
            rounds: ti.template(), first_scans: ti.template()):
    """`rounds` rounds of pick and resolve as top-level loops; a round after one that resolved
    nothing finds no dirty circle and no mutual approaching pick, so it changes nothing."""
    for r in ti.static(range(rounds)):
        _pick(pos, vel, radius, ids, partner, key_t, dirty, contacts, n_contacts, cell_of, cell_start, sorted_ids,
              ncx, ncy, rows, segs, box_w, box_h, counters, real, periodic, ti.static(first_scans and r == 0))
        _resolve(pos, vel, radius, inv_mass, ids, partner, pair_count, virial, dirty, contacts, n_contacts,
                 cell_of, cell_start, sorted_ids, ncx, ncy, rows, segs, box_w, box_h, counters, real, periodic)


@ti.kernel
def begin_step(pos: ndarr, vel: ndarr, radius: ndarr, inv_mass: ndarr, ids: ndarr, partner: ndarr, key_t: ndarr,
               dirty: ndarr, contacts: ti.types.ndarray(ndim=2), n_contacts: ndarr, pair_count: ndarr,
               virial: ndarr, mask: ndarr, cell_of: ndarr, slot: ndarr, cell_count: ndarr, cell_start: ndarr,
               sorted_ids: ndarr, ncx: ti.i32, ncy: ti.i32, inv_cw: ti.f64, inv_ch: ti.f64, rows: ti.i32,
               segs: ti.i32, dt: ti.f64, box_w: ti.f64, box_h: ti.f64, counters: ndarr, real: ti.template(),
               periodic: ti.template(), rounds: ti.template()) -> ti.i32:
    """Move, grid and the first `rounds` rounds of pair resolution, in one launch (launches cost
    tens of microseconds each, which is the whole step for a few thousand circles). Returns 1
    when the last round resolved a pair (more rounds may be needed), else 0."""
    _move(pos, vel, dt, box_w, box_h, real, periodic)
    build_cells(pos, mask, cell_of, slot, cell_count, cell_start, sorted_ids, ncx, ncy, inv_cw, inv_ch, False)
    for i in range(pos.shape[0]):
        dirty[i] = 1
    _rounds(pos, vel, radius, inv_mass, ids, partner, key_t, dirty, contacts, n_contacts, pair_count, virial,
            cell_of, cell_start, sorted_ids, ncx, ncy, rows, segs, box_w, box_h, counters, real, periodic, rounds,
            True)
    return counters[0]


@ti.kernel
def more_rounds(pos: ndarr, vel: ndarr, radius: ndarr, inv_mass: ndarr, ids: ndarr, partner: ndarr, key_t: ndarr,
                dirty: ndarr, contacts: ti.types.ndarray(ndim=2), n_contacts: ndarr, pair_count: ndarr,
                virial: ndarr, cell_of: ndarr, cell_start: ndarr, sorted_ids: ndarr, ncx: ti.i32, ncy: ti.i32,
                rows: ti.i32, segs: ti.i32, box_w: ti.f64, box_h: ti.f64, counters: ndarr, real: ti.template(),
                periodic: ti.template(), rounds: ti.template()) -> ti.i32:
    _rounds(pos, vel, radius, inv_mass, ids, partner, key_t, dirty, contacts, n_contacts, pair_count, virial,
            cell_of, cell_start, sorted_ids, ncx, ncy, rows, segs, box_w, box_h, counters, real, periodic, rounds,
            False)
    return counters[0]
