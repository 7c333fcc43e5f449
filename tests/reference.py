"""Reference event-driven simulator of hard disks, in float64 and plain Python.

The contract: given positions, velocities, radii and masses of circles in a box
``[0, W] x [0, H]`` with reflecting walls or periodic boundaries, execute every
collision in time order, exactly as the physics model of ``circles`` defines it,
and record what happened. It is the yardstick the tests hold the engine's
``"event"`` scheme to, so it favours being obviously correct over being fast:

- One global priority queue (``heapq``) holds candidate events keyed by
  ``(time, i, j)``. A candidate stores the collision counters of the circles it
  involves when it was predicted; any collision of either circle afterwards
  makes it stale, and a stale candidate is dropped when it reaches the front.
- After a collision the circles involved predict again against every other
  circle and every wall: O(n) per event, fine for tens of circles.
- Each circle stores its position at its own time ``t_own`` and is moved only
  when it takes part in an event or is read, so round-off does not grow with
  the number of events elsewhere.
- Periodic boxes: images are searched in the 3 x 3 block around the minimum
  image. That finds every collision before the pair's relative displacement
  reaches ``min(W, H) / 2 - s``; if the earliest hit found lies beyond that
  horizon, a re-prediction of the pair is scheduled at the horizon instead.

Physics (as the README's section Physics states it):

- time of impact with ``dx = x_j - x_i``, ``dv = v_j - v_i``, ``s = r_i + r_j``,
  ``b = dx.dv``, ``a = dv.dv``, ``c = dx.dx - s^2``: an event exists when
  ``b < 0`` and ``b^2 - a c > 0`` at ``t = c / (-b + sqrt(b^2 - a c))``; a
  negative ``t`` (touching or overlapping and approaching) means now.
- pair impulse along the unit normal ``n`` from ``i`` to ``j``, with
  ``vn = (v_j - v_i).n < 0`` and ``w = 1/m``: ``J = 2 vn / (w_i + w_j)``,
  ``v_i += w_i J n``, ``v_j -= w_j J n``;
- walls reflect the normal velocity component at contact (``x = r``,
  ``x = W - r``, ``y = r``, ``y = H - r``) when it points outward.

Recorded, since the start: ``events`` as ``(time, i, j)`` with ``i < j`` for
pairs and ``j`` = -1 (x = 0 wall), -2 (x = W), -3 (y = 0), -4 (y = H) for
walls; ``pair_collisions``, ``wall_collisions``; ``virial`` (sum over pair
collisions of ``(r_i + r_j) |J|``) and ``wall_impulse`` (sum of ``2 m |v_n|``).

Also here, for the tests: ``random_disks`` (small random test scenes) and the
brute-force geometric checks ``pair_overlap`` and ``outside_walls``.
"""

import heapq
import math

import numpy as np

WALL_X0, WALL_XW, WALL_Y0, WALL_YH = -1, -2, -3, -4

_COLLISION = 0
_RECHECK = 1  # periodic only: predict a pair again once its search horizon is reached


def time_of_impact(dx, dy, dvx, dvy, s):
    """Time until two circles at separation ``(dx, dy)`` (j minus i) closing with
    relative velocity ``(dvx, dvy)`` touch at contact distance ``s``.

    Returns ``math.inf`` when they never touch; ``0.0`` when they touch or overlap
    now and approach. Uses ``c / (-b + sqrt(b^2 - a c))``, the root without
    cancellation.
    """
    b = dx * dvx + dy * dvy
    if b >= 0.0:
        return math.inf
    a = dvx * dvx + dvy * dvy
    c = dx * dx + dy * dy - s * s
    disc = b * b - a * c
    if disc <= 0.0:
        return math.inf
    t = c / (-b + math.sqrt(disc))
    return max(t, 0.0)


def mass_from_model(radius, mass):
    """Masses for a mass model name, or the given per-circle masses."""
    radius = np.asarray(radius, dtype=np.float64)
    if mass is None or (isinstance(mass, str) and mass == "radius"):
        return radius.copy()
    if isinstance(mass, str) and mass == "area":
        return radius * radius
    if isinstance(mass, str) and mass == "equal":
        return np.ones_like(radius)
    if isinstance(mass, str):
        raise ValueError(f"unknown mass model {mass!r}")
    return np.asarray(mass, dtype=np.float64).copy()


