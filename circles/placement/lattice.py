"""The jittered hexagonal lattice start (see `circles.placement`)."""
import math

import numpy as np

from ..scene import area_fraction, rounding_margin
from .sampling import CLEARANCE

#: Each circle of the filled lattice starts uniform over this many bricks along each axis.
FILL_BRICKS = 3


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


def crystal_positions(nx, ny, box):
    """The centres of a perfect triangular crystal of nx columns and ny rows (ny even) filling a
    periodic box of aspect nx : ny sqrt(3)/2, in row order: circle (i, j) at
    x = (i + 1/4 + (j mod 2)/2) W/nx and y = (j + 1/2) H/ny, so every other row is shifted by
    half a spacing and no centre lies on a side of the box."""
    w, h = float(box[0]), float(box[1])
    a, b = w / nx, h / ny
    i, j = np.meshgrid(np.arange(nx), np.arange(ny))
    x = (i + 0.25 + 0.5 * (j % 2)) * a
    y = (j + 0.5) * b
    return np.stack([x.ravel(), y.ravel()], axis=1)
