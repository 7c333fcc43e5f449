"""Random non-overlapping placement, from a seed.

Every placement keeps each pair at least (r_i + r_j)(1 + CLEARANCE) apart and each circle
r (1 + CLEARANCE) inside the walls, checked on the positions as the simulation will store
them (float32 values for a float32 simulation), so the largest overlap is exactly 0. Random
numbers come from a counter-based hash of (seed, circle, draw), not from a per-thread
generator, and every sum that feeds a position is taken in a fixed order, so the result does
not depend on the thread count or on thread timing.

`place` picks the method by area fraction:

Up to `RSA_LIMIT`: parallel random sequential addition. In each round every unplaced circle
tries a few random positions against the circles already placed and proposes the first free
one; a proposal that overlaps a proposal of a lower id is dropped. Circles are placed in size
classes, largest first (radii within a factor `CLASS_RATIO` of the largest unplaced one): a
large circle needs a hole free of small ones, which a box already sprinkled with small circles
no longer has, while small circles always find room between large ones. Towards its jamming
limit (0.547 for equal disks) it needs ever more darts and rounds per circle (a minute for a
million circles at 0.5), so it stops well before.

Up to `FILL_LIMIT` (the fluid: equal hard disks freeze near 0.70), and above it when the radii
are too spread for a lattice of the largest one (that lattice would have to start shrunk and
grow back, which is slower and jams sooner; wide mixtures do not order anyway): a filled
lattice with its overlaps removed, then a few sweeps of hard-disk Monte Carlo (`fluid`). Each
circle starts uniform over FILL_BRICKS x FILL_BRICKS bricks around a site of a hexagonal
lattice of about n sites (a brick is the spacing along a row times the row spacing; the
bricks tile the plane, so the start has no Bragg peak of the lattice, while each few bricks
hold their share of circles, so density is even on large scales as in the fluid). Parallel
Jacobi passes then push overlapping pairs apart until none is left (`_relax`), each pair
towards a random distance up to RELAX_GAP past contact. Little of the lattice is left: its
Bragg peaks S(G) / N are below 1e-4 at a million circles (1 for the lattice, 1 / N for a
random placement), the bond orientations are random. The MC_FLUID_SWEEPS Monte Carlo sweeps
then bring the pairs near contact close to the fluid's (at 0.5, g(r) within 25% of its
equilibrium values up to 1.05 diameters).

Above, or when a method before gives up: a hexagonal lattice whose spacing is the largest
that fits, each site jittered by at most half the free gap, circles assigned to sites in a
random order, then MC_SOLID_SWEEPS sweeps of hard-disk Monte Carlo (`lattice_monte_carlo`).
Above the freezing point the equilibrium state is itself (quasi-)ordered and no method
forgets the lattice: the sweeps move every circle about its gap around its site (tens of
accepted moves each), the rows and their orientation stay. When the radii are too spread for
a lattice of the largest one, the lattice takes the circles shrunk by a common factor, and
they grow back between sweeps, each by at most its share of its smallest gap.

Hard-disk Monte Carlo (`hard_disk_monte_carlo`): one trial move per circle per sweep, uniform
in a square, kept when the circle overlaps nothing and stays inside the walls; this samples
the uniform distribution over non-overlapping configurations. It runs race-free in parallel
on a checkerboard: cells at least a contact distance wide in four colours (x and y parity),
one colour at a time with one thread per row of that colour's cells and the circles of a
cell one after another; a move that would leave its cell is refused, and the grid is shifted
by a random offset every sweep.

These replace the melt of a lattice with the event scheme (ten collisions per circle), which
took minutes for a million circles: overlap removal and Monte Carlo cost a few passes over
the circles each.
"""

import math

import numpy as np
import taichi as ti

from .geometry import cell_index, displacement, neighbour_range
from .grid import Grid, prefix_sum
from .scene import DENSEST_PACKING, PLACE_CLEARANCE, area_fraction, rounding_margin

ndarr = ti.types.ndarray(ndim=1)

