"""A filled lattice with its overlaps removed by parallel Jacobi passes (`relaxed_fill`)."""
import math

import numpy as np
import taichi as ti

from ..geometry import displacement
from .cells import _Cells, _block, _piece, _pieces
from .lattice import hexagonal
from .sampling import CLEARANCE, _draw_key, inside, mix32, stored, uniform

ndarr = ti.types.ndarray(ndim=1)


#: Overlap removal leaves each pushed pair at a random distance of up to this (relative) past contact.
RELAX_GAP = 0.1
#: Each push moves a circle this many times half the way to that distance (both circles of a pair move).
RELAX_FACTOR = 1.75
#: ... down to this, by steps of 0.7, whenever RELAX_PATIENCE passes left more circles in overlap than before.
RELAX_FACTOR_MIN = 0.25
RELAX_PATIENCE = 10
#: Passes of overlap removal before it gives up.
RELAX_PASSES = 2000
#: Circles may move this many radii from where the cells of overlap removal were built.
RELAX_SLACK = 0.5


@ti.func
def _push(i, xi, ri, spans_: ti.template(), pos: ti.template(), rad: ti.template(), sorted_ids: ti.template(), box,
          seed, key, factor, periodic: ti.template()):
    """(push, hit): the sum of the pushes on circle i from the circles of its block that break the gap rule."""
    push = ti.Vector([0.0, 0.0], dt=ti.f64)
    hit = 0
    for q in ti.static(range(6 if periodic else 3)):
        for k in range(spans_[2 * q], spans_[2 * q + 1]):
            j = sorted_ids[k]
            d = displacement(xi, pos[j], box, periodic)
            s = ri + rad[j]
            d2 = d.dot(d)
            if d2 < (s * (1.0 + CLEARANCE)) ** 2 and j != i:
                hit = 1
                lo = ti.min(i, j)
                hi = ti.max(i, j)
                dist = ti.sqrt(d2)
                e = d * (1.0 / dist)
                if dist == 0.0:
                    # Coincident centres: a direction drawn for the pair, opposite for its two circles.
                    a = 2.0 * math.pi * uniform(seed, lo, hi)
                    e = ti.Vector([ti.cos(a), ti.sin(a)], dt=ti.f64)
                    if i > j:
                        e = -e
                # The pair's target distance (the same for both circles), drawn anew each pass.
                u = ti.cast(mix32(mix32(ti.cast(lo, ti.u32) ^ key) ^ ti.cast(hi, ti.u32)), ti.f64) / 4294967296.0
                push -= e * (factor * 0.5 * (s * (1.0 + RELAX_GAP * u) - dist))
    return push, hit


@ti.func
def _mark_block(cx, cy, flags: ti.template(), ncx, ncy, periodic: ti.template()):
    """Set the flags of the 3 x 3 cells around (cx, cy)."""
    for dx, dy in ti.static(ti.ndrange((-1, 2), (-1, 2))):
        ux = cx + dx
        uy = cy + dy
        if ti.static(periodic):
            ux = (ux + ncx) % ncx
            uy = (uy + ncy) % ncy
        if 0 <= ux < ncx and 0 <= uy < ncy:
            flags[uy * ncx + ux] = 1


