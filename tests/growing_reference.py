"""Reference event-driven simulator of hard disks whose radii grow, in plain Python: the
yardstick for `circles.growth`, as `reference.Reference` is for the event scheme.

Every radius grows in proportion, r_i(t) = r0_i (1 + g t). The physics, written out here from
Lubachevsky and Stillinger (J. Stat. Phys. 60, 561 (1990)) and not from the engine:

- a pair touches when |dx + dv t| = s + G t, s the contact distance now and G = (r0_i + r0_j) g:
  the smaller root of (|dv|^2 - G^2) t^2 + 2 (dx.dv - s G) t + |dx|^2 - s^2, or the larger one
  when the pair parts now and growth outruns it;
- a collision turns the normal speed vn = (v_j - v_i).n into 2 G - vn, with the impulse shared by
  the inverse masses;
- a wall turns the normal speed of the circle towards it, v, into 2 r0 g - v (its surface
  moves at v - r0 g).

The search is one global heap over every pair, O(n) per event, with no cells and no per-circle
calendar. Periodic boxes take the minimum image only: a test keeps its horizon short enough
that no pair comes within reach through another image (`check_short_horizon`).
"""

import math

from reference import WALL_X0, WALL_XW, WALL_Y0, WALL_YH, Reference


def growing_time_of_impact(dx, dy, dvx, dvy, s, grow):
    """Time until a pair at separation (dx, dy), relative velocity (dvx, dvy), contact distance
    s growing at `grow`, touches; math.inf if never; 0 when touching and closing now."""
    b = dx * dvx + dy * dvy - s * grow
    c = dx * dx + dy * dy - s * s
    a = dvx * dvx + dvy * dvy - grow * grow
    if b < 0.0:
        disc = b * b - a * c
        if disc < 0.0:
            return math.inf
        return max(c / (-b + math.sqrt(disc)), 0.0)
    if a < 0.0:
        return (b + math.sqrt(max(b * b - a * c, 0.0))) / -a
    return math.inf


class GrowingReference(Reference):
    """`Reference` with radii r0 (1 + g t); `self.r` holds r0."""

    def __init__(self, pos, vel, radius, mass=None, box=(1.0, 1.0), boundary="walls", growth=0.0):
        self.g = float(growth)
        super().__init__(pos, vel, radius, mass, box, boundary)

    def scale(self):
        return 1.0 + self.g * self.time

    def _predict_pair(self, i, j):
        if j < i:
            i, j = j, i
        dx, dy = self._separation(i, j)
        s0 = self.r[i] + self.r[j]
        t = growing_time_of_impact(dx, dy, self.vx[j] - self.vx[i], self.vy[j] - self.vy[i], s0 * self.scale(),
                                   s0 * self.g)
        if t < math.inf:
            self._push(self.time + t, i, j)

    def _predict_walls(self, i):
        if self.periodic:
            return
        self._move(i, self.time)
        r, rg = self.r[i] * self.scale(), self.r[i] * self.g
        for position, velocity, side, low, high in ((self.x[i], self.vx[i], self.W, WALL_X0, WALL_XW),
                                                    (self.y[i], self.vy[i], self.H, WALL_Y0, WALL_YH)):
            if velocity < rg:  # the gap to the low wall, position - r, closes
                self._push(self.time + max((position - r) / (rg - velocity), 0.0), i, low)
            if -velocity < rg:  # the gap to the high wall, side - position - r, closes
                self._push(self.time + max((side - position - r) / (rg + velocity), 0.0), i, high)

    def _collide_pair(self, i, j):
        dx, dy = self._separation(i, j)
        d = math.hypot(dx, dy)
        nx, ny = dx / d, dy / d
        vn = (self.vx[j] - self.vx[i]) * nx + (self.vy[j] - self.vy[i]) * ny
        grow = (self.r[i] + self.r[j]) * self.g
        if vn >= grow:  # the surfaces do not close in
            return False
        J = 2.0 * (grow - vn) / (self.w[i] + self.w[j])
        self.vx[i] -= self.w[i] * J * nx
        self.vy[i] -= self.w[i] * J * ny
        self.vx[j] += self.w[j] * J * nx
        self.vy[j] += self.w[j] * J * ny
        self.virial += (self.r[i] + self.r[j]) * self.scale() * J
        self.pair_collisions += 1
        return True

    def _collide_wall(self, i, wall):
        self._move(i, self.time)
        rg = self.r[i] * self.g
        if wall in (WALL_X0, WALL_Y0):
            v = self.vx[i] if wall == WALL_X0 else self.vy[i]  # towards the inside
        else:
            v = -self.vx[i] if wall == WALL_XW else -self.vy[i]
        if v >= rg:
            return False
        new = 2.0 * rg - v
        self.wall_impulse += 2.0 * self.m[i] * (rg - v)
        if wall == WALL_X0:
            self.vx[i] = new
        elif wall == WALL_XW:
            self.vx[i] = -new
        elif wall == WALL_Y0:
            self.vy[i] = new
        else:
            self.vy[i] = -new
        self.wall_collisions += 1
        return True


def check_short_horizon(ref, until, vmax):
    """Assert that up to `until` no pair of a periodic box can reach another than its minimum
    image: every relative displacement stays below half the box less the largest contact
    distance then."""
    s_end = 2.0 * max(ref.r) * (1.0 + ref.g * until)
    assert 2.0 * vmax * until < min(ref.W, ref.H) / 2.0 - s_end, "the horizon is too long for the minimum image"


