"""Event-driven hard disks whose radii grow: the kernels of compression (`circles.compress`).

Every radius grows in proportion, r_i(T) = r0_i (1 + g T), T the compression's clock, so a
pair's contact distance s(T) = (r0_i + r0_j)(1 + g T) grows linearly and its time of impact is
a root of a quadratic, exactly as for disks of fixed size:

    |dx + dv t|^2 = (s + G t)^2,  G = (r0_i + r0_j) g,

that is ``(|dv|^2 - G^2) t^2 + 2 (dx.dv - s G) t + (|dx|^2 - s^2) = 0``. A collision reflects
the pair's normal velocity in the frame of their growing surfaces (Lubachevsky and Stillinger,
J. Stat. Phys. 60, 561 (1990)): the normal speed u of j away from i becomes ``2 G - u``, so the
pair parts faster than their radii close in; a wall reflects v_n to ``2 r0 g - v_n``. Growth
pumps energy in; the caller rescales the speeds between calls.

The scheme is the classic serial one: each circle holds its next event (a partner, a wall or
the side of its cell) in a binary heap keyed by time, partners checked by collision counts
(an event whose partner has collided since it was predicted is predicted again), and a grid of
cells at least a diameter wide (at the largest radii the call reaches). It runs on one thread:
a jammed packing needs millions of events among few circles, where a parallel step has
nothing to share out.

All arrays are numpy arrays, passed to the kernels in place (float64 and int32): the state
between calls is the caller's to read and rescale.
"""

import taichi as ti

#: Event partners below 0: a wall (x = 0, x = W, y = 0, y = H), the side of the cell (the
#: same four directions), or nothing.
WALL_LEFT, WALL_RIGHT, WALL_BOTTOM, WALL_TOP = -1, -2, -3, -4
CELL_LEFT, CELL_RIGHT, CELL_DOWN, CELL_UP = -5, -6, -7, -8
NOTHING = -10
#: A time later than any call reaches.
NEVER = 1.0e30

#: Indices of the totals array that `run` adds to (LOGGED: the rows of the event log written).
PAIRS, WALLS, VIRIAL, WALL_IMPULSE, TIME, EVENTS, LOGGED = range(7)

arr1 = ti.types.ndarray(ndim=1)
arr2 = ti.types.ndarray(ndim=2)


@ti.func
def _pair_time(dx, dv, s, grow):
    """Time from now until circles at displacement dx (j - i), relative velocity dv (j - i) and
    contact distance s, growing at `grow` (ds/dt), touch; NEVER if they do not. A pair in
    contact or overlapping by round-off that closes in collides now (0); one that parts meets
    again only when growth outruns it."""
    b = dx.dot(dv) - s * grow  # half the rate at which the gap squared closes
    c = dx.dot(dx) - s * s
    a = dv.dot(dv) - grow * grow
    t = ti.cast(NEVER, ti.f64)  # float64 throughout: a literal alone would take Taichi's default, float32
    if b < 0.0:
        disc = b * b - a * c
        if disc >= 0.0:
            t = ti.max(c / (-b + ti.sqrt(disc)), 0.0)
    elif a < 0.0:
        t = (b + ti.sqrt(ti.max(b * b - a * c, 0.0))) / (-a)
    return t


@ti.func
def _wrap(d, w, periodic: ti.template()):
    if ti.static(periodic):
        d -= w * ti.floor(d / w + 0.5)
    return d


