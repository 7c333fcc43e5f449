"""Parallel random sequential addition, in size classes, largest first (see `circles.placement`)."""
import numpy as np
import taichi as ti

from ..geometry import cell_index, displacement, neighbour_range
from ..grid import Grid
from .sampling import CLEARANCE, inside, seed_key, stored, uniform

ndarr = ti.types.ndarray(ndim=1)


#: Size classes of random sequential addition: radii in (r / CLASS_RATIO, r] go together.
CLASS_RATIO = 2.0


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
