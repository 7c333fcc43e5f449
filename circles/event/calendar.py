"""The one queue's calendar: buckets of equal width over the step with a small heap in front."""
import taichi as ti

from ..geometry import key_less, NO_EVENT
from .time_of_impact import _tie_ids

# The queue is a calendar of buckets with a small heap in front: the step [0, t_end] is cut
# into `nb` buckets of equal width, each a doubly linked list of the circles whose event falls
# in it, in no order; the heap holds the events of the buckets already reached (the current
# one and any event that came back into it), ordered by key. Taking the earliest event takes
# the heap's top; when the heap runs empty, the next bucket's list is poured into it. A bucket
# holds a few events, so the heap stays small enough to live in the cache and a changed event
# costs a few stores, where one heap of every event would take a cache miss at each of its
# twenty levels at 1e6. The order is the keys' order, the same as one heap's.


#: head[b] of a bucket already poured into the heap: its events go to the heap directly.
POURED = -2


@ti.func
def _before(x, t, y, u, ev_p: ti.template(), ids: ti.template(), n):
    """Whether circle x's event, at time t, comes before circle y's, at u, by the key of
    `event_key`; the ids are read only for equal times (the two circles of a pair, mostly)."""
    less = t < u
    if t == u:
        xl, xh = _tie_ids(x, ev_p, ids, n)
        yl, yh = _tie_ids(y, ev_p, ids, n)
        less = key_less(t, xl, xh, u, yl, yh)
    return less


@ti.func
def _heap_put(k, x, t, heap: ti.template(), where: ti.template(), heap_t: ti.template(), off):
    """Circle x, whose event is at time t, into heap slot k (of the heap from `off`)."""
    heap[off + k] = x
    heap_t[off + k] = t
    where[x] = k


@ti.func
def _sift_up(k, heap: ti.template(), where: ti.template(), heap_t: ti.template(), ev_p: ti.template(),
             ids: ti.template(), n, off):
    """Move the event in heap slot k up to its place; returns its new slot. The parents it passes
    move down one level each, and it is written once, at its place (a hole moves up, not a
    swapped pair: half the stores)."""
    x = heap[off + k]
    t = heap_t[off + k]
    while k > 0:
        parent = (k - 1) // 2
        y = heap[off + parent]
        if _before(x, t, y, heap_t[off + parent], ev_p, ids, n):
            _heap_put(k, y, heap_t[off + parent], heap, where, heap_t, off)
            k = parent
        else:
            break
    _heap_put(k, x, t, heap, where, heap_t, off)
    return k


@ti.func
def _sift_down(k, size, heap: ti.template(), where: ti.template(), heap_t: ti.template(), ev_p: ti.template(),
               ids: ti.template(), n, off):
    """Move the event in heap slot k down to its place, the earlier of its two children moving
    up each level (the hole of `_sift_up`, downwards)."""
    x = heap[off + k]
    t = heap_t[off + k]
    while 2 * k + 1 < size:
        m = 2 * k + 1
        if m + 1 < size and _before(heap[off + m + 1], heap_t[off + m + 1], heap[off + m], heap_t[off + m], ev_p,
                                    ids, n):
            m += 1
        y = heap[off + m]
        if _before(y, heap_t[off + m], x, t, ev_p, ids, n):
            _heap_put(k, y, heap_t[off + m], heap, where, heap_t, off)
            k = m
        else:
            break
    _heap_put(k, x, t, heap, where, heap_t, off)


@ti.func
def _bucket(t, scale, nb):
    """The calendar bucket of time t in [0, t_end] (scale = nb / t_end, float64, at most 1e30):
    monotone in t, so the buckets' order agrees with the times'. In float64 and clamped before
    the conversion, so that a step of 1e-36 (nb / t_end past float32's range, times 0 at a
    touch) still gives a bucket in range."""
    return ti.cast(ti.min(ti.max(ti.cast(t, ti.f64) * scale, 0.0), ti.cast(nb - 1, ti.f64)), ti.i32)


@ti.func
def _queue_put(x, size, scale, nb, q: ti.template(), ev_t: ti.template(), ev_p: ti.template(), ids: ti.template(),
               n, off, hb):
    """Circle x, which has an event and is not in the queue, into it: into the heap when its
    bucket was poured, else at the front of its bucket's list. Returns the heap's size.
    q: (heap, where, heap_t, head, nxt, prv, pending); the queue's heap starts at slot `off` of
    its arrays and its nb buckets at `hb` of `head` (one queue of several, `queue_parts`)."""
    t = ev_t[x]
    b = _bucket(t, scale, nb)
    first = q[3][hb + b]
    if first == POURED:
        q[0][off + size] = x
        q[2][off + size] = t
        _sift_up(size, q[0], q[1], q[2], ev_p, ids, n, off)
        size += 1
    else:
        q[4][x] = first
        q[5][x] = -1
        if first >= 0:
            q[5][first] = x
        q[3][hb + b] = x
        q[1][x] = -2 - b
    return size


@ti.func
def _queue_fix(x, size, scale, nb, q: ti.template(), ev_t: ti.template(), ev_p: ti.template(), ids: ti.template(),
               n, off, hb):
    """Put circle x where its (changed) event belongs in the queue, which holds each circle with
    an event once: in it when it has an event, out of it when not. Returns the heap's size."""
    k = q[1][x]
    has = ev_p[x] != NO_EVENT
    b = -1
    if has:
        b = _bucket(ev_t[x], scale, nb)
    if k >= 0:  # in the heap
        if has and q[3][hb + b] == POURED:  # stays there, moved to its place
            q[2][off + k] = ev_t[x]
            k = _sift_up(k, q[0], q[1], q[2], ev_p, ids, n, off)
            _sift_down(k, size, q[0], q[1], q[2], ev_p, ids, n, off)
        else:
            size -= 1
            q[1][x] = -1
            if k < size:  # the last event fills the hole
                q[0][off + k] = q[0][off + size]
                q[2][off + k] = q[2][off + size]
                k = _sift_up(k, q[0], q[1], q[2], ev_p, ids, n, off)
                _sift_down(k, size, q[0], q[1], q[2], ev_p, ids, n, off)
            if has:
                size = _queue_put(x, size, scale, nb, q, ev_t, ev_p, ids, n, off, hb)
    elif k <= -2:  # in bucket -2 - k's list
        old = -2 - k
        if b != old:
            nx = q[4][x]
            pv = q[5][x]
            if pv >= 0:
                q[4][pv] = nx
            else:
                q[3][hb + old] = nx
            if nx >= 0:
                q[5][nx] = pv
            q[1][x] = -1
            if has:
                size = _queue_put(x, size, scale, nb, q, ev_t, ev_p, ids, n, off, hb)
    elif has:
        size = _queue_put(x, size, scale, nb, q, ev_t, ev_p, ids, n, off, hb)
    return size
