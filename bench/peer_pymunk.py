"""The peer: pymunk (Chipmunk2D) on the same scene, and a numpy overlap check for any state.

Chipmunk is set up as an elastic hard-disk gas: elasticity 1 on every shape (Chipmunk
multiplies the two), friction 0, no gravity, no damping, infinite moments (no rotation),
a spatial hash with cells one diameter wide, and the walls as four static segments of zero
thickness on the box edges. Its solver is iterative and allows a small overlap
(`collision_slop`) which it pushes out with a bias velocity; we set the slop to
`SLOP_FRACTION` of the diameter, far below its default of 0.1 world units, so that its
overlap is comparable with ours. Everything else keeps Chipmunk's defaults (10 solver
iterations, default collision bias). Chipmunk runs single-threaded.
"""
from __future__ import annotations

import math

import numpy as np
import pymunk

#: Allowed penetration as a fraction of the smallest diameter.
SLOP_FRACTION = 1e-3
#: Hash-table size per circle (Chipmunk's guide: about 10 times the number of objects).
HASH_CELLS_PER_CIRCLE = 10

CIRCLE, WALL = 1, 2


class PymunkGas:
    """Circles with the given state in a walled box, in a pymunk Space.

    pos, vel (n, 2), radius, mass (n,): float64 world units; box (W, H).
    With `observe`, begin and post-solve callbacks count circle-circle contacts and sum the
    pair virial (r_i + r_j) |J|; they cost Python calls, so timed runs leave them off.
    """

    def __init__(self, pos, vel, radius, mass, box, observe=False):
        self.n = len(radius)
        self.box = (float(box[0]), float(box[1]))
        self.radius = np.asarray(radius, dtype=np.float64)
        self.mass = np.asarray(mass, dtype=np.float64)
        space = pymunk.Space()
        space.gravity = (0.0, 0.0)
        space.damping = 1.0
        space.collision_slop = SLOP_FRACTION * 2.0 * float(self.radius.min())
        space.use_spatial_hash(2.0 * float(self.radius.max()), HASH_CELLS_PER_CIRCLE * self.n)
        self.bodies = []
        shapes = []
        for p, v, r, m in zip(np.asarray(pos, dtype=np.float64), np.asarray(vel, dtype=np.float64),
                              self.radius, self.mass):
            body = pymunk.Body(float(m), math.inf)
            body.position = (float(p[0]), float(p[1]))
            body.velocity = (float(v[0]), float(v[1]))
            shape = pymunk.Circle(body, float(r))
            shape.elasticity = 1.0
            shape.friction = 0.0
            shape.collision_type = CIRCLE
            self.bodies.append(body)
            shapes.append(body)
            shapes.append(shape)
        w, h = self.box
        corners = [(0.0, 0.0), (w, 0.0), (w, h), (0.0, h)]
        for a, b in zip(corners, corners[1:] + corners[:1]):
            seg = pymunk.Segment(space.static_body, a, b, 0.0)
            seg.elasticity = 1.0
            seg.friction = 0.0
            seg.collision_type = WALL
            shapes.append(seg)
        space.add(*shapes)
        self.space = space
        self.pair_collisions = 0
        self.virial = 0.0
        if observe:
            space.on_collision(CIRCLE, CIRCLE, begin=self._begin, post_solve=self._post_solve)

    def _begin(self, arbiter, space, data):
        self.pair_collisions += 1

    def _post_solve(self, arbiter, space, data):
        a, b = arbiter.shapes
        self.virial += (a.radius + b.radius) * abs(arbiter.total_impulse)

    def step(self, dt, k=1):
        step = self.space.step
        for _ in range(k):
            step(dt)

    def positions(self):
        return np.array([tuple(b.position) for b in self.bodies], dtype=np.float64)

    def velocities(self):
        return np.array([tuple(b.velocity) for b in self.bodies], dtype=np.float64)

    def kinetic_energy(self):
        v = self.velocities()
        return float(0.5 * np.sum(self.mass * (v[:, 0] ** 2 + v[:, 1] ** 2)))

    def max_overlap(self):
        return max_overlap(self.positions(), self.radius, self.box)


def max_overlap(pos, radius, box):
    """Largest (r_i + r_j - d_ij) / (r_i + r_j) over pairs in a walled box, 0 when none.

    The same measure as `Simulation.stats()["max_overlap"]`, by a cell list in numpy: cells at
    least a largest diameter wide, the ids of each cell padded into a dense table, and every
    cell compared with itself and four neighbours (each pair once).
    """
    pos = np.asarray(pos, dtype=np.float64)
    radius = np.asarray(radius, dtype=np.float64)
    n = len(radius)
    if n < 2:
        return 0.0
    w, h = box
    reach = 2.0 * float(radius.max())
    ncx = max(1, int(w / reach))
    ncy = max(1, int(h / reach))
    # Circles pushed outside the walls (a peer may allow that) go to the border cells.
    cx = np.clip(np.floor(pos[:, 0] * (ncx / w)).astype(np.int64), 0, ncx - 1)
    cy = np.clip(np.floor(pos[:, 1] * (ncy / h)).astype(np.int64), 0, ncy - 1)
    cell = cx * ncy + cy
    order = np.argsort(cell, kind="stable")
    counts = np.bincount(cell, minlength=ncx * ncy)
    start = np.cumsum(counts) - counts
    slot = np.arange(n) - start[cell[order]]
    k = int(counts.max())
    table = np.full((ncx + 2, ncy + 2, k), -1, dtype=np.int64)
    table[cx[order] + 1, cy[order] + 1, slot] = order
    best = 0.0
    home = table[1:-1, 1:-1]
    for dx, dy in ((0, 0), (1, -1), (1, 0), (1, 1), (0, 1)):
        other = table[1 + dx:ncx + 1 + dx, 1 + dy:ncy + 1 + dy]
        a = np.broadcast_to(home[..., :, None], home.shape + (k,))
        b = np.broadcast_to(other[..., None, :], home.shape + (k,))
        keep = (a >= 0) & (b >= 0)
        if dx == 0 and dy == 0:
            keep &= a < b
        i, j = a[keep], b[keep]
        if len(i) == 0:
            continue
        d = pos[j] - pos[i]
        s = radius[i] + radius[j]
        overlap = (s - np.sqrt((d * d).sum(axis=1))) / s
        best = max(best, float(overlap.max()))
    return max(best, 0.0)


if __name__ == "__main__":
    import sys

    _USE = ("peer_pymunk.py is a module used by bench/bench.py (its peers and work-precision sections), not a "
            "command: run the pymunk rows with `python bench/bench.py --skip throughput,placement,memory,spread,wp` "
            "(add --quick for smaller sizes)")
    if sys.argv[1:] in (["-h"], ["--help"]):
        print(_USE)
        sys.exit(0)
    print(f"usage: {_USE}", file=sys.stderr)
    sys.exit(2)