@ti.func
def _predict(i, now, x: arr2, v: arr2, tau: arr1, r0: arr1, count: arr1, ev_t: arr1, ev_p: arr1, ev_c: arr1,
             head: arr1, nxt: arr1, cell: arr1, params: arr1, periodic: ti.template()):
    """The next event of circle i, whose clock is `now`: ev_t, ev_p, ev_c."""
    w, h, g = params[0], params[1], params[2]
    ncx, ncy = ti.cast(params[3], ti.i32), ti.cast(params[4], ti.i32)
    cw, ch = params[5], params[6]
    scale = 1.0 + g * now
    best = ti.cast(NEVER, ti.f64)
    partner = NOTHING
    cx, cy = cell[i] % ncx, cell[i] // ncx
    # The neighbouring columns and rows, each once: all of them when there are fewer than 3.
    x_lo, x_n, y_lo, y_n = -1, 3, -1, 3
    if ncx < 3:
        x_lo, x_n = -cx, ncx
    if ncy < 3:
        y_lo, y_n = -cy, ncy
    for oy in range(y_n):
        for ox in range(x_n):
            kx, ky = cx + x_lo + ox, cy + y_lo + oy
            inside = True
            if ti.static(periodic):
                kx = (kx + ncx) % ncx
                ky = (ky + ncy) % ncy
            else:
                inside = 0 <= kx < ncx and 0 <= ky < ncy
            if inside:
                j = head[ky * ncx + kx]
                while j >= 0:
                    if j != i:
                        # Vectors made here, in the loop, never at the function's top level (tests/test_gpu_rules.py).
                        ahead = now - tau[j]
                        d = ti.Vector([_wrap(x[j, 0] + v[j, 0] * ahead - x[i, 0], w, periodic),
                                       _wrap(x[j, 1] + v[j, 1] * ahead - x[i, 1], h, periodic)])
                        dv = ti.Vector([v[j, 0] - v[i, 0], v[j, 1] - v[i, 1]])
                        s0 = r0[i] + r0[j]
                        t = _pair_time(d, dv, s0 * scale, s0 * g)
                        if t < best or (t == best and j < partner):
                            best, partner = t, j
                    j = nxt[j]
    r = r0[i] * scale
    rg = r0[i] * g
    if ti.static(not periodic):
        # A wall: the gap x - r closes at rg - v.
        for k in ti.static(range(2)):
            side = w if k == 0 else h
            if v[i, k] - rg < 0.0:
                t = ti.max((x[i, k] - r) / (rg - v[i, k]), 0.0)
                if t < best:
                    best, partner = t, WALL_LEFT if k == 0 else WALL_BOTTOM
            if -v[i, k] - rg < 0.0:
                t = ti.max((side - x[i, k] - r) / (rg + v[i, k]), 0.0)
                if t < best:
                    best, partner = t, WALL_RIGHT if k == 0 else WALL_TOP
    # The side of its cell.
    for k in ti.static(range(2)):
        size = cw if k == 0 else ch
        lower = (cx if k == 0 else cy) * size
        if v[i, k] > 0.0:
            t = ti.max((lower + size - x[i, k]) / v[i, k], 0.0)
            if t < best:
                best, partner = t, CELL_RIGHT if k == 0 else CELL_UP
        elif v[i, k] < 0.0:
            t = ti.max((lower - x[i, k]) / v[i, k], 0.0)
            if t < best:
                best, partner = t, CELL_LEFT if k == 0 else CELL_DOWN
    ev_t[i] = now + best
    ev_p[i] = partner
    ev_c[i] = 0
    if partner >= 0:
        ev_c[i] = count[partner]


@ti.func
def _less(a, b, ev_t: arr1):
    return ev_t[a] < ev_t[b] or (ev_t[a] == ev_t[b] and a < b)


@ti.func
def _swap(a, b, heap: arr1, where: arr1):
    heap[a], heap[b] = heap[b], heap[a]
    where[heap[a]] = a
    where[heap[b]] = b


@ti.func
def _down(k, n, heap: arr1, where: arr1, ev_t: arr1):
    """Sift slot k of a heap of n down to its place."""
    while True:
        least = k
        left = 2 * k + 1
        if left < n and _less(heap[left], heap[least], ev_t):
            least = left
        if left + 1 < n and _less(heap[left + 1], heap[least], ev_t):
            least = left + 1
        if least == k:
            break
        _swap(k, least, heap, where)
        k = least


