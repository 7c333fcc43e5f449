"""Parallel loops over n items that take several items per iteration on a CPU.

Taichi reloads an array's address from the kernel's arguments at every access (it cannot tell
that a store leaves the arguments alone), a load that follows a store waits for it, and a
loop that stores one item per iteration runs far below the memory's speed
(`bench/diagnostics/loop_cost.py` measures it). Taking several items per iteration, their loads
before their stores, comes closer. The reorder's gathers use `each` and the cell starts take
`unroll()` cells per iteration; the grid's count and scatter take their items' loads before
their stores (`grid.enter_cells`); passes whose items do much more work than a copy (the
overlap search, the first round's pick and resolve) gain nothing and keep plain loops. On a GPU consecutive threads must
take consecutive items (coalesced loads), so there a loop takes one item per iteration.
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
