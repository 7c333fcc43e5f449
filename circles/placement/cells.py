"""The cells of placement's parallel passes: a grid shifted by a random offset, and each
circle's block of neighbour cells."""
import taichi as ti

from ..grid import prefix_sum

ndarr = ti.types.ndarray(ndim=1)


@ti.func
def _cell_xy(x, ox, oy, inv_cw, inv_ch, ncx, ncy, box_w, box_h, periodic: ti.template()):
    """Cell (cx, cy) of a point on the grid of cells 1 / inv_cw x 1 / inv_ch shifted by (ox, oy)."""
    u = x[0] + ox
    v = x[1] + oy
    if ti.static(periodic):
        u -= box_w * ti.floor(u / box_w)
        v -= box_h * ti.floor(v / box_h)
    cx = ti.min(ti.max(ti.cast(ti.floor(u * inv_cw), ti.i32), 0), ncx - 1)
    cy = ti.min(ti.max(ti.cast(ti.floor(v * inv_ch), ti.i32), 0), ncy - 1)
    return cx, cy


@ti.func
def _block(cx, cy, cell_start: ti.template(), ncx, ncy, periodic: ti.template()):
    """Slot ranges (lo, hi) of the 3 x 3 cells around cell (cx, cy), each cell once.

    Three rows of one run each in a walled box; in a periodic box up to three rows (fewer
    when there are fewer) of up to two runs (a row that wraps around the edge splits).
    """
    spans_ = ti.Vector([0] * 12, dt=ti.i32)
    if ti.static(periodic):
        rows = ti.min(3, ncy)
        for r in ti.static(range(3)):
            if r < rows:
                y = r
                if ncy >= 3:
                    y = (cy + r - 1 + ncy) % ncy
                first = y * ncx
                if ncx < 3:
                    spans_[4 * r] = cell_start[first]
                    spans_[4 * r + 1] = cell_start[first + ncx]
                else:
                    x0 = cx - 1
                    x1 = cx + 2
                    if x0 < 0:
                        spans_[4 * r] = cell_start[first + ncx - 1]
                        spans_[4 * r + 1] = cell_start[first + ncx]
                        spans_[4 * r + 2] = cell_start[first]
                        spans_[4 * r + 3] = cell_start[first + x1]
                    elif x1 > ncx:
                        spans_[4 * r] = cell_start[first + x0]
                        spans_[4 * r + 1] = cell_start[first + ncx]
                        spans_[4 * r + 2] = cell_start[first]
                        spans_[4 * r + 3] = cell_start[first + x1 - ncx]
                    else:
                        spans_[4 * r] = cell_start[first + x0]
                        spans_[4 * r + 1] = cell_start[first + x1]
    else:
        x0 = ti.max(cx - 1, 0)
        x1 = ti.min(cx + 2, ncx)
        for r in ti.static(range(3)):
            y = cy + r - 1
            if 0 <= y < ncy:
                spans_[2 * r] = cell_start[y * ncx + x0]
                spans_[2 * r + 1] = cell_start[y * ncx + x1]
    return spans_


@ti.func
def _pieces(rows, per_row):
    """Pieces to cut each of `rows` rows of `per_row` cells into: about 4096 pieces in all, at most one per cell."""
    return ti.max(1, ti.min(per_row, (4096 + rows - 1) // ti.max(rows, 1)))


@ti.func
def _piece(k, pieces, per_row):
    """Cells [a0, a1) of piece k of a row of `per_row` cells cut into `pieces`."""
    size = (per_row + pieces - 1) // pieces
    a0 = k * size
    return a0, ti.min(a0 + size, per_row)


@ti.kernel
def _build_cells(pos: ndarr, cell_of: ndarr, slot: ndarr, cell_count: ndarr, cell_start: ndarr, sorted_ids: ndarr,
                 ncx: ti.i32, ncy: ti.i32, ox: ti.f64, oy: ti.f64, inv_cw: ti.f64, inv_ch: ti.f64, box_w: ti.f64,
                 box_h: ti.f64, anchor: ndarr, periodic: ti.template(), keep: ti.template()):
    """Cell lists by counting sort, each cell's circles in increasing index (not in atomic slot order).
    `cell_count` is zero on entry and left zero.

    With `keep`, anchor[i] = pos[i]: where each circle was when the cells were built.
    """
    for i in range(pos.shape[0]):
        if ti.static(keep):
            anchor[i] = pos[i]
        cx, cy = _cell_xy(pos[i], ox, oy, inv_cw, inv_ch, ncx, ncy, box_w, box_h, periodic)
        c = cy * ncx + cx
        cell_of[i] = c
        slot[i] = ti.atomic_add(cell_count[c], 1)
    prefix_sum(cell_count, cell_start, ncx * ncy, False)  # the grid's scan, which leaves the counts zeroed
    for i in range(pos.shape[0]):
        sorted_ids[cell_start[cell_of[i]] + slot[i]] = i
    for c in range(ncx * ncy):
        lo = cell_start[c]
        for a in range(lo + 1, cell_start[c + 1]):
            v = sorted_ids[a]
            b = a - 1
            while b >= lo:
                if sorted_ids[b] < v:
                    break
                sorted_ids[b + 1] = sorted_ids[b]
                b -= 1
            sorted_ids[b + 1] = v


class _Cells:
    """Cell lists on a grid of cells at least `side` wide, which may be shifted by an offset.

    In a periodic box the cells divide each side evenly, in an even number (or one), so that
    cells of one parity are a cell apart also across the wrap. Against a wall the last cell
    may be wider. The circles of a cell are listed in increasing index.
    """

    def __init__(self, n, box, periodic, side):
        w, h = box
        self.box = (float(w), float(h))
        self.periodic = periodic
        if periodic:
            def count(length):
                k = max(1, int(length / side))
                return k - 1 if k > 1 and k % 2 else k
            self.ncx, self.ncy = count(w), count(h)
            self.cw, self.ch = w / self.ncx, h / self.ncy
        else:
            self.cw = self.ch = side
            self.ncx, self.ncy = int(w / side) + 1, int(h / side) + 1
        ncells = self.ncx * self.ncy
        self.cell_of = ti.ndarray(ti.i32, shape=n)
        self.slot = ti.ndarray(ti.i32, shape=n)
        self.sorted_ids = ti.ndarray(ti.i32, shape=n)
        self.cell_count = ti.ndarray(ti.i32, shape=ncells)
        self.cell_count.fill(0)  # and zero after every build (see grid.prefix_sum)
        self.cell_start = ti.ndarray(ti.i32, shape=ncells + 1)
        self.ox = self.oy = 0.0

    def build(self, pos, ox=0.0, oy=0.0, anchor=None):
        """Build the lists for `pos`, the grid shifted by (ox, oy); copy pos to `anchor` if given."""
        self.ox, self.oy = ox, oy
        keep = anchor is not None
        _build_cells(pos, self.cell_of, self.slot, self.cell_count, self.cell_start, self.sorted_ids, self.ncx,
                     self.ncy, ox, oy, 1.0 / self.cw, 1.0 / self.ch, self.box[0], self.box[1],
                     anchor if keep else pos, self.periodic, keep)

    def lists(self):
        """(cell_start, sorted_ids, ncx, ncy)."""
        return self.cell_start, self.sorted_ids, self.ncx, self.ncy

    def frame(self):
        """(ox, oy, 1 / cw, 1 / ch)."""
        return self.ox, self.oy, 1.0 / self.cw, 1.0 / self.ch
