"""Hard-disk Monte Carlo on a checkerboard of cells (see `circles.placement`)."""
import numpy as np
import taichi as ti

from ..geometry import displacement
from .cells import _Cells, _block, _cell_xy, _piece, _pieces
from .sampling import CLEARANCE, _draw_key, inside, mix32, stored

ndarr = ti.types.ndarray(ndim=1)


#: The trial step is adapted towards this fraction of accepted moves.
MC_ACCEPTANCE = 0.4
#: Sweeps allowed for circles to grow back to their radii before placement gives up ...
MC_GROW_SWEEPS = 5000
#: ... or sweeps in a row without fewer circles short of their radii.
MC_GROW_PATIENCE = 500


@ti.func
def _free(x, ri, i, spans_: ti.template(), pos: ti.template(), rad: ti.template(), sorted_ids: ti.template(), box,
          periodic: ti.template()):
    """Whether circle i of radius ri at x keeps the clearance to every other circle of the block."""
    hits = 0
    for q in ti.static(range(6 if periodic else 3)):
        for k in range(spans_[2 * q], spans_[2 * q + 1]):
            j = sorted_ids[k]
            s = (ri + rad[j]) * (1.0 + CLEARANCE)
            d = displacement(x, pos[j], box, periodic)
            # Without branches (whether a neighbour is hit is hard to predict).
            hits += ti.select((d.dot(d) < s * s) & (j != i), 1, 0)
    return hits == 0


@ti.func
def _mc_cell(cx0, cy0, pos: ti.template(), rad: ti.template(), cell_start: ti.template(), sorted_ids: ti.template(),
             ncx, ncy, ox, oy, inv_cw, inv_ch, box_w, box_h, key, delta, periodic: ti.template(),
             single: ti.template()):
    """One trial move of each circle of cell (cx0, cy0), one after another; returns how many were kept."""
    c = cy0 * ncx + cx0
    spans_ = _block(cx0, cy0, cell_start, ncx, ncy, periodic)
    done = 0
    for m in range(cell_start[c], cell_start[c + 1]):
        box = ti.Vector([box_w, box_h], dt=ti.f64)
        i = sorted_ids[m]
        ri = rad[i]
        h = mix32(mix32(ti.cast(i, ti.u32)) ^ key)
        h2 = mix32(h ^ ti.u32(0x68E31DA4))
        step = ti.Vector([ti.cast(h, ti.f64), ti.cast(h2, ti.f64)]) * (2.0 * delta / 4294967296.0) - delta
        x = pos[i] + step
        if ti.static(periodic):
            x -= box * ti.floor(x / box)
        x = stored(x, single)
        ok = inside(x, ri, box_w, box_h, periodic)
        if ok:
            cx, cy = _cell_xy(x, ox, oy, inv_cw, inv_ch, ncx, ncy, box_w, box_h, periodic)
            ok = cx == cx0 and cy == cy0
        if ok:
            ok = _free(x, ri, i, spans_, pos, rad, sorted_ids, box, periodic)
        if ok:
            pos[i] = x
            done += 1
    return done


@ti.kernel
def _mc_colour(pos: ndarr, rad: ndarr, cell_start: ndarr, sorted_ids: ndarr, ncx: ti.i32, ncy: ti.i32, ox: ti.f64,
               oy: ti.f64, inv_cw: ti.f64, inv_ch: ti.f64, box_w: ti.f64, box_h: ti.f64, seed: ti.i32, sweep: ti.i32,
               delta: ti.f64, px: ti.i32, py: ti.i32, periodic: ti.template(), single: ti.template()) -> ti.i32:
    """One trial move for each circle in the cells of one colour (x parity px, y parity py); returns how many were kept.

    Rows of the colour's cells are cut into pieces (enough of them to share out among threads:
    Taichi runs a loop of fewer than about a thousand items on one thread), one thread per
    piece, along it every other cell. Cells of one
    colour are a cell apart and at least a contact distance wide, so circles of two of them
    never meet; a circle only moves within its cell, so the cells it reads (its 3 x 3 block)
    are not written meanwhile. Within a cell the circles move one after another, in
    increasing index.
    """
    key = _draw_key(seed, sweep)
    accepted = 0
    rows = (ncy - py + 1) // 2
    per_row = (ncx - px + 1) // 2
    pieces = _pieces(rows, per_row)
    for t in range(rows * pieces):
        b = t // pieces
        a0, a1 = _piece(t - b * pieces, pieces, per_row)
        cy = 2 * b + py
        done = 0
        for a in range(a0, a1):
            cx = 2 * a + px
            c = cy * ncx + cx
            if cell_start[c] < cell_start[c + 1]:
                done += _mc_cell(cx, cy, pos, rad, cell_start, sorted_ids, ncx, ncy, ox, oy, inv_cw, inv_ch, box_w,
                                 box_h, key, delta, periodic, single)
        accepted += done
    return accepted