#: Area fraction up to which random sequential addition is used.
RSA_LIMIT = 0.35
#: Area fraction up to which a filled lattice with its overlaps removed is used (the fluid).
FILL_LIMIT = 0.70
#: Placed circles keep this relative clearance, so rounding never makes an overlap (a walled
#: scene is checked to leave room for it, `scene.check_room`).
CLEARANCE = PLACE_CLEARANCE
#: Size classes of random sequential addition: radii in (r / CLASS_RATIO, r] go together.
CLASS_RATIO = 2.0
#: Each circle of the filled lattice starts uniform over this many bricks along each axis.
FILL_BRICKS = 3
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
#: Monte Carlo sweeps after overlap removal (relaxing the pairs it left near contact).
MC_FLUID_SWEEPS = 4
#: Monte Carlo sweeps from a jittered lattice (after the circles have grown to their radii).
MC_SOLID_SWEEPS = 60
#: The trial step is adapted towards this fraction of accepted moves.
MC_ACCEPTANCE = 0.4
#: Sweeps allowed for circles to grow back to their radii before placement gives up ...
MC_GROW_SWEEPS = 5000
#: ... or sweeps in a row without fewer circles short of their radii.
MC_GROW_PATIENCE = 500


@ti.func
def mix32(x):
    """A 32-bit integer hash with good avalanche (lowbias32)."""
    x ^= x >> ti.u32(16)
    x *= ti.u32(0x7FEB352D)
    x ^= x >> ti.u32(15)
    x *= ti.u32(0x846CA68B)
    x ^= x >> ti.u32(16)
    return x


@ti.func
def uniform(seed, i, k):
    """A float64 in [0, 1) from the counters (seed, i, k)."""
    h = mix32(ti.cast(seed, ti.u32) ^ mix32(ti.cast(i, ti.u32) ^ mix32(ti.cast(k, ti.u32) * ti.u32(0x9E3779B9))))
    return ti.cast(h, ti.f64) * (1.0 / 4294967296.0)


@ti.func
def stored(x, single: ti.template()):
    """x (float64) rounded to the storage precision: the value the simulation will hold."""
    y = x
    if ti.static(single):
        y = ti.cast(ti.cast(x, ti.f32), ti.f64)
    return y


@ti.func
def inside(x, r, box_w, box_h, periodic: ti.template()):
    """Whether a circle of radius r at x is CLEARANCE r inside the walls (in [0, W) x [0, H) if periodic)."""
    ok = True
    if ti.static(periodic):
        ok = 0.0 <= x[0] < box_w and 0.0 <= x[1] < box_h
    else:
        m = r * (1.0 + CLEARANCE)
        ok = m <= x[0] <= box_w - m and m <= x[1] <= box_h - m
    return ok


@ti.kernel
def _propose(pos: ndarr, radius: ndarr, placed: ndarr, proposing: ndarr, seed: ti.i32, first_draw: ti.i32,
             attempts: ti.i32, r_min: ti.f64, cell_of: ndarr, cell_start: ndarr, sorted_ids: ndarr, ncx: ti.i32, ncy: ti.i32,
             rows: ti.i32, segs: ti.i32, box_w: ti.f64, box_h: ti.f64, periodic: ti.template(),
             single: ti.template()):
    for i in range(pos.shape[0]):
        box = ti.Vector([box_w, box_h], dt=ti.f64)
        proposing[i] = 0
        if placed[i] == 0 and radius[i] > r_min:
            r = ti.cast(radius[i], ti.f64)
            for k in range(attempts):
                draw = first_draw + 2 * k
                u = ti.Vector([uniform(seed, i, draw), uniform(seed, i, draw + 1)])
                x = u * box
                if ti.static(not periodic):
                    x = r + u * (box - 2.0 * r)
                x = stored(x, single)
                free = inside(x, r, box_w, box_h, periodic)
                cx = ti.min(ti.max(ti.cast(ti.floor(x[0] / box_w * ncx), ti.i32), 0), ncx - 1)
                cy = ti.min(ti.max(ti.cast(ti.floor(x[1] / box_h * ncy), ti.i32), 0), ncy - 1)
                c = cell_index(cx, cy, ncx, periodic)
                for row, seg in ti.ndrange(rows, segs):
                    k_lo, k_hi = neighbour_range(c, row, seg, cell_start, ncx, ncy, periodic)
                    for m in range(k_lo, k_hi):
                        j = sorted_ids[m]
                        s = (r + ti.cast(radius[j], ti.f64)) * (1.0 + CLEARANCE)
                        d = displacement(x, ti.cast(pos[j], ti.f64), box, periodic)
                        if d.dot(d) < s * s:
                            free = False
                if free:
                    pos[i] = x
                    proposing[i] = 1
                    break


