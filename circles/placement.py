"""Random non-overlapping placement, from a seed.

Up to an area fraction of `RSA_LIMIT`: parallel random sequential addition. In each round
every unplaced circle tries a few random positions against the circles already placed and
proposes the first free one; a proposal that overlaps a proposal of a lower id is dropped,
so the result does not depend on thread timing. Random numbers come from a counter-based
hash of (seed, circle, attempt), not from a per-thread generator, for the same reason.
Circles are placed in size classes, largest first (radii within a factor `CLASS_RATIO` of
the largest unplaced one): a large circle needs a hole free of small ones, which a box
already sprinkled with small circles no longer has, while small circles always find room
between large ones.

Above it (RSA jams near 0.547 for equal disks): a hexagonal lattice whose spacing is the
largest that fits, with every site jittered by at most half the free gap and the circles
assigned to sites in a random order. The caller then melts it with the event scheme. When
the radii are too spread for a lattice of the largest one, the lattice takes the circles
shrunk by a common factor, and they grow back while the lattice melts (`grow`): each circle
grows by at most half its smallest gap, so no pair ever overlaps.
"""

import math

import numpy as np
import taichi as ti

from .geometry import displacement, neighbour_range
from .grid import Grid

ndarr = ti.types.ndarray(ndim=1)

#: Area fraction up to which random sequential addition is used.
RSA_LIMIT = 0.45
#: Placed circles keep this relative clearance, so rounding to float32 never makes an overlap.
CLEARANCE = 1e-6
#: Size classes of random sequential addition: radii in (r / CLASS_RATIO, r] go together.
CLASS_RATIO = 2.0


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


@ti.kernel
def _propose(pos: ndarr, radius: ndarr, placed: ndarr, proposing: ndarr, seed: ti.i32, first_draw: ti.i32,
             attempts: ti.i32, r_min: ti.f64, cell_of: ndarr, cell_start: ndarr, sorted_ids: ndarr, ncx: ti.i32, ncy: ti.i32,
             rows: ti.i32, segs: ti.i32, box_w: ti.f64, box_h: ti.f64, periodic: ti.template()):
    box = ti.Vector([box_w, box_h], dt=ti.f64)
    for i in range(pos.shape[0]):
        proposing[i] = 0
        if placed[i] == 0 and radius[i] > r_min:
            r = ti.cast(radius[i], ti.f64)
            for k in range(attempts):
                draw = first_draw + 2 * k
                u = ti.Vector([uniform(seed, i, draw), uniform(seed, i, draw + 1)])
                x = u * box
                if ti.static(not periodic):
                    x = r + u * (box - 2.0 * r)
                cx = ti.min(ti.max(ti.cast(ti.floor(x[0] / box_w * ncx), ti.i32), 0), ncx - 1)
                cy = ti.min(ti.max(ti.cast(ti.floor(x[1] / box_h * ncy), ti.i32), 0), ncy - 1)
                c = cy * ncx + cx
                free = True
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
    box = ti.Vector([box_w, box_h], dt=ti.f64)
    accepted = 0
    for i in range(pos.shape[0]):
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


def random_sequential(radius: np.ndarray, box, periodic: bool, seed: int, max_rounds: int = 400):
    """Positions (n, 2) float64 by parallel random sequential addition, or None if it jams."""
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
    seed32 = int(seed) & 0x7FFFFFFF
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
                     periodic)
            draw += 2 * attempts
            grid.build(pos, reach, include=proposing)
            remaining -= _settle(pos, rad, placed, proposing, *grid.args(), box[0], box[1], periodic)
        unplaced &= ~(radius > r_min)
    return pos.to_numpy()


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
            else:
                ax = usable_w / (nx - 0.5) if nx > 1 else math.inf
                ay = usable_h / (ny - 1)
                d = min(ax, math.hypot(ax / 2, ay), 2 * ay if ny > 2 else math.inf)
        if best is None or d > best[4]:
            best = (nx, ny, ax, ay, d)
    return best


