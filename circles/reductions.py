"""Whole-array kernels: largest speed with a finiteness check, largest overlap, copies."""
import math

import taichi as ti

from . import launch
from .backend import current_arch
from .geometry import displacement, neighbour_range
from .loops import each

ndarr = ti.types.ndarray(ndim=1)


#: Threads of `max_speed` on a GPU: each takes every STRIDED_THREADS-th circle, so that a
#: warp reads neighbouring circles, and offers one maximum to the contended atomic.
STRIDED_THREADS = 1 << 16


@ti.func
def speed_of(p, v):
    """(|v|^2 in float64, 1.0 when the position p or the velocity v is not finite else 0.0)."""
    p64 = ti.cast(p, ti.f64)
    v64 = ti.cast(v, ti.f64)
    bad = 0.0
    for a in ti.static(range(2)):
        # x - x is 0 for finite x and NaN for NaN or +-Inf.
        if not (p64[a] - p64[a] == 0.0) or not (v64[a] - v64[a] == 0.0):
            bad = 1.0
    return v64.norm_sqr(), bad


@ti.func
def offer_speed(out: ti.template(), s, bad):
    """One circle's (|v|^2, bad) from `speed_of` into a largest-speed pass's out array: out[1]
    counts the circles that are not finite, out[0] keeps the largest |v|^2 of the others."""
    if bad > 0:
        ti.atomic_add(out[1], 1.0)
    elif s > out[0]:
        # Reading first leaves only the few new maxima to the (contended) atomic.
        ti.atomic_max(out[0], s)


@ti.func
def speed_result(out: ti.template()) -> ti.f64:
    """A largest-speed pass's result from its out array: the largest |v|^2, or minus the number
    of circles that are not finite (`speed_in` reads the same on the host)."""
    result = out[0]
    if out[1] > 0:
        result = -out[1]
    return result


def speed_from(result: float) -> float:
    """The largest |v| from a kernel's result of the largest |v|^2 (`speed_of`), or that result
    when negative (minus the number of circles that are not finite). A correctly rounded square
    root is monotonic, so the root of the largest square is the largest |v|, bit for bit."""
    return math.sqrt(result) if result >= 0 else result


def speed_in(out):
    """`speed_from` of what a largest-speed pass left in its `out` array (a numpy view of it,
    `launch.host_view`; None, as where there is no view, gives None): as `speed_result`."""
    if out is None:
        return None
    return speed_from(-float(out[1]) if out[1] > 0 else float(out[0]))


def max_speed(pos, vel, out, serial=False) -> float:
    """Largest |v|, or minus the number of circles with a non-finite position or velocity.

    `out`: a float64 ndarray of 2 elements. One launch, whose kernel returns the value (a
    separate read-back would cost a second launch). `serial`: on one thread, on a CPU (see
    backend.serial_loops). An event step's finish on a CPU measures the same in its own pass
    (`event.finish`), and the simulation keeps that value for the next step.
    """
    if current_arch() == "gpu":
        return speed_from(_max_speed(pos, vel, out, STRIDED_THREADS))
    return speed_from(_max_speed(pos, vel, out, -1 if serial else 0))


@launch.kernel
def _max_speed(pos: ndarr, vel: ndarr, out: ndarr, threads: ti.template()) -> ti.f64:
    """`max_speed`'s largest |v|^2 (or minus the count of circles not finite) as one loop over
    the circles (threads = 0; -1: on one thread), or as `threads` threads that each take every
    threads-th circle."""
    out[0] = 0.0
    out[1] = 0.0
    n = pos.shape[0]
    if ti.static(threads > 0):
        for t in range(ti.min(n, threads)):
            top = 0.0
            bad = 0.0
            i = t
            while i < n:
                s, b = speed_of(pos[i], vel[i])
                top = ti.max(top, s)
                bad += b
                i += threads
            if bad > 0:
                ti.atomic_add(out[1], bad)
            if top > out[0]:
                ti.atomic_max(out[0], top)
    else:
        ti.loop_config(serialize=threads < 0)
        for i in range(n):
            s, bad = speed_of(pos[i], vel[i])
            offer_speed(out, s, bad)
    return speed_result(out)