@ti.kernel
def _settle(pos: ndarr, radius: ndarr, placed: ndarr, proposing: ndarr, cell_of: ndarr, cell_start: ndarr,
            sorted_ids: ndarr, ncx: ti.i32, ncy: ti.i32, rows: ti.i32, segs: ti.i32, box_w: ti.f64, box_h: ti.f64,
            periodic: ti.template()) -> ti.i32:
    accepted = 0
    for i in range(pos.shape[0]):
        box = ti.Vector([box_w, box_h], dt=ti.f64)
        if proposing[i] != 0:
            ok = True
            c = cell_of[i]
            xi = ti.cast(pos[i], ti.f64)
            for row, seg in ti.ndrange(rows, segs):
                k_lo, k_hi = neighbour_range(c, row, seg, cell_start, ncx, ncy, periodic)
                for m in range(k_lo, k_hi):
                    j = sorted_ids[m]
                    if j < i:
                        s = ti.cast(radius[i] + radius[j], ti.f64) * (1.0 + CLEARANCE)
                        d = displacement(xi, ti.cast(pos[j], ti.f64), box, periodic)
                        if d.dot(d) < s * s:
                            ok = False
            if ok:
                placed[i] = 1
                accepted += 1
    return accepted


def seed_key(seed: int) -> int:
    """The 31-bit key of the placement's hash for a seed >= 0: the seed itself below 2**31, else
    a key drawn from all of its bits (so that seeds that differ only above bit 31 place apart)."""
    seed = int(seed)
    if seed < 1 << 31:
        return seed
    return int(np.random.SeedSequence(seed).generate_state(1, np.uint32)[0]) & 0x7FFFFFFF


def random_sequential(radius: np.ndarray, box, periodic: bool, seed: int, max_rounds: int = 400,
                      single: bool = False):
    """Positions (n, 2) float64 by parallel random sequential addition, or None if it jams.

    With `single` the positions are float32 values (as a float32 simulation stores them),
    checked after rounding.
    """
    n = radius.shape[0]
    rad = ti.ndarray(ti.f64, shape=n)
    rad.from_numpy(radius.astype(np.float64))
    pos = ti.Vector.ndarray(2, ti.f64, shape=n)
    placed = ti.ndarray(ti.i32, shape=n)
    proposing = ti.ndarray(ti.i32, shape=n)
    grid = Grid(n, box, periodic)
    reach = 2.0 * float(radius.max()) * (1.0 + 2 * CLEARANCE)
    unplaced = np.ones(n, bool)
    draw = 0
    seed32 = seed_key(seed)
    rounds = 0
    while unplaced.any():
        # The class of the largest unplaced circle, and how many circles it holds.
        r_min = float(radius[unplaced].max()) / CLASS_RATIO
        in_class = int(np.count_nonzero(unplaced & (radius > r_min)))
        remaining = in_class
        while remaining > 0:
            if rounds == max_rounds:
                return None
            rounds += 1
            # Few circles left: give each more tries per round (each round costs two grid builds).
            attempts = 1 if remaining > in_class // 4 else (4 if remaining > in_class // 64 else 16)
            grid.build(pos, reach, include=placed)
            _propose(pos, rad, placed, proposing, seed32, draw, attempts, r_min, *grid.args(), box[0], box[1],
                     periodic, single)
            draw += 2 * attempts
            grid.build(pos, reach, include=proposing)
            remaining -= _settle(pos, rad, placed, proposing, *grid.args(), box[0], box[1], periodic)
        unplaced &= ~(radius > r_min)
    return pos.to_numpy()


