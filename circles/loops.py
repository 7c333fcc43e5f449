"""Parallel loops over n items that take several items per iteration on a CPU.

Taichi reloads an array's address from the kernel's arguments at every access (it cannot tell
that a store leaves the arguments alone), and a loop that takes one item per iteration then
runs far below the memory's speed. `python bench/loop_unroll.py`, y = 1.5 x over 1e7 float32
on this project's 2-core machine: 1.5 GB/s on one thread and 3.3 on two taking one item per
iteration, 3.5 and 8.2 taking 8, 4.5 and 9.3 taking 16; numpy makes 12.4 on one thread. The
passes that stream through arrays (the grid's scatter and cell starts, the reorder's copies)
use `each`; passes whose items do much more work than a copy gain nothing measurable and keep
plain loops. On a GPU consecutive threads must take consecutive items (coalesced loads), so
there a loop takes one item per iteration.
"""
import taichi as ti

#: Items per iteration of `each` on a CPU.
CPU_UNROLL = 8


def unroll() -> int:
    """Items per iteration on the arch Taichi runs on (read when a kernel compiles):
    `CPU_UNROLL` on a CPU, 1 on a GPU."""
    return CPU_UNROLL if ti.lang.impl.current_cfg().arch in (ti.x64, ti.arm64) else 1


@ti.func
def each(n, body: ti.template(), args: ti.template(), serial: ti.template()):
    """body(i, args) for every i in [0, n), as one parallel loop of the calling kernel (a
    top-level loop when called at the kernel's top level); with `serial`, on one thread.
    Each iteration takes `unroll()` consecutive items."""
    u = ti.static(unroll())
    ti.loop_config(serialize=serial)
    for b in range((n + u - 1) // u):
        for k in ti.static(range(u)):
            i = b * u + k
            if i < n:
                body(i, args)
