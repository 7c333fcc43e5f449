"""Parallel loops over n items that take several items per iteration on a CPU.

Taichi reloads an array's address from the kernel's arguments at every access (it cannot tell
that a store leaves the arguments alone), and a loop that stores one item per iteration runs
far below the memory's speed. `python bench/loop_cost.py` (a float32 copy of 128 MB, GB/s
read plus written, on this project's 2-core machine): Taichi's plain loop 4.8 on two threads
and 1.75 on one; `each` taking 8 items per iteration 5.9 and 3.5, taking 16 6.3 and 4.6;
numpy 19 on one thread. In a discrete step at 1e6 (`bench/kernel_profile.py`, per-task
minima) the cell starts took 1.5 ms instead of 3.5 and the scatter into cells 2.5 to 2.8
instead of 3.2 to 3.3. Those passes, and the reorder's copies, use `each`; passes whose items
do much more work than a copy measured no faster or slower (the overlap search, the move,
the first round's pick and resolve) and keep plain loops. On a GPU consecutive threads must
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
