"""Small Taichi functions shared by the schemes: displacement, event keys, neighbour cells.

Event keys order events totally: (time, lo, hi), with lo < hi the two circle ids of a pair,
or (time, i, n + w) for a hit of circle i on wall w. Every choice between events compares
keys, never the order in which threads or cells were visited, so results do not depend on
the thread count or on atomic slot order inside a cell.

A rule for every kernel: build vectors (the box, say) inside the loop that uses them, not at
kernel scope. Taichi keeps a kernel-scope value that a parallel loop reads in a global buffer
aligned for scalars, and on CUDA a float64 vector read from there faults (misaligned address).
"""
import taichi as ti

#: "No event": larger than any step (`scene.MAX_DT`), representable in float32.
NEVER = 1.0e30

#: Wall codes stored as partners: -1 is x = 0, -2 is x = W, -3 is y = 0, -4 is y = H.
WALL_LEFT, WALL_RIGHT, WALL_BOTTOM, WALL_TOP = -1, -2, -3, -4
NO_EVENT = -10


@ti.func
def displacement(xi, xj, box, periodic: ti.template()):
    """x_j - x_i, by the minimum image in a periodic box."""
    d = xj - xi
    if ti.static(periodic):
        d -= box * ti.floor(d / box + 0.5)
    return d


@ti.func
def key_less(t1, a1, b1, t2, a2, b2):
    less = False
    if t1 < t2:
        less = True
    elif t1 == t2:
        if a1 < a2:
            less = True
        elif a1 == a2 and b1 < b2:
            less = True
    return less


def cell_total(ncx: int, ncy: int, periodic: bool) -> int:
    """Cells in the layout of an ncx x ncy grid (see `cell_index`): cell_start has one more entry."""
    return ncx * ncy if periodic else (ncy + 2) * (ncx + 1) + 1


@ti.func
def cells_in(ncx, ncy, periodic: ti.template()):
    """`cell_total` inside a kernel."""
    total = ncx * ncy
    if ti.static(not periodic):
        total = (ncy + 2) * (ncx + 1) + 1
    return total


@ti.func
def cell_index(cx, cy, ncx, periodic: ti.template()):
    """The number of cell (cx, cy), 0 <= cx < ncx, 0 <= cy < ncy.

    Periodic: row-major, cy * ncx + cx. Walled: row-major in a frame of cells that stay empty,
    rows of ncx + 1 cells whose first is empty, and an empty row below and above. So the
    neighbours of a cell are at fixed offsets (c - 1, c + 1, c -+ (ncx + 1)) with no test
    for the edge: past an edge lies an empty cell. Cell ranges need no cell coordinates.
    """
    c = cy * ncx + cx
    if ti.static(not periodic):
        c = (cy + 1) * (ncx + 1) + cx + 1
    return c


@ti.func
def neighbour_range(c, row, seg, cell_start: ti.template(), ncx, ncy, periodic: ti.template()):
    """Slots [k_lo, k_hi) of `sorted_ids` in segment `seg` of row `row` of the 3 x 3 cells around c.

    The three cells of a row are consecutive cell numbers, so a row is one contiguous run of
    slots: three ranges per circle instead of nine. In a walled box the empty frame of the
    layout (`cell_index`) takes the place of cells past the edge. In a periodic box a row
    that wraps around the edge splits into two runs (seg 0 and 1); with fewer than 3 cells
    along an axis the rows and runs cover each cell once, so no pair is seen twice. `row`
    runs over range(rows) and `seg` over range(segs), with (rows, segs) from `spans`.
    """
    lo = 0
    hi = 0
    if ti.static(periodic):
        cx = c % ncx
        cy = c // ncx
        ny = (cy + row - (1 if ncy >= 3 else 0) + ncy) % ncy
        first = ny * ncx
        if ncx < 3:
            lo = first
            hi = first + ncx
        else:
            x0 = cx - 1
            x1 = cx + 2
            if x0 < 0:
                if seg == 0:
                    lo, hi = first + ncx - 1, first + ncx
                else:
                    lo, hi = first, first + x1
            elif x1 > ncx:
                if seg == 0:
                    lo, hi = first + x0, first + ncx
                else:
                    lo, hi = first, first + x1 - ncx
            elif seg == 0:
                lo, hi = first + x0, first + x1
    else:
        mid = c + (row - 1) * (ncx + 1)
        lo = mid - 1
        hi = mid + 2
    return cell_start[lo], cell_start[hi]