class Reference:
    """Exact event-driven simulation of elastic circles (see module docstring).

    Arrays given are copied; ``mass`` is ``None`` (proportional to radius),
    ``"radius"``, ``"area"``, ``"equal"`` or per-circle masses.
    """

    def __init__(self, pos, vel, radius, mass=None, box=(1.0, 1.0), boundary="walls"):
        pos = np.asarray(pos, dtype=np.float64)
        vel = np.asarray(vel, dtype=np.float64)
        radius = np.asarray(radius, dtype=np.float64)
        n = len(radius)
        if pos.shape != (n, 2) or vel.shape != (n, 2):
            raise ValueError("pos and vel must have shape (n, 2)")
        if boundary not in ("walls", "periodic"):
            raise ValueError(f"unknown boundary {boundary!r}")
        self.n = n
        self.W, self.H = float(box[0]), float(box[1])
        self.periodic = boundary == "periodic"
        self.x = [float(v) for v in pos[:, 0]]
        self.y = [float(v) for v in pos[:, 1]]
        self.vx = [float(v) for v in vel[:, 0]]
        self.vy = [float(v) for v in vel[:, 1]]
        self.r = [float(v) for v in radius]
        self.m = [float(v) for v in mass_from_model(radius, mass)]
        self.w = [1.0 / m for m in self.m]
        self.t_own = [0.0] * n
        self.count = [0] * n
        self.time = 0.0

        self.events = []
        self.pair_collisions = 0
        self.wall_collisions = 0
        self.virial = 0.0
        self.wall_impulse = 0.0

        if self.periodic:
            smax = 2.0 * max(self.r)
            if min(self.W, self.H) / 2.0 <= smax:
                raise ValueError("periodic box must exceed twice the largest diameter")
            self.x = [self._wrap(v, self.W) for v in self.x]
            self.y = [self._wrap(v, self.H) for v in self.y]
            self._images = [(ox, oy) for ox in (-1, 0, 1) for oy in (-1, 0, 1)]
        self._heap = []
        for i in range(n):
            self._predict_walls(i)
            for j in range(i + 1, n):
                self._predict_pair(i, j)

    # ---- motion -------------------------------------------------------

    @staticmethod
    def _wrap(v, length):
        v = v % length
        return v - length if v >= length else v

    def _move(self, i, t):
        """Bring circle i to time t (free flight)."""
        h = t - self.t_own[i]
        if h != 0.0:
            self.x[i] += self.vx[i] * h
            self.y[i] += self.vy[i] * h
            if self.periodic:
                self.x[i] = self._wrap(self.x[i], self.W)
                self.y[i] = self._wrap(self.y[i], self.H)
            self.t_own[i] = t

    def _separation(self, i, j):
        """x_j - x_i, y_j - y_i at the current time (minimum image if periodic)."""
        self._move(i, self.time)
        self._move(j, self.time)
        dx = self.x[j] - self.x[i]
        dy = self.y[j] - self.y[i]
        if self.periodic:
            dx -= self.W * round(dx / self.W)
            dy -= self.H * round(dy / self.H)
        return dx, dy

    # ---- prediction ---------------------------------------------------

    def _push(self, t, i, j, kind=_COLLISION):
        cj = self.count[j] if j >= 0 else -1
        heapq.heappush(self._heap, (t, i, j, self.count[i], cj, kind))

    def _predict_pair(self, i, j):
        if j < i:
            i, j = j, i
        dx, dy = self._separation(i, j)
        dvx = self.vx[j] - self.vx[i]
        dvy = self.vy[j] - self.vy[i]
        s = self.r[i] + self.r[j]
        if not self.periodic:
            t = time_of_impact(dx, dy, dvx, dvy, s)
            if t < math.inf:
                self._push(self.time + t, i, j)
            return
        t = min(time_of_impact(dx + ox * self.W, dy + oy * self.H, dvx, dvy, s)
                for ox, oy in self._images)
        speed = math.hypot(dvx, dvy)
        if speed == 0.0:
            return
        horizon = (min(self.W, self.H) / 2.0 - s) / speed
        if t <= horizon:
            self._push(self.time + t, i, j)
        else:
            self._push(self.time + horizon, i, j, _RECHECK)

    def _predict_walls(self, i):
        if self.periodic:
            return
        self._move(i, self.time)
        r = self.r[i]
        if self.vx[i] < 0.0:
            self._push(self.time + max((self.x[i] - r) / -self.vx[i], 0.0), i, WALL_X0)
        elif self.vx[i] > 0.0:
            self._push(self.time + max((self.W - r - self.x[i]) / self.vx[i], 0.0), i, WALL_XW)
        if self.vy[i] < 0.0:
            self._push(self.time + max((self.y[i] - r) / -self.vy[i], 0.0), i, WALL_Y0)
        elif self.vy[i] > 0.0:
            self._push(self.time + max((self.H - r - self.y[i]) / self.vy[i], 0.0), i, WALL_YH)

    def _predict(self, i, skip=-1):
        self._predict_walls(i)
        for k in range(self.n):
            if k != i and k != skip:
                self._predict_pair(i, k)

    # ---- collisions ---------------------------------------------------

    def _collide_pair(self, i, j):
        dx, dy = self._separation(i, j)
        d = math.hypot(dx, dy)
        nx, ny = dx / d, dy / d
        vn = (self.vx[j] - self.vx[i]) * nx + (self.vy[j] - self.vy[i]) * ny
        if vn >= 0.0:  # not approaching: nothing to resolve
            return False
        J = 2.0 * vn / (self.w[i] + self.w[j])
        self.vx[i] += self.w[i] * J * nx
        self.vy[i] += self.w[i] * J * ny
        self.vx[j] -= self.w[j] * J * nx
        self.vy[j] -= self.w[j] * J * ny
        self.virial += (self.r[i] + self.r[j]) * abs(J)
        self.pair_collisions += 1
        return True

    def _collide_wall(self, i, wall):
        self._move(i, self.time)
        if wall in (WALL_X0, WALL_XW):
            outward = self.vx[i] < 0.0 if wall == WALL_X0 else self.vx[i] > 0.0
            if not outward:
                return False
            self.wall_impulse += 2.0 * self.m[i] * abs(self.vx[i])
            self.vx[i] = -self.vx[i]
        else:
            outward = self.vy[i] < 0.0 if wall == WALL_Y0 else self.vy[i] > 0.0
            if not outward:
                return False
            self.wall_impulse += 2.0 * self.m[i] * abs(self.vy[i])
            self.vy[i] = -self.vy[i]
        self.wall_collisions += 1
        return True

    # ---- driver -------------------------------------------------------

    def run(self, until=None, max_events=None, max_pair_collisions=None):
        """Execute events in time order.

        Stops before the first event later than ``until`` (then moves the clock
        to ``until``), or once ``max_events`` events (pairs and walls) or
        ``max_pair_collisions`` pair collisions have been executed by this call
        or before, whichever comes first. Returns ``self``.
        """
        while self._heap:
            if max_events is not None and len(self.events) >= max_events:
                break
            if max_pair_collisions is not None and self.pair_collisions >= max_pair_collisions:
                break
            t, i, j, ci, cj, kind = self._heap[0]
            if until is not None and t > until:
                break
            heapq.heappop(self._heap)
            if self.count[i] != ci or (j >= 0 and self.count[j] != cj):
                continue  # stale: one of the circles has collided since
            self.time = t
            if kind == _RECHECK:
                self._predict_pair(i, j)
                continue
            if j >= 0:
                done = self._collide_pair(i, j)
            else:
                done = self._collide_wall(i, j)
            if not done:  # cannot happen for a correct prediction; keep going safely
                continue
            self.events.append((t, i, j))
            self.count[i] += 1
            if j >= 0:
                self.count[j] += 1
                self._predict(i)
                self._predict(j, skip=i)
            else:
                self._predict(i)
        if until is not None and until > self.time:
            self.time = until
        return self

    # ---- read-out -----------------------------------------------------

    @property
    def pos(self):
        """Positions at ``self.time``, shape (n, 2) (wrapped into the box if periodic)."""
        for i in range(self.n):
            self._move(i, self.time)
        return np.column_stack([self.x, self.y])

    @property
    def vel(self):
        return np.column_stack([self.vx, self.vy])

    @property
    def mass(self):
        return np.array(self.m)

    @property
    def radius(self):
        return np.array(self.r)

    def kinetic_energy(self):
        """Sum of m v^2 / 2, accumulated with math.fsum."""
        return math.fsum(0.5 * m * (vx * vx + vy * vy)
                         for m, vx, vy in zip(self.m, self.vx, self.vy))

    def momentum(self):
        return (math.fsum(m * v for m, v in zip(self.m, self.vx)),
                math.fsum(m * v for m, v in zip(self.m, self.vy)))

    def events_array(self):
        """Recorded events as a float64 array (k, 3) of [time, i, j]."""
        return np.array(self.events, dtype=np.float64).reshape(-1, 3)