@ti.kernel
def _mark_moved(moved: ndarr, cell_of: ndarr, active: ndarr, ncx: ti.i32, ncy: ti.i32, periodic: ti.template()):
    """Flag the 3 x 3 cells around every circle that moved (after the cells were built again)."""
    for c in range(ncx * ncy):
        active[c] = 0
    for i in range(moved.shape[0]):
        if moved[i] != 0:
            c = cell_of[i]
            _mark_block(c % ncx, c // ncx, active, ncx, ncy, periodic)


@ti.kernel
def _relax(pos: ndarr, rad: ndarr, new: ndarr, anchor: ndarr, moved: ndarr, active: ndarr, next_active: ndarr,
           cell_start: ndarr, sorted_ids: ndarr, ncx: ti.i32, ncy: ti.i32, box_w: ti.f64, box_h: ti.f64, slack: ti.f64,
           seed: ti.i32, pass_: ti.i32, factor: ti.f64, out: ndarr, periodic: ti.template(), single: ti.template()):
    """One Jacobi pass of overlap removal over the circles of the active cells: positions from `pos` to `new`.

    A pair closer than (r_i + r_j)(1 + CLEARANCE) pushes both circles apart along their line
    of centres, each by `factor` times half of what separates them from a target distance up
    to RELAX_GAP past contact (drawn for the pair and the pass); a circle too near a wall is
    put RELAX_GAP of its radius inside. The pushes on a circle are summed in cell order, each
    cell's circles in increasing index, so the sums do not depend on the thread count. A
    circle that moves makes its 3 x 3 cells active for the next pass (only there can a pair
    have changed), so every circle of an inactive cell has the same position in `pos` and in
    `new`, and the caller swaps the two for the next pass; `moved` flags the circles that
    moved. out[0]: circles that broke the rule before the pass; out[1]: circles now more than
    `slack` from `anchor`, where the cells were built (then they must be built again).
    """
    key = _draw_key(seed, pass_)
    out[0] = 0
    out[1] = 0
    pieces = _pieces(ncy, ncx)
    for t in range(ncy * pieces):
        box = ti.Vector([box_w, box_h], dt=ti.f64)
        cy = t // pieces
        x0, x1 = _piece(t - cy * pieces, pieces, ncx)
        hits = 0
        far = 0
        for cx in range(x0, x1):
            c = cy * ncx + cx
            if active[c] != 0 and cell_start[c] < cell_start[c + 1]:
                spans_ = _block(cx, cy, cell_start, ncx, ncy, periodic)
                count = 0
                for m in range(cell_start[c], cell_start[c + 1]):
                    i = sorted_ids[m]
                    xi = pos[i]
                    ri = rad[i]
                    push, hit = _push(i, xi, ri, spans_, pos, rad, sorted_ids, box, seed, key, factor, periodic)
                    if not inside(xi, ri, box_w, box_h, periodic):
                        hit = 1
                    x = xi
                    if hit:
                        x = xi + push
                        if ti.static(periodic):
                            x -= box * ti.floor(x / box)
                        else:
                            edge = ri * (1.0 + RELAX_GAP)
                            x[0] = ti.min(ti.max(x[0], edge), box_w - edge)
                            x[1] = ti.min(ti.max(x[1], edge), box_h - edge)
                        x = stored(x, single)
                        if ti.static(periodic):
                            # Rounding may give exactly W (or H): that is 0.
                            if x[0] >= box_w:
                                x[0] = 0.0
                            if x[1] >= box_h:
                                x[1] = 0.0
                        d = displacement(anchor[i], x, box, periodic)
                        if d.dot(d) > slack * slack:
                            far += 1
                    new[i] = x
                    moved[i] = hit
                    count += hit
                if count > 0:
                    hits += count
                    _mark_block(cx, cy, next_active, ncx, ncy, periodic)
        if hits > 0:
            ti.atomic_add(out[0], hits)
        if far > 0:
            ti.atomic_add(out[1], far)


@ti.kernel
def _fill_i32(arr: ndarr, value: ti.i32):
    for i in range(arr.shape[0]):
        arr[i] = value


@ti.kernel
def _copy_vec(src: ndarr, dst: ndarr):
    for i in range(src.shape[0]):
        dst[i] = src[i]


def relaxed_fill(radius: np.ndarray, box, periodic: bool, rng: np.random.Generator, single: bool = False,
                 max_passes: int = RELAX_PASSES):
    """(positions, radii, order, passes): the filled lattice with its overlaps removed, or None.

    `hexagonal` with `fill`, then `_relax` passes until every pair and wall keeps its
    clearance; None if that takes more than `max_passes`. positions and radii are Taichi
    ndarrays in site order; order[k] is the circle at the k-th. The cells are RELAX_SLACK
    radii wider than a contact distance on each side and are built again only when a circle
    has moved that far; in between, a pass visits only the cells next to a move.
    """
    n = radius.shape[0]
    pos, order = hexagonal(radius, box, periodic, rng, single, fill=True)
    rmax = float(radius.max())
    slack = RELAX_SLACK * rmax
    cells = _Cells(n, box, periodic, 2.0 * rmax * (1.0 + 4 * CLEARANCE) + 2.0 * slack)
    ncells = cells.ncx * cells.ncy
    p = ti.Vector.ndarray(2, ti.f64, shape=n)
    p.from_numpy(pos)
    rad = ti.ndarray(ti.f64, shape=n)
    rad.from_numpy(radius[order].astype(np.float64))
    new = ti.Vector.ndarray(2, ti.f64, shape=n)
    anchor = ti.Vector.ndarray(2, ti.f64, shape=n)
    active = ti.ndarray(ti.i32, shape=ncells)
    next_active = ti.ndarray(ti.i32, shape=ncells)
    out = ti.ndarray(ti.i32, shape=2)
    seed = int(rng.integers(0, 2 ** 31))
    moved = ti.ndarray(ti.i32, shape=n)
    _fill_i32(moved, 1)
    _copy_vec(p, new)
    factor, best, since = RELAX_FACTOR, n + 1, 0
    hits = n
    stale = True
    for k in range(max_passes):
        if stale:
            cells.build(p, anchor=anchor)
            if hits > n // 4:
                _fill_i32(active, 1)
            else:
                # Only cells near a circle that moved in the last pass can hold a new overlap.
                _mark_moved(moved, cells.cell_of, active, cells.ncx, cells.ncy, periodic)
        _fill_i32(next_active, 0)
        _relax(p, rad, new, anchor, moved, active, next_active, *cells.lists(), box[0], box[1], slack, seed, k, factor,
               out, periodic, single)
        p, new = new, p
        hits, far = (int(v) for v in out.to_numpy())
        if hits == 0:
            return p, rad, order, k
        # Pushing past the target spreads a crowd fast, but near jamming it overshoots back and
        # forth: when the count of circles in overlap stops falling, push less.
        if hits < best:
            best, since = hits, 0
        else:
            since += 1
            if since >= RELAX_PATIENCE:
                factor, since = max(RELAX_FACTOR_MIN, factor * 0.7), 0
        stale = far > 0
        active, next_active = next_active, active
    return None