@ti.func
def run_parts(r, segs, periodic: ti.template()):
    """(row, seg) of run r of the runs rows x segs of `neighbour_range`. A walled box has one
    run per row (segs = 1, see `spans`): no integer division, which takes tens of cycles in a
    search that reads a few circles."""
    row = r
    seg = 0
    if ti.static(periodic):
        row = r // segs
        seg = r % segs
    return row, seg


@ti.func
def cell_coords(c, ncx):
    """(cx, cy) of cell number c of a walled box (the inverse of `cell_index`)."""
    stride = ncx + 1
    cy = c // stride - 1
    return c - (cy + 1) * stride - 1, cy


@ti.func
def wide_row(c, dy, kx, cell_start: ti.template(), ncx, ncy):
    """Slots [lo, hi) of row dy (from -ky to ky) of the block of cells within kx cells along x
    of cell c, in a walled box (`cell_index`), cut at the edges of the grid.

    Two-level grids (see `circles.discrete` and `circles.event`): the cells are sized for the
    small circles, and each of the few large circles searches the block its own reach spans.
    With kx = 1 the rows are those of the 3 x 3 cells (`neighbour_range`).
    """
    cx, cy = cell_coords(c, ncx)
    y = cy + dy
    lo = 0
    hi = 0
    if 0 <= y < ncy:
        row = cell_index(0, y, ncx, False)
        lo = cell_start[row + ti.max(cx - kx, 0)]
        hi = cell_start[row + ti.min(cx + kx, ncx - 1) + 1]
    return lo, hi


@ti.func
def forward_range(q, c, cx, cy, own, cell_start: ti.template(), ncx, ncy, periodic: ti.template()):
    """Slots [k_lo, k_hi) of part `q` of the forward half of the 3 x 3 cells around c = (cx, cy).

    The forward half of the circle in slot `own` of cell c: the later slots of c, the cell to
    its right and the three cells of the row above. Each pair of circles in neighbouring
    cells lies in the forward half of exactly one of its two circles, so a search over the
    forward halves sees every pair once. Parts: 2 in a walled box (the own row is one run;
    cx and cy are not read, see `cell_index`), 4 in a periodic box (own cell, right cell,
    and the row above in up to two runs), where it needs at least 3 cells along each axis
    (`forward_fits`).
    """
    lo = own + 1
    hi = own + 1
    if ti.static(periodic):
        if q == 0:
            hi = cell_start[c + 1]
        elif q == 1:
            right = c + 1 if cx + 1 < ncx else c + 1 - ncx
            lo, hi = cell_start[right], cell_start[right + 1]
        else:
            lo, hi = neighbour_range(c, 2, q - 2, cell_start, ncx, ncy, periodic)
    else:
        if q == 0:
            hi = cell_start[c + 2]
        else:
            lo, hi = neighbour_range(c, 2, 0, cell_start, ncx, ncy, periodic)
    return lo, hi


@ti.func
def pairs_once(own, i, c, forward, cell_start: ti.template(), sorted_ids: ti.template(), ncx, ncy, rows, segs,
               periodic: ti.template(), visit: ti.template(), args: ti.template()):
    """visit(i, j, args) for each circle j whose pair with circle i (in slot `own` of cell c) is
    met from i's side: the forward half of i's cells (`forward_range`), or, where `forward` is
    False (`forward_fits`: a periodic grid under 3 cells wide), the full 3 x 3 search with each
    pair from its lower index. Over every circle, each neighbouring pair is visited once."""
    if forward:
        cy = c // ncx  # cell coordinates of a periodic grid (a walled one does not read them)
        cx = c - cy * ncx
        for q in ti.static(range(forward_parts(periodic))):
            k_lo, k_hi = forward_range(q, c, cx, cy, own, cell_start, ncx, ncy, periodic)
            for k in range(k_lo, k_hi):
                visit(i, sorted_ids[k], args)
    else:
        for row, seg in ti.ndrange(rows, segs):
            k_lo, k_hi = neighbour_range(c, row, seg, cell_start, ncx, ncy, periodic)
            for k in range(k_lo, k_hi):
                j = sorted_ids[k]
                if j > i:
                    visit(i, j, args)


def forward_parts(periodic: bool) -> int:
    """The number of parts of `forward_range`."""
    return 4 if periodic else 2


@ti.func
def forward_fits(ncx, ncy, periodic: ti.template()):
    """Whether `forward_range` covers each neighbouring pair once on this grid."""
    fits = True
    if ti.static(periodic):
        fits = ncx >= 3 and ncy >= 3
    return fits


def spans(ncx: int, ncy: int, periodic: bool):
    """(rows, segs): the loop bounds of `neighbour_range` for a grid of ncx x ncy cells."""
    if not periodic:
        return 3, 1
    return min(3, ncy), (2 if ncx >= 3 else 1)
