"""What a plain loop costs in Taichi's CPU code, against numpy: the floor under a step's passes.

    python bench/diagnostics/loop_cost.py [--mb 128] [--reps 7] [--grid-n 1e6]

Copies of a float32 array larger than the cache (bytes read plus written per second, the
median with [min, max] over `reps` runs after one that compiles): a Taichi loop on all
threads and on one thread, the one-thread loop unrolled by 16 with its 16 loads before its
16 stores, the package's `circles.loops.each` compiled to take 1, 8 (the package's
`loops.CPU_UNROLL`) and 16 items per iteration on all threads and on one, a read-only Taichi
loop (a sum), and numpy's copy. Then the grid count of a discrete step alone (`--grid-n`
circles, 1e6 by default, in cell order: the cell of each, counted into its cell with an
atomic add, or as the grid counts on a CPU, `grid.enter_cells`) against the same pass
that only writes the cell.

Taichi's generated loop reads each array's data pointer from the kernel's argument buffer
at every access; after a store, which might alias that buffer, it reads it again, and a
loop that takes one item per iteration runs far below the memory's speed. A loop with no
store keeps the pointers in registers (the read-only row). See circles/loops.py and
the Performance page of the docs (the discrete scheme on a CPU).
"""
import argparse
import math
import os
import time

import numpy as np
import taichi as ti

from circles import grid, loops, reductions

nd = ti.types.ndarray(ndim=1)
#: The least array of the copies (numbers): the grouped copy takes 16 at a time.
MIN_NUMBERS = 1024
#: Bytes per circle of the grid pass, about: its position (8, and 8 more on the host with the sort's
#: temporaries, 16), the cell, slot and stray arrays (12) and 2.6 cells of counts (10), rounded up.
GRID_BYTES_PER_CIRCLE = 64


@ti.kernel
def copy_parallel(src: nd, dst: nd):
    for i in range(src.shape[0]):
        dst[i] = src[i]


@ti.kernel
def copy_serial(src: nd, dst: nd):
    ti.loop_config(serialize=True)
    for i in range(src.shape[0]):
        dst[i] = src[i]