def _mc_sweep(pos, rad, cell_start, sorted_ids, ncx, ncy, ox, oy, inv_cw, inv_ch, box_w, box_h, seed, sweep, delta,
              periodic, single):
    """One sweep: the four colours of cells one after another (x and y parity); returns the moves kept."""
    return sum(_mc_colour(pos, rad, cell_start, sorted_ids, ncx, ncy, ox, oy, inv_cw, inv_ch, box_w, box_h, seed,
                          sweep, delta, colour % 2, colour // 2, periodic, single) for colour in range(4))


@ti.kernel
def _mc_grow(pos: ndarr, rad: ndarr, target: ndarr, scratch: ndarr, cell_of: ndarr, cell_start: ndarr,
             sorted_ids: ndarr, ncx: ti.i32, ncy: ti.i32, box_w: ti.f64, box_h: ti.f64,
             periodic: ti.template()) -> ti.i32:
    """Every circle grows towards its target radius; returns how many are still short of it.

    A circle takes half of each gap (all of it next to a circle that has its radius, which
    does not grow), less a little against round-off, and stays CLEARANCE inside the walls.
    """
    short = 0
    for i in range(pos.shape[0]):
        box = ti.Vector([box_w, box_h], dt=ti.f64)
        xi = pos[i]
        ri = rad[i]
        allowed = target[i]
        if ti.static(not periodic):
            wall = ti.min(ti.min(xi[0], box_w - xi[0]), ti.min(xi[1], box_h - xi[1]))
            allowed = ti.min(allowed, wall / (1.0 + CLEARANCE) * (1.0 - 1e-12))
        c = cell_of[i]
        spans_ = _block(c % ncx, c // ncx, cell_start, ncx, ncy, periodic)
        for q in ti.static(range(6 if periodic else 3)):
            for k in range(spans_[2 * q], spans_[2 * q + 1]):
                j = sorted_ids[k]
                if j != i:
                    d = displacement(xi, pos[j], box, periodic).norm()
                    gap = d / (1.0 + CLEARANCE) - ri - rad[j]
                    share = 0.5
                    if rad[j] >= target[j]:
                        share = 1.0
                    allowed = ti.min(allowed, ri + share * gap * (1.0 - 1e-6))
        grown = ti.max(ri, allowed)
        scratch[i] = grown
        if grown < target[i]:
            short += 1
    for i in range(pos.shape[0]):
        rad[i] = scratch[i]
    return short


@ti.kernel
def _violations(pos: ndarr, rad: ndarr, cell_of: ndarr, cell_start: ndarr, sorted_ids: ndarr, ncx: ti.i32,
                ncy: ti.i32, box_w: ti.f64, box_h: ti.f64, periodic: ti.template()) -> ti.i32:
    """Circles that overlap another (distance below the sum of radii) or cross a wall."""
    bad = 0
    for i in range(pos.shape[0]):
        box = ti.Vector([box_w, box_h], dt=ti.f64)
        xi = pos[i]
        ri = rad[i]
        ok = True
        if ti.static(periodic):
            ok = 0.0 <= xi[0] <= box_w and 0.0 <= xi[1] <= box_h
        else:
            ok = ri <= xi[0] <= box_w - ri and ri <= xi[1] <= box_h - ri
        c = cell_of[i]
        spans_ = _block(c % ncx, c // ncx, cell_start, ncx, ncy, periodic)
        for q in ti.static(range(6 if periodic else 3)):
            for k in range(spans_[2 * q], spans_[2 * q + 1]):
                j = sorted_ids[k]
                if j != i and displacement(xi, pos[j], box, periodic).norm() < ri + rad[j]:
                    ok = False
        if not ok:
            bad += 1
    return bad


def _device(arr, width):
    """A float64 Taichi ndarray of `arr` (n,) or (n, 2) (width 1 or 2); a Taichi ndarray as it is."""
    if not isinstance(arr, np.ndarray):
        return arr
    out = ti.Vector.ndarray(2, ti.f64, shape=arr.shape[0]) if width == 2 else ti.ndarray(ti.f64, shape=arr.shape[0])
    out.from_numpy(np.ascontiguousarray(arr, dtype=np.float64))
    return out


class GrowthStalled(ValueError):
    """Monte Carlo could not grow `short` of `n` circles to their radii (`hard_disk_monte_carlo`)."""

    def __init__(self, short, n):
        super().__init__(f"could not grow {short} of {n} circles to their radii: too close to jamming")
        self.short, self.n = short, n


def hard_disk_monte_carlo(pos, radius, target: np.ndarray, box, periodic: bool, rng: np.random.Generator,
                          sweeps: int, delta: float, single: bool = False):
    """(positions, sweeps run): `sweeps` sweeps of hard-disk Monte Carlo from a valid start.

    pos (n, 2): every pair at least (r_i + r_j)(1 + CLEARANCE) apart and every circle
    r (1 + CLEARANCE) inside the walls; radius: the start radii, each at most its target
    (numpy arrays, or Taichi ndarrays when the radii are the targets).
    Each sweep shifts the cell grid by a random offset (from `rng`) and gives every circle one
    trial move, uniform in a square of half-side `delta`. While circles are short of their
    target radii they grow after every sweep (`_mc_grow`); the `sweeps` count starts when all
    have their radii. `delta` is adapted after each sweep towards an acceptance of
    MC_ACCEPTANCE (from the count of kept moves, an integer, so the same for any thread count).
    Positions that leave are float32 values with `single`. Raises GrowthStalled (a ValueError)
    when the circles do not grow back within MC_GROW_SWEEPS sweeps, or MC_GROW_PATIENCE sweeps
    go by without fewer of them short.
    """
    n = target.shape[0]
    side = 2.0 * float(target.max()) * (1.0 + 4 * CLEARANCE)
    cells = _Cells(n, box, periodic, side)
    max_delta = 0.5 * min(cells.cw, cells.ch)
    delta = min(max(delta, 1e-9 * side), max_delta)
    p = _device(pos, 2)
    rad = _device(radius, 1)
    growing = bool(np.any(radius < target)) if isinstance(radius, np.ndarray) else False
    if growing:
        tgt = ti.ndarray(ti.f64, shape=n)
        tgt.from_numpy(target.astype(np.float64))
        scratch = ti.ndarray(ti.f64, shape=n)
    seed = int(rng.integers(0, 2 ** 31))
    done = sweep = short = since = 0
    fewest = n + 1
    while growing or done < sweeps:
        if growing and (sweep >= MC_GROW_SWEEPS or since >= MC_GROW_PATIENCE):
            raise GrowthStalled(short, n)
        cells.build(p, rng.uniform(0.0, cells.cw), rng.uniform(0.0, cells.ch))
        accepted = _mc_sweep(p, rad, *cells.lists(), *cells.frame(), box[0], box[1], seed, sweep, delta, periodic,
                             single)
        sweep += 1
        if growing:
            short = _mc_grow(p, rad, tgt, scratch, cells.cell_of, *cells.lists(), box[0], box[1], periodic)
            growing = short > 0
            fewest, since = (short, 0) if short < fewest else (fewest, since + 1)
        else:
            done += 1
        rate = accepted / n
        delta *= min(2.0, max(0.5, rate / MC_ACCEPTANCE))
        delta = min(max(delta, 1e-9 * side), max_delta)
    _check(p, rad, cells, box, periodic)
    return p.to_numpy(), sweep


def _check(p, rad, cells, box, periodic):
    """Raise RuntimeError if any circle overlaps another or crosses a wall (a bug, never expected)."""
    cells.build(p)
    bad = _violations(p, rad, cells.cell_of, *cells.lists(), box[0], box[1], periodic)
    if bad:
        raise RuntimeError(f"internal error: {bad} circles overlap or cross a wall after placement")