# ------------------------------------------------------------------ lattice start
def _lattice_shape(n, usable_w, usable_h, periodic):
    """(nx, ny, ax, ay, spacing): the hexagonal-like lattice of >= n sites with the largest nearest distance."""
    best = None
    ny_max = max(1, int(math.sqrt(n * max(usable_h, 1e-300) / max(usable_w, 1e-300) * 2)) + 3)
    for ny in range(1, min(n, ny_max * 2) + 1):
        nx = -(-n // ny)
        if periodic:
            ax, ay = usable_w / nx, usable_h / ny
            # Neighbours: along a row (ax), the next row (shifted by ax / 2), two rows on (same
            # shift, 2 ay); with an odd row count the last and first rows share a shift (ay).
            d = min(ax, math.hypot(ax / 2, ay), 2 * ay, ay if ny % 2 else math.inf)
        else:
            if ny == 1:
                ax = usable_w / (nx - 1) if nx > 1 else math.inf
                ay = math.inf
                d = ax
            elif nx == 1:
                # One column (at mid-width): neighbours are the rows next to each other.
                ax = math.inf
                ay = usable_h / (ny - 1)
                d = ay
            else:
                ax = usable_w / (nx - 0.5)
                ay = usable_h / (ny - 1)
                d = min(ax, math.hypot(ax / 2, ay), 2 * ay if ny > 2 else math.inf)
        if best is None or d > best[4]:
            best = (nx, ny, ax, ay, d)
    return best


def hexagonal(radius: np.ndarray, box, periodic: bool, rng: np.random.Generator, single: bool = False,
              fill: bool = False):
    """(positions, order): circles on a hexagonal lattice of at least n sites, in a random order.

    positions (n, 2) float64 are in site order (row by row), rounded to the storage precision
    (float32 values with `single`); order[k] is the circle at the k-th of them. Without `fill`
    each circle is jittered by at most half the free gap, so every pair is at least
    (r_i + r_j)(1 + CLEARANCE) apart and every circle r (1 + CLEARANCE) inside the walls, after
    rounding; raises ValueError if no lattice leaves that room. With `fill` each circle is
    uniform over FILL_BRICKS x FILL_BRICKS bricks around its site (a brick is the lattice
    spacing along a row times the row spacing; the bricks tile the plane), and circles may
    overlap.
    """
    n = radius.shape[0]
    w, h = box
    rmax = float(radius.max())
    rounding = rounding_margin(box, single)
    need = 2.0 * rmax * (1.0 + 4 * CLEARANCE) + 2.0 * rounding
    edge = rmax * (1.0 + CLEARANCE) + rounding  # nearest a site comes to a wall
    uw, uh = (w, h) if periodic else (w - 2 * edge, h - 2 * edge)
    nx, ny, ax, ay, spacing = _lattice_shape(n, uw, uh, periodic)
    if spacing < need and not fill:
        fraction = area_fraction(radius, box)
        raise ValueError(f"cannot place {n} circles of radius up to {rmax} in a {w} x {h} box "
                         f"(area fraction {fraction:.4f}): the best lattice leaves {spacing:.6g} between centres, "
                         f"below the largest diameter {2 * rmax:.6g} plus a clearance of {need - 2 * rmax:.3g}"
                         f"{' for float32 positions' if single else ''}; "
                         "use fewer or smaller circles or a bigger box")
    # Random vacancies, then the circles in a random order over the sites that are left.
    keep = np.ones(nx * ny, bool)
    if nx * ny > n:
        keep[rng.choice(nx * ny, nx * ny - n, replace=False)] = False
    site = np.flatnonzero(keep)
    order = np.arange(n, dtype=np.int32)
    rng.shuffle(order)
    rows, cols = site // nx, site % nx
    shift = 0.5 * (rows % 2)
    ax_, ay_ = (ax if np.isfinite(ax) else 0.0), (ay if np.isfinite(ay) else 0.0)
    if periodic:
        xs, ys = (cols + shift) * ax_, rows * ay_
    else:
        xs = edge + (cols + shift) * ax_
        ys = edge + rows * ay_
        if ny == 1:
            ys = np.full_like(xs, h / 2)
        if nx == 1:
            xs = np.full_like(ys, w / 2)
    if fill:
        # A single row or column spreads over the whole usable height or width.
        bx = FILL_BRICKS * ax_ if np.isfinite(ax) else uw
        by = FILL_BRICKS * ay_ if np.isfinite(ay) else uh
        pos = np.stack([xs + bx * (rng.uniform(0, 1, n) - 0.5), ys + by * (rng.uniform(0, 1, n) - 0.5)], axis=1)
    else:
        # A jitter of at most half the free gap per circle keeps every pair apart.
        amp = 0.5 * min(spacing - need, spacing) if np.isfinite(spacing) else 0.0
        ang = rng.uniform(0, 2 * np.pi, n)
        mag = amp * np.sqrt(rng.uniform(0, 1, n))
        pos = np.stack([xs + mag * np.cos(ang), ys + mag * np.sin(ang)], axis=1)
    if periodic:
        pos %= np.array([w, h])
    else:
        margin = radius[order] * (1.0 + CLEARANCE) + rounding
        for axis, side in ((0, w), (1, h)):
            lo, hi = margin, side - margin
            x = pos[:, axis]
            if fill:
                # Mirrored back inside, not clipped: circles piled on one line along a wall
                # would push each other only along it.
                x = np.where(x < lo, 2 * lo - x, x)
                x = np.where(x > hi, 2 * hi - x, x)
            # Clipping towards the site keeps each circle of the jittered lattice within
            # `amp` of it, so still apart.
            pos[:, axis] = np.clip(x, lo, hi)
    if single:
        pos = pos.astype(np.float32).astype(np.float64)
    if periodic:
        # Rounding or wrapping may give exactly W (or H): that is 0.
        pos[pos[:, 0] >= w, 0] = 0.0
        pos[pos[:, 1] >= h, 1] = 0.0
    return pos, order


def hexagonal_shrunk(radius: np.ndarray, box, periodic: bool, rng: np.random.Generator, single: bool = False):
    """(positions, order, scale): `hexagonal` for the radii times `scale` <= 1, the largest that fits."""
    scale = 1.0
    for _ in range(200):
        try:
            return (*hexagonal(radius * scale, box, periodic, rng, single), scale)
        except ValueError:
            if scale < 0.3:
                w, h = box
                fraction = area_fraction(radius, box)
                raise ValueError(f"cannot place {radius.shape[0]} circles of radius up to {float(radius.max())} in a "
                                 f"{w} x {h} box (area fraction {fraction:.4f}): no lattice of the largest radius "
                                 "holds them, even with every radius shrunk to 0.3 of its own to start; use "
                                 "fewer or smaller circles, a narrower spread of radii, or a bigger box") from None
            scale *= 0.98
    raise AssertionError("unreachable")


# ------------------------------------------------------------ cells of the parallel passes
@ti.func
def _draw_key(seed, draw):
    """A key for draw number `draw`; mix32(mix32(i) ^ key) is circle i's 32-bit number for it."""
    return mix32(ti.cast(seed, ti.u32) ^ mix32(ti.cast(draw, ti.u32) * ti.u32(0x9E3779B9)))


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


# ------------------------------------------------------------ overlap removal
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


# ------------------------------------------------------------ hard-disk Monte Carlo
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


# ------------------------------------------------------------------ the policy
def lattice_monte_carlo(radius: np.ndarray, box, periodic: bool, rng: np.random.Generator, single: bool = False,
                        sweeps: int = MC_SOLID_SWEEPS):
    """Positions (n, 2) in creation order: a jittered lattice (shrunk if need be), then Monte Carlo."""
    pos, order, scale = hexagonal_shrunk(radius, box, periodic, rng, single)
    target = radius[order]
    placed, _ = hard_disk_monte_carlo(pos, target * scale, target, box, periodic, rng, sweeps,
                                      _mean_gap(radius, box), single)
    out = np.empty_like(placed)
    out[order] = placed
    return out


def fluid(radius: np.ndarray, box, periodic: bool, rng: np.random.Generator, single: bool = False,
          sweeps: int = MC_FLUID_SWEEPS):
    """Positions (n, 2) in creation order: `relaxed_fill`, then Monte Carlo; None if overlaps remain."""
    filled = relaxed_fill(radius, box, periodic, rng, single)
    if filled is None:
        return None
    pos, rad, order, _ = filled
    placed, _ = hard_disk_monte_carlo(pos, rad, radius[order], box, periodic, rng, sweeps, _mean_gap(radius, box),
                                      single)
    out = np.empty_like(placed)
    out[order] = placed
    return out


def _mean_gap(radius, box):
    """The mean gap between neighbours of a hexagonal lattice at this area fraction: a first trial step."""
    fraction = area_fraction(radius, box)
    mean_r = float(radius.mean())
    gap = 2.0 * mean_r * (math.sqrt(DENSEST_PACKING / fraction) - 1.0)
    return max(gap, 1e-3 * mean_r)


def lattice_fits(radius: np.ndarray, box, periodic: bool, single: bool = False) -> bool:
    """Whether a hexagonal lattice of the largest radius holds the circles (else `hexagonal` shrinks them)."""
    rmax = float(radius.max())
    rounding = rounding_margin(box, single)
    edge = rmax * (1.0 + CLEARANCE) + rounding
    uw, uh = box if periodic else (box[0] - 2 * edge, box[1] - 2 * edge)
    spacing = _lattice_shape(radius.shape[0], uw, uh, periodic)[4]
    return spacing >= 2.0 * rmax * (1.0 + 4 * CLEARANCE) + 2.0 * rounding


def method(radius: np.ndarray, box, periodic: bool = False, single: bool = False) -> str:
    """The method `place` tries first for these circles."""
    fraction = area_fraction(radius, box)
    if fraction <= RSA_LIMIT:
        return "random sequential addition"
    if fraction <= FILL_LIMIT or not lattice_fits(radius, box, periodic, single):
        return "filled lattice, overlaps removed, Monte Carlo"
    return "jittered lattice, Monte Carlo"


def place(radius: np.ndarray, box, periodic: bool, seed: int, rng: np.random.Generator, single: bool = False):
    """Positions (n, 2) float64 in creation order (float32 values with `single`).

    Random sequential addition up to RSA_LIMIT; the filled lattice with its overlaps removed
    up to FILL_LIMIT, and above it too when the radii are too spread for a lattice of the
    largest one; else, or when the method before gives up
    (random sequential addition jams, overlaps remain after RELAX_PASSES passes), the jittered
    lattice. `seed` keys random sequential addition; the other methods draw from `rng`.
    Raises ValueError when the circles cannot be placed.
    """
    fraction = area_fraction(radius, box)
    pos = None
    try:
        if fraction <= RSA_LIMIT:
            pos = random_sequential(radius, box, periodic, seed, single=single)
        if pos is None and (fraction <= FILL_LIMIT or not lattice_fits(radius, box, periodic, single)):
            pos = fluid(radius, box, periodic, rng, single)
        if pos is None:
            pos = lattice_monte_carlo(radius, box, periodic, rng, single)
    except GrowthStalled as stalled:
        raise ValueError(_stalled_message(stalled, radius, box, periodic, single, fraction)) from None
    return pos


def largest_lattice_scale(radius: np.ndarray, box, periodic: bool, single: bool = False, lowest: float = 0.3):
    """The largest s in [lowest, 1] (to 1e-6) for which a hexagonal lattice of the largest radius
    times s holds the circles times s (`lattice_fits`), or None below `lowest`."""
    if not lattice_fits(radius * lowest, box, periodic, single):
        return None
    lo, hi = lowest, 1.0
    while hi - lo > 1e-6:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if lattice_fits(radius * mid, box, periodic, single) else (lo, mid)
    return lo


def _stalled_message(stalled, radius, box, periodic, single, fraction):
    """Why a placement stopped, with the area fraction and, when a lattice holds the circles at
    smaller radii, the area fraction it places them at."""
    w, h = box
    said = (f"cannot place {stalled.n} circles at area fraction {fraction:.4f} in a {w} x {h} box with "
            f"{'a periodic boundary' if periodic else 'walls'}: Monte Carlo could not grow {stalled.short} of "
            "them to their radii from a start at smaller radii (too close to jamming for these radii)")
    scale = largest_lattice_scale(radius, box, periodic, single)
    if scale is None:
        return said + "; use fewer or smaller circles, a narrower spread of radii, or a bigger box"
    reach = fraction * scale * scale
    return (said + f"; a hexagonal lattice of the largest radius holds them with every radius {scale:.6f} times "
            f"its own (area fraction {reach:.4f}), which places: use radii at most that many times these, fewer "
            "circles or a bigger box")