def hexagonal(radius: np.ndarray, box, periodic: bool, rng: np.random.Generator):
    """Positions (n, 2) on a jittered hexagonal lattice, or raise ValueError if none fits."""
    n = radius.shape[0]
    w, h = box
    rmax = float(radius.max())
    need = 2.0 * rmax * (1.0 + 4 * CLEARANCE)
    uw, uh = (w, h) if periodic else (w - 2 * rmax, h - 2 * rmax)
    nx, ny, ax, ay, spacing = _lattice_shape(n, uw, uh, periodic)
    if spacing < need:
        fraction = float(np.sum(np.pi * radius ** 2)) / (w * h)
        raise ValueError(f"cannot place {n} circles of radius up to {rmax} in a {w} x {h} box "
                         f"(area fraction {fraction:.4f}): the best lattice leaves {spacing:.6g} between centres, "
                         f"below the largest diameter {2 * rmax:.6g}; use fewer or smaller circles or a bigger box")
    rows = np.repeat(np.arange(ny), nx)
    cols = np.tile(np.arange(nx), ny)
    shift = 0.5 * (rows % 2)
    if periodic:
        xs, ys = (cols + shift) * ax, rows * ay
    else:
        x0 = rmax
        xs = x0 + (cols + shift) * (ax if np.isfinite(ax) else 0.0)
        ys = rmax + rows * (ay if np.isfinite(ay) else 0.0)
        if ny == 1:
            ys = np.full_like(xs, h / 2)
        if nx == 1:
            xs = np.full_like(ys, w / 2)
    sites = np.stack([xs, ys], axis=1)
    chosen = sites[rng.permutation(len(sites))[:n]]
    # A jitter of at most half the free gap per circle keeps every pair apart.
    amp = 0.5 * min(spacing - need, spacing) if np.isfinite(spacing) else 0.0
    ang = rng.uniform(0, 2 * np.pi, n)
    mag = amp * np.sqrt(rng.uniform(0, 1, n))
    pos = chosen + np.stack([mag * np.cos(ang), mag * np.sin(ang)], axis=1)
    if periodic:
        pos %= np.array([w, h])
    else:
        # Clipping towards the site keeps each circle within `amp` of it, so still apart.
        pos[:, 0] = np.clip(pos[:, 0], radius, w - radius)
        pos[:, 1] = np.clip(pos[:, 1], radius, h - radius)
    return pos


def hexagonal_shrunk(radius: np.ndarray, box, periodic: bool, rng: np.random.Generator):
    """(positions, scale): a lattice start for the radii times `scale` <= 1, the largest that fits."""
    scale = 1.0
    for _ in range(200):
        try:
            return hexagonal(radius * scale, box, periodic, rng), scale
        except ValueError:
            if scale < 0.3:
                raise
            scale *= 0.98
    raise AssertionError("unreachable")


@ti.kernel
def _grow_limits(pos: ndarr, radius: ndarr, target: ndarr, new_radius: ndarr, cell_of: ndarr, cell_start: ndarr,
                 sorted_ids: ndarr, ncx: ti.i32, ncy: ti.i32, rows: ti.i32, segs: ti.i32, box_w: ti.f64, box_h: ti.f64,
                 real: ti.template(), periodic: ti.template()) -> ti.i32:
    box = ti.Vector([box_w, box_h], dt=ti.f64)
    short = 0
    for i in range(pos.shape[0]):
        xi = ti.cast(pos[i], ti.f64)
        ri = ti.cast(radius[i], ti.f64)
        allowed = ti.cast(target[i], ti.f64)
        if ti.static(not periodic):
            allowed = ti.min(allowed, ti.min(ti.min(xi[0], box_w - xi[0]), ti.min(xi[1], box_h - xi[1])))
        c = cell_of[i]
        for row, seg in ti.ndrange(rows, segs):
            k_lo, k_hi = neighbour_range(c, row, seg, cell_start, ncx, ncy, periodic)
            for m in range(k_lo, k_hi):
                j = sorted_ids[m]
                if j != i:
                    d = displacement(xi, ti.cast(pos[j], ti.f64), box, periodic).norm()
                    gap = d - ri - ti.cast(radius[j], ti.f64)
                    # Half the gap each, less a clearance so round-off never closes it.
                    allowed = ti.min(allowed, ri + 0.5 * gap * (1.0 - 1e-6))
        grown = ti.max(ri, allowed)
        new_radius[i] = ti.cast(grown, real)
        if grown < target[i]:
            short += 1
    return short


def grow(pos, radius, target, scratch, grid, box, real, periodic):
    """Grow every circle towards its target radius without overlap; returns how many are still short.

    `grid` must be built with a reach of at least the largest target diameter.
    """
    short = _grow_limits(pos, radius, target, scratch, *grid.args(), box[0], box[1], real, periodic)
    _copy(scratch, radius)
    return short


@ti.kernel
def _copy(src: ndarr, dst: ndarr):
    for i in range(src.shape[0]):
        dst[i] = src[i]