@launch.kernel
def max_overlap(pos: ndarr, radius: ndarr, cell_of: ndarr, cell_start: ndarr, sorted_ids: ndarr,
                ncx: ti.i32, ncy: ti.i32, rows: ti.i32, segs: ti.i32, box_w: ti.f64, box_h: ti.f64, out: ndarr,
                periodic: ti.template()) -> ti.f64:
    """Largest (r_i + r_j - d_ij) / (r_i + r_j) over all pairs, 0 when none overlap."""
    out[0] = 0.0
    for i in range(pos.shape[0]):
        box = ti.Vector([box_w, box_h], dt=ti.f64)
        c = cell_of[i]
        xi = ti.cast(pos[i], ti.f64)
        for row, seg in ti.ndrange(rows, segs):
            k_lo, k_hi = neighbour_range(c, row, seg, cell_start, ncx, ncy, periodic)
            for k in range(k_lo, k_hi):
                j = sorted_ids[k]
                if j > i:
                    s = ti.cast(radius[i] + radius[j], ti.f64)
                    d = displacement(xi, ti.cast(pos[j], ti.f64), box, periodic).norm()
                    if d < s:
                        ti.atomic_max(out[0], (s - d) / s)
    return out[0]


@ti.func
def _gather(k, a: ti.template()):
    """a = (src, dst, order): dst[k] = src[order[k]]."""
    a[1][k] = a[0][a[2][k]]


@ti.func
def _copy(k, a: ti.template()):
    """a = (src, dst): dst[k] = src[k]."""
    a[1][k] = a[0][k]


@launch.kernel
def copy_vec(src: ndarr, dst: ndarr):
    each(src.shape[0], _copy, (src, dst), False)


@ti.func
def _gather_chain(order: ti.template(), chain: ti.template(), serial: ti.template()):
    """chain = (free, a_1, ..., a_m), arrays of one kind: a_1 gathered by `order` into free,
    then each a_k into a_(k-1), which the gather before has read (top-level loops run in turn)."""
    for k in ti.static(range(1, len(chain))):
        each(order.shape[0], _gather, (chain[k], chain[k - 1], order), serial)


@launch.kernel
def permute_state(order: ndarr, pos: ndarr, vel: ndarr, radius: ndarr, inv_mass: ndarr, ids: ndarr,
                  pair_count: ndarr, wall_count: ndarr, virial: ndarr, wall_impulse: ndarr, vec_free: ndarr,
                  real_free: ndarr, int_free: ndarr, f64_free: ndarr, serial: ti.template()):
    """Every per-circle array permuted, arr'[k] = arr[order[k]], in one launch and without
    copies: each kind's arrays are gathered along a chain from a free array of their kind
    (`_gather_chain`), so that pos' is in vec_free, vel' in pos's array, and vel's array is
    free after (see Simulation._reorder, which renames them). With `serial`, on one thread
    (see backend.serial_loops)."""
    _gather_chain(order, (vec_free, pos, vel), serial)
    _gather_chain(order, (real_free, radius, inv_mass), serial)
    _gather_chain(order, (int_free, ids, pair_count, wall_count), serial)
    _gather_chain(order, (f64_free, virial, wall_impulse), serial)


@launch.kernel
def events_since(pair_count: ndarr, wall_count: ndarr, pair_before: ndarr, wall_before: ndarr) -> ti.i64:
    """Events (collisions and wall hits) the per-circle counts have gained since the copies
    `*_before` were taken: each collision counts once, although both its circles count it."""
    pairs = ti.cast(0, ti.i64)
    walls = ti.cast(0, ti.i64)
    for i in range(pair_count.shape[0]):
        pairs += ti.cast(pair_count[i] - pair_before[i], ti.i64)
        walls += ti.cast(wall_count[i] - wall_before[i], ti.i64)
    return pairs // 2 + walls


@launch.kernel
def fill_i32(dst: ndarr, value: ti.i32):
    for i in range(dst.shape[0]):
        dst[i] = value


@launch.kernel
def _fill_real(dst: ndarr, value: ti.f64, real: ti.template()):
    for i in range(dst.shape[0]):
        dst[i] = ti.cast(value, real)


def fill_real(dst, value):
    _fill_real(dst, value, dst.dtype)
