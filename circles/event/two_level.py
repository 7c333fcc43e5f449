"""The event queue's two-level grid: coarse cells, blocks of fine cells as wide as the reach of
two large circles, that list the large circles only (see `circles.event`, "Radius spread")."""
import taichi as ti

from .. import launch
from ..discrete import NLARGE
from ..geometry import cell_coords, neighbour_range, run_parts, wide_row

ndarr = ti.types.ndarray(ndim=1)


@ti.func
def _coarse_of(c, ncx, mx, my):
    """(gx, gy): the coarse cell that holds fine cell c of a walled grid (`build_coarse`)."""
    cx, cy = cell_coords(c, ncx)
    return cx // mx, cy // my


@ti.func
def _runs(i, radius: ti.template(), box, ncx, ncy, rows, segs, r_cut, margin, two_level: ti.template()):
    """(runs, kx, ky): the number of runs of slots (`_run`) that hold every circle that circle i
    can meet in the step, and the half-widths in cells of its block of fine cells.

    One level: the runs of the 3 x 3 cells. Two levels (`build_coarse`): a small circle's 3 x 3
    fine cells (kx = ky = 1) or a large circle's block of fine cells within its reach of any
    small circle (a whole cell more, against round-off), then the three rows of its 3 x 3
    coarse cells, which list the large circles only."""
    runs = rows * segs
    kx = 1
    ky = 1
    if ti.static(two_level):
        r = ti.cast(radius[i], ti.f64)
        if r > r_cut:
            reach = r + r_cut + margin
            kx = ti.cast(ti.floor(reach * ncx / ti.cast(box[0], ti.f64)), ti.i32) + 1
            ky = ti.cast(ti.floor(reach * ncy / ti.cast(box[1], ti.f64)), ti.i32) + 1
        runs = 2 * ky + 1 + 3
    return runs, kx, ky


@ti.func
def _run(r, c, kx, ky, cell_start: ti.template(), coarse_start: ti.template(), ncx, ncy, segs, ncx_c, ncy_c, mx,
         my, periodic: ti.template(), two_level: ti.template()):
    """(lo, hi, coarse): run r of `_runs` around fine cell c: slots [lo, hi) of the grid's
    `sorted_ids`, or of the coarse grid's `coarse_ids` when `coarse`."""
    lo = 0
    hi = 0
    coarse = False
    if ti.static(two_level):
        fine = 2 * ky + 1
        if r < fine:
            lo, hi = wide_row(c, r - ky, kx, cell_start, ncx, ncy)
        else:
            coarse = True
            gx, gy = _coarse_of(c, ncx, mx, my)
            y = gy + r - fine - 1
            if 0 <= y < ncy_c:
                base = y * ncx_c
                lo = coarse_start[base + ti.max(gx - 1, 0)]
                hi = coarse_start[base + ti.min(gx + 1, ncx_c - 1) + 1]
    else:
        row, seg = run_parts(r, segs, periodic)
        lo, hi = neighbour_range(c, row, seg, cell_start, ncx, ncy, periodic)
    return lo, hi, coarse


@ti.func
def _at(k, coarse, sorted_ids: ti.template(), coarse_ids: ti.template(), radius: ti.template(), r_cut,
        two_level: ti.template()):
    """The circle in slot k of a run (`_run`), or -1 for a large circle met in a fine run of a
    two-level grid (its coarse run lists it: each circle is met once)."""
    j = -1
    if ti.static(two_level):
        if coarse:
            j = coarse_ids[k]
        else:
            j = sorted_ids[k]
            if ti.cast(radius[j], ti.f64) > r_cut:
                j = -1
    else:
        j = sorted_ids[k]
    return j


@launch.kernel
def build_coarse(large: ndarr, work: ndarr, cell_of: ndarr, coarse_start: ndarr, coarse_ids: ndarr, ncx: ti.i32,
                 mx: ti.i32, my: ti.i32, ncx_c: ti.i32, ncy_c: ti.i32):
    """The coarse level of a two-level grid: the work[NLARGE] large circles listed in `large`,
    sorted into coarse cells of mx x my fine cells (so a circle's coarse cell follows from its
    fine cell, the one it started the step in); cell g holds coarse_ids[coarse_start[g]:
    coarse_start[g + 1]]. The coarse cells are as wide as two large radii and the reach of a
    step, so every large circle that a circle can meet lies in its 3 x 3 coarse cells.
    Serial counting sort: the large circles are few."""
    ncells = ncx_c * ncy_c
    for g in range(ncells + 1):
        coarse_start[g] = 0
    ti.loop_config(serialize=True)
    for _ in range(1):
        nl = work[NLARGE]
        for a in range(nl):
            gx, gy = _coarse_of(cell_of[large[a]], ncx, mx, my)
            coarse_start[gy * ncx_c + gx] += 1
        for g in range(1, ncells):
            coarse_start[g] += coarse_start[g - 1]
        # coarse_start[g] is now the end of cell g; counting down fills each cell to its start.
        for a in range(nl):
            i = large[a]
            gx, gy = _coarse_of(cell_of[i], ncx, mx, my)
            g = gy * ncx_c + gx
            coarse_start[g] -= 1
            coarse_ids[coarse_start[g]] = i
        coarse_start[ncells] = nl