def random_disks(n, box, radius, rng, speed=(0.5, 1.0), max_tries=100_000):
    """Non-overlapping random circles inside the walls, by random sequential
    addition (test scenes only: O(n^2)). ``radius`` is a float or (rmin, rmax).
    Returns pos (n, 2), vel (n, 2), radius (n,)."""
    W, H = box
    if np.isscalar(radius):
        r = np.full(n, float(radius))
    else:
        r = rng.uniform(radius[0], radius[1], n)
    r = np.sort(r)[::-1].copy()  # large first: denser packings succeed
    pos = np.zeros((n, 2))
    for i in range(n):
        for _ in range(max_tries):
            p = rng.uniform((r[i], r[i]), (W - r[i], H - r[i]))
            d = np.hypot(*(pos[:i] - p).T)
            if np.all(d > (r[:i] + r[i]) * (1 + 1e-6)):
                pos[i] = p
                break
        else:
            raise RuntimeError("could not place the circles")
    angle = rng.uniform(0.0, 2.0 * np.pi, n)
    v = rng.uniform(speed[0], speed[1], n)
    vel = np.column_stack([v * np.cos(angle), v * np.sin(angle)])
    order = rng.permutation(n)
    return pos[order], vel[order], r[order]


def pair_overlap(pos, radius, box=None):
    """Largest ``(r_i + r_j - d_ij) / (r_i + r_j)`` over all pairs, by brute
    force in chunks (minimum image when ``box`` is given: periodic). Negative
    when no pair touches."""
    pos = np.asarray(pos, dtype=np.float64)
    radius = np.asarray(radius, dtype=np.float64)
    n = len(radius)
    worst = -np.inf
    chunk = max(1, 2_000_000 // max(n, 1))
    for start in range(0, n, chunk):
        stop = min(n, start + chunk)
        d = pos[None, :, :] - pos[start:stop, None, :]
        if box is not None:
            size = np.asarray(box, dtype=np.float64)
            d -= np.round(d / size) * size
        dist = np.sqrt(np.sum(d * d, axis=-1))
        contact = radius[None, :] + radius[start:stop, None]
        rel = (contact - dist) / contact
        rows = np.arange(start, stop)
        rel[np.arange(stop - start), rows] = -np.inf  # no self pairs
        worst = max(worst, float(rel.max()))
    return worst


def outside_walls(pos, radius, box):
    """Largest distance by which a circle crosses a wall, relative to its radius
    (positive means outside by that fraction)."""
    pos = np.asarray(pos, dtype=np.float64)
    r = np.asarray(radius, dtype=np.float64)
    W, H = box
    cross = np.max(np.stack([r - pos[:, 0], pos[:, 0] + r - W,
                             r - pos[:, 1], pos[:, 1] + r - H]), axis=0)
    return float(np.max(cross / r))