@ti.func
def _sift(k, n, heap: arr1, where: arr1, ev_t: arr1):
    """Restore the heap after the time of slot k changed: up towards the root, or down."""
    while k > 0 and _less(heap[k], heap[(k - 1) // 2], ev_t):
        _swap(k, (k - 1) // 2, heap, where)
        k = (k - 1) // 2
    _down(k, n, heap, where, ev_t)


@ti.func
def _unlink(i, head: arr1, nxt: arr1, prv: arr1, cell: arr1):
    if prv[i] >= 0:
        nxt[prv[i]] = nxt[i]
    else:
        head[cell[i]] = nxt[i]
    if nxt[i] >= 0:
        prv[nxt[i]] = prv[i]


@ti.func
def _link(i, c, head: arr1, nxt: arr1, prv: arr1, cell: arr1):
    cell[i] = c
    prv[i] = -1
    nxt[i] = head[c]
    if head[c] >= 0:
        prv[head[c]] = i
    head[c] = i


@ti.func
def _log(log: arr2, totals: arr1, now, i, j):
    row = ti.cast(totals[LOGGED], ti.i32)
    if row < log.shape[0]:
        log[row, 0] = now
        log[row, 1] = ti.cast(i, ti.f64)
        log[row, 2] = ti.cast(j, ti.f64)
        totals[LOGGED] += 1.0


@ti.kernel
def start(x: arr2, v: arr2, tau: arr1, r0: arr1, count: arr1, ev_t: arr1, ev_p: arr1, ev_c: arr1,
          head: arr1, nxt: arr1, prv: arr1, cell: arr1, heap: arr1, where: arr1, params: arr1,
          periodic: ti.template()):
    """Sort the circles (clocks all params[7]) into cells, predict every event, build the heap."""
    n = x.shape[0]
    ncx, ncy = ti.cast(params[3], ti.i32), ti.cast(params[4], ti.i32)
    cw, ch = params[5], params[6]
    now = params[7]
    ti.loop_config(serialize=True)
    for c in range(head.shape[0]):
        head[c] = -1
    ti.loop_config(serialize=True)
    for i in range(n):
        cx = ti.min(ti.max(ti.cast(ti.floor(x[i, 0] / cw), ti.i32), 0), ncx - 1)
        cy = ti.min(ti.max(ti.cast(ti.floor(x[i, 1] / ch), ti.i32), 0), ncy - 1)
        _link(i, cy * ncx + cx, head, nxt, prv, cell)
    for i in range(n):
        _predict(i, now, x, v, tau, r0, count, ev_t, ev_p, ev_c, head, nxt, cell, params, periodic)
    ti.loop_config(serialize=True)
    for k in range(n):
        heap[k] = k
        where[k] = k
    ti.loop_config(serialize=True)
    for k in range(n // 2):
        _down(n // 2 - 1 - k, n, heap, where, ev_t)


@ti.kernel
def run(x: arr2, v: arr2, tau: arr1, r0: arr1, inv_m: arr1, count: arr1, ev_t: arr1, ev_p: arr1, ev_c: arr1,
        head: arr1, nxt: arr1, prv: arr1, cell: arr1, heap: arr1, where: arr1, params: arr1, totals: arr1,
        log: arr2, end: ti.f64, most: ti.i64, periodic: ti.template()):
    """Carry out events in order up to time `end` or `most` events, whichever comes first;
    totals[TIME] is then the time reached (the last event's, or `end`). Each collision that
    changes velocities goes into `log` as (time, i, j) while it has rows left: i < j for a
    pair, j the wall's code for a wall."""
    n = x.shape[0]
    w, h, g = params[0], params[1], params[2]
    ncx, ncy = ti.cast(params[3], ti.i32), ti.cast(params[4], ti.i32)
    done = ti.cast(0, ti.i64)
    reached = end  # or the last event's time, when `most` events stop the run first
    while done < most:
        i = heap[0]
        now = ev_t[i]
        if now > end:
            reached = end
            break
        done += 1
        reached = now
        p = ev_p[i]
        # Circle i to the event's time.
        for k in ti.static(range(2)):
            x[i, k] += v[i, k] * (now - tau[i])
        tau[i] = now
        if p >= 0 and count[p] != ev_c[i]:
            pass  # its partner has collided since: predict again below
        elif p >= 0:
            for k in ti.static(range(2)):
                x[p, k] += v[p, k] * (now - tau[p])
            tau[p] = now
            d = ti.Vector([x[p, 0] - x[i, 0], x[p, 1] - x[i, 1]])
            d[0] = _wrap(d[0], w, periodic)
            d[1] = _wrap(d[1], h, periodic)
            normal = d / d.norm()
            s0 = r0[i] + r0[p]
            grow = s0 * g
            u = (v[p, 0] - v[i, 0]) * normal[0] + (v[p, 1] - v[i, 1]) * normal[1]
            change = 2.0 * (grow - u)  # u to 2 grow - u
            if change > 0.0:
                share = change / (inv_m[i] + inv_m[p])  # the impulse
                for k in ti.static(range(2)):
                    v[i, k] -= share * inv_m[i] * normal[k]
                    v[p, k] += share * inv_m[p] * normal[k]
                totals[PAIRS] += 1.0
                totals[VIRIAL] += share * s0 * (1.0 + g * now)
                _log(log, totals, now, ti.min(i, p), ti.max(i, p))
            count[i] += 1
            count[p] += 1
            _predict(p, now, x, v, tau, r0, count, ev_t, ev_p, ev_c, head, nxt, cell, params, periodic)
            _sift(where[p], n, heap, where, ev_t)
        elif p >= WALL_TOP:
            k = 0 if p >= WALL_RIGHT else 1
            sign = 1.0 if p == WALL_LEFT or p == WALL_BOTTOM else -1.0  # the wall's inward normal
            rg = r0[i] * g
            vn = v[i, k] * sign
            if vn < rg:
                v[i, k] = (2.0 * rg - vn) * sign
                totals[WALLS] += 1.0
                totals[WALL_IMPULSE] += 2.0 * (rg - vn) / inv_m[i]
                _log(log, totals, now, i, p)
            count[i] += 1
        elif p >= CELL_UP:
            cx, cy = cell[i] % ncx, cell[i] // ncx
            if p == CELL_LEFT:
                cx -= 1
            elif p == CELL_RIGHT:
                cx += 1
            elif p == CELL_DOWN:
                cy -= 1
            else:
                cy += 1
            if ti.static(periodic):
                if cx < 0:
                    cx += ncx
                    x[i, 0] += w
                elif cx >= ncx:
                    cx -= ncx
                    x[i, 0] -= w
                if cy < 0:
                    cy += ncy
                    x[i, 1] += h
                elif cy >= ncy:
                    cy -= ncy
                    x[i, 1] -= h
            else:
                cx = ti.min(ti.max(cx, 0), ncx - 1)
                cy = ti.min(ti.max(cy, 0), ncy - 1)
            _unlink(i, head, nxt, prv, cell)
            _link(i, cy * ncx + cx, head, nxt, prv, cell)
        _predict(i, now, x, v, tau, r0, count, ev_t, ev_p, ev_c, head, nxt, cell, params, periodic)
        _sift(where[i], n, heap, where, ev_t)
    totals[TIME] = reached
    totals[EVENTS] += ti.cast(done, ti.f64)