@ti.kernel
def copy_serial_grouped(src: nd, dst: nd):
    ti.loop_config(serialize=True)
    for g in range(src.shape[0] // 16):
        v = ti.Vector([0.0] * 16, dt=ti.f32)
        for u in ti.static(range(16)):
            v[u] = src[g * 16 + u]
        for u in ti.static(range(16)):
            dst[g * 16 + u] = v[u]


@ti.kernel
def read_sum(src: nd) -> ti.f32:
    total = ti.cast(0.0, ti.f32)
    for i in range(src.shape[0]):
        total += src[i]
    return total


@ti.kernel
def cell_only(pos: ti.types.ndarray(ndim=1), cell_of: nd, ncx: ti.i32, ncy: ti.i32):
    for i in range(pos.shape[0]):
        cx = ti.min(ti.cast(pos[i][0] * ncx, ti.i32), ncx - 1)
        cy = ti.min(ti.cast(pos[i][1] * ncy, ti.i32), ncy - 1)
        cell_of[i] = cy * ncx + cx


@ti.kernel
def cell_and_count(pos: ti.types.ndarray(ndim=1), cell_of: nd, slot: nd, count: nd, ncx: ti.i32, ncy: ti.i32):
    for i in range(pos.shape[0]):
        cx = ti.min(ti.cast(pos[i][0] * ncx, ti.i32), ncx - 1)
        cy = ti.min(ti.cast(pos[i][1] * ncy, ti.i32), ncy - 1)
        c = cy * ncx + cx
        cell_of[i] = c
        slot[i] = ti.atomic_add(count[c], 1)


@ti.kernel
def cell_in_parts(pos: ti.types.ndarray(ndim=1), cell_of: nd, slot: nd, count: nd, stray: nd, parts: nd, ncx: ti.i32,
                  ncy: ti.i32):
    """The grid build's count on a CPU (`grid.enter_cells` with the build's own position reader)."""
    grid.enter_cells(pos.shape[0], grid._position, grid._keep_nothing, (pos,), cell_of, slot, count, stray, parts, ncx,
                     ncy, ti.cast(ncx, ti.f64), ti.cast(ncy, ti.f64), 0, ti.f32, True, False)


def each_copy(items, serial, src, dst):
    """The reorder's copy (`reductions._copy`) through `loops.each`, compiled (by a first call)
    to take `items` items per iteration: loops.unroll() is read when a kernel compiles."""
    @ti.kernel
    def copy(src: nd, dst: nd):
        loops.each(src.shape[0], reductions._copy, (src, dst), serial)

    saved = loops.CPU_UNROLL
    loops.CPU_UNROLL = items
    try:
        copy(src, dst)
    finally:
        loops.CPU_UNROLL = saved
    return copy


def timed(reps, fn, before=None):
    """Seconds of `reps` calls of `fn` (each after `before`, untimed), after one call that compiles."""
    times = []
    for _ in range(reps + 1):  # the first call compiles
        if before is not None:
            before()
        ti.sync()
        t0 = time.perf_counter()
        fn()
        ti.sync()
        times.append(time.perf_counter() - t0)
    return np.array(times[1:])


def spread(values, digits=2):
    """'median [min, max]' of an array."""
    return f"{np.median(values):6.{digits}f} [{values.min():.{digits}f}, {values.max():.{digits}f}]"


def grid_shape(circles):
    """Cells (ncx, ncy) of a discrete step's grid for this many circles at area fraction 0.3: about
    2.6 cells per circle, 16:9 (2160 x 1212 at 1e6)."""
    scale = math.sqrt(circles / 1e6)
    return max(1, round(2160 * scale)), max(1, round(1212 * scale))


def check_args(parser, args):
    """Sizes and repeats that can run, found before any work."""
    if not (math.isfinite(args.mb) and args.mb * 2**20 / 4 >= MIN_NUMBERS):
        parser.error(f"--mb {args.mb:g}: give at least {MIN_NUMBERS * 4 / 2**20:.3g} MB ({MIN_NUMBERS} numbers); "
                     "larger than the cache (tens of MB) to measure the memory")
    memory = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2**20
    if 4 * args.mb > memory / 2:
        parser.error(f"--mb {args.mb:g}: four arrays of that size would take more than half of this machine's "
                     f"{memory:.0f} MB; give at most {memory / 8:.0f} MB")
    if args.reps < 1:
        parser.error(f"--reps {args.reps}: give 1 or more timed runs")
    if not (args.grid_n >= 1 and args.grid_n.is_integer()):
        parser.error(f"--grid-n {args.grid_n:g}: give a whole number of circles, 1 or more (1e6 or 1000000)")
    if args.grid_n * GRID_BYTES_PER_CIRCLE / 2**20 > memory / 2:
        parser.error(f"--grid-n {args.grid_n:g}: the grid pass's arrays ({GRID_BYTES_PER_CIRCLE} B a circle) would "
                     f"take more than half of this machine's {memory:.0f} MB; give at most "
                     f"{memory / 2 * 2**20 / GRID_BYTES_PER_CIRCLE:.3g}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mb", type=float, default=128, help="size of the copied array, MB (default: 128)")
    parser.add_argument("--reps", type=int, default=7, help="timed runs of each pass (default: 7)")
    parser.add_argument("--grid-n", type=float, default=1e6, help="circles of the grid pass (default: 1e6)")
    args = parser.parse_args()
    check_args(parser, args)
    ti.init(arch=ti.cpu)
    n = int(args.mb * 2**20 / 4)
    host = np.random.default_rng(0).random(n, dtype=np.float32)
    src = ti.ndarray(ti.f32, n)
    dst = ti.ndarray(ti.f32, n)
    src.from_numpy(host)
    out = np.empty_like(host)
    moved = 8.0 * n / 1e9
    print(f"float32 copy of {args.mb:g} MB, GB/s read plus written, median [min, max] over {args.reps} runs")
    rows = [("taichi loop, all threads", lambda: copy_parallel(src, dst), moved),
            ("taichi loop, one thread", lambda: copy_serial(src, dst), moved),
            ("taichi loop, one thread, 16 loads then 16 stores", lambda: copy_serial_grouped(src, dst), moved),
            ("taichi read-only loop (sum), all threads", lambda: read_sum(src), moved / 2),
            ("numpy copyto, one thread", lambda: np.copyto(out, host), moved)]
    for serial in (False, True):
        for items in (1, 8, 16):
            kernel = each_copy(items, serial, src, dst)
            rows.insert(-2, (f"loops.each, {items} per iteration, {'one thread' if serial else 'all threads'}",
                             lambda kernel=kernel: kernel(src, dst), moved))
    for name, fn, gb in rows:
        print(f"  {name:50s} {spread(gb / timed(args.reps, fn))}")

    circles = int(args.grid_n)
    ncx, ncy = grid_shape(circles)
    rng = np.random.default_rng(1)
    p = rng.random((circles, 2), dtype=np.float32)
    p = p[np.lexsort((p[:, 0], np.floor(p[:, 1] * ncy)))]  # cell order, as after a reorder
    pos = ti.Vector.ndarray(2, ti.f32, circles)
    pos.from_numpy(p)
    cell_of = ti.ndarray(ti.i32, circles)
    slot = ti.ndarray(ti.i32, circles)
    count = ti.ndarray(ti.i32, ncx * ncy)
    stray = ti.ndarray(ti.i32, circles)
    parts = ti.ndarray(ti.i32, 2 * grid.count_parts() + 1)
    only = timed(args.reps, lambda: cell_only(pos, cell_of, ncx, ncy)) * 1e3
    counted = timed(args.reps, lambda: cell_and_count(pos, cell_of, slot, count, ncx, ncy),
                    before=lambda: count.fill(0)) * 1e3
    # cell_of holds this order's cells from the passes above, as a step's count finds them.
    in_parts = timed(args.reps, lambda: cell_in_parts(pos, cell_of, slot, count, stray, parts, ncx, ncy),
                     before=lambda: count.fill(0)) * 1e3
    print(f"grid pass over {circles} circles in cell order ({ncx} x {ncy} cells), all threads, ms median "
          f"[min, max] over {args.reps} runs:")
    digits = 2 if circles >= 100_000 else 4
    print(f"  cell of each circle only      {spread(only, digits)}")
    print(f"  and counted into its cell     {spread(counted, digits)} (an atomic add per circle)")
    print(f"  counted in parts (the grid's) {spread(in_parts, digits)} (grid.enter_cells: plain adds, "
          f"{grid.CPU_GROUP} circles at a time)")


if __name__ == "__main__":
    main()
