"""Scheme "discrete": the fast approximate baseline (the original assignment's method).

A step moves every circle by v dt, then resolves overlapping approaching pairs with the exact
elastic impulse, then reflects circles that crossed a wall by mirroring their position.
Pairs are resolved race-free and deterministically: in each round every circle picks, among
its overlapping approaching neighbours, the pair that touched first (largest overlap over
approach speed, ties by ids), and mutual picks are resolved together. The pair with the
smallest key overall is always mutual, so each round resolves at least one pair. After the
first round only circles next to a resolved pair pick again; the others' picks still hold.

Known errors of the method, which the benchmark measures: a circle faster than about a
diameter per step can pass through another (tunnelling), overlap is left behind, and
collisions can be missed or counted twice.
"""
import taichi as ti

from .event import mark_neighbours_dirty
from .geometry import NEVER, displacement, key_less, neighbour_cell

ndarr = ti.types.ndarray(ndim=1)


@ti.kernel
def move(pos: ndarr, vel: ndarr, dt: ti.f64, box_w: ti.f64, box_h: ti.f64, real: ti.template(),
         periodic: ti.template()):
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


@ti.kernel
def pick(pos: ndarr, vel: ndarr, radius: ndarr, ids: ndarr, partner: ndarr, key_t: ndarr, dirty: ndarr,
         cell_of: ndarr, cell_start: ndarr, sorted_ids: ndarr, ncx: ti.i32, ncy: ti.i32, sx: ti.i32, sy: ti.i32,
         box_w: ti.f64, box_h: ti.f64, counters: ndarr, real: ti.template(), periodic: ti.template()):
    n = pos.shape[0]
    box = ti.Vector([box_w, box_h], dt=real)
    counters[0] = 0
    for i in range(n):
        # A circle keeps its pick unless a pair near it was resolved (see resolve).
        if dirty[i] == 0:
            continue
        dirty[i] = 0
        best = ti.cast(NEVER, real)
        best_lo = n
        best_hi = n
        best_p = -1
        c = cell_of[i]
        for a, b in ti.ndrange(sx, sy):
            c2 = neighbour_cell(c, a, b, ncx, ncy, periodic)
            if c2 >= 0:
                for k in range(cell_start[c2], cell_start[c2 + 1]):
                    j = sorted_ids[k]
                    if j != i:
                        lo = ti.min(i, j)
                        hi = ti.max(i, j)
                        d = displacement(pos[lo], pos[hi], box, periodic)
                        s = radius[lo] + radius[hi]
                        dist2 = d.dot(d)
                        if dist2 < s * s:
                            dist = ti.sqrt(dist2)
                            vn = (vel[hi] - vel[lo]).dot(d) / ti.max(dist, s * 1e-30)
                            if vn < 0:
                                # -(time since first contact at the current speeds): earliest first.
                                key = -(s - dist) / (-vn)
                                klo = ti.min(ids[i], ids[j])
                                khi = ti.max(ids[i], ids[j])
                                if key_less(key, klo, khi, best, best_lo, best_hi):
                                    best, best_lo, best_hi, best_p = key, klo, khi, j
        partner[i] = best_p
        key_t[i] = best


@ti.kernel
def resolve(pos: ndarr, vel: ndarr, radius: ndarr, inv_mass: ndarr, ids: ndarr, partner: ndarr, pair_count: ndarr,
            virial: ndarr, dirty: ndarr, cell_of: ndarr, cell_start: ndarr, sorted_ids: ndarr, ncx: ti.i32,
            ncy: ti.i32, sx: ti.i32, sy: ti.i32, box_w: ti.f64, box_h: ti.f64, counters: ndarr, real: ti.template(),
            periodic: ti.template()):
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
                owner = i if ids[i] < ids[j] else j
                pair_count[owner] += 1
                virial[owner] += ti.cast(radius[i] + radius[j], ti.f64) * ti.abs(ti.cast(jmp, ti.f64))
                ti.atomic_add(counters[0], 1)
                mark_neighbours_dirty(i, dirty, cell_of, cell_start, sorted_ids, ncx, ncy, sx, sy, periodic)
                mark_neighbours_dirty(j, dirty, cell_of, cell_start, sorted_ids, ncx, ncy, sx, sy, periodic)


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
                wall_count[i] += 1
                wall_impulse[i] += 2.0 * ti.abs(ti.cast(v[a], ti.f64)) / ti.cast(inv_mass[i], ti.f64)
        pos[i] = x
        vel[i] = v
