"""What a kernel call costs on a CPU besides its kernel: Python's work and Taichi's launch.

    python bench/diagnostics/launch_cost.py [--calls 5000] [--runs 5]

Kernels that do (almost) nothing, with 1 and with 30 ndarray arguments (and two scalars), each
called `calls` times in a row through circles' fast calls (`circles/launch.py`) and through
Taichi's own call; microseconds per call, the median with [min, max] over `runs` runs (the
least is the cost on a quiet machine, the spread what a shared one adds). Then the share of Taichi's
launch alone (the C++ call that the fast path ends in), from the same calls timed without
the Python around them.

Last, what one more loop costs inside a kernel (each loop of a kernel is a task of its own, as
each stage of a step is): a kernel of LOOPS + 1 loops over m items against one of a single
loop, per further loop, with the loops run in parallel (each starts the CPU's thread pool) and
with the loops serialized (on the calling thread), for m = 1, 1000 and 100000. The parallel
start is what a stage pays for running on several threads (see circles.backend.SERIAL_N and
circles.discrete.stepper.DISCRETE_PARALLEL_ROUNDS).
"""
import argparse
import statistics
import time

import taichi as ti

import circles
from circles import backend, launch

nd = ti.types.ndarray(ndim=1)


def one_array(a: nd, x: ti.f64, y: ti.f64) -> ti.i32:
    a[0] = x + y
    return 1


def thirty_arrays(a0: nd, a1: nd, a2: nd, a3: nd, a4: nd, a5: nd, a6: nd, a7: nd, a8: nd, a9: nd, a10: nd, a11: nd,
                  a12: nd, a13: nd, a14: nd, a15: nd, a16: nd, a17: nd, a18: nd, a19: nd, a20: nd, a21: nd, a22: nd,
                  a23: nd, a24: nd, a25: nd, a26: nd, a27: nd, a28: nd, a29: nd, x: ti.f64, y: ti.f64) -> ti.i32:
    a0[0] = x + y
    return 1


def per_call(fn, args, calls, runs):
    """Microseconds per call in each of `runs` runs of `calls` calls (after two calls that compile)."""
    fn(*args)
    fn(*args)
    times = []
    for _ in range(runs):
        t0 = time.perf_counter()
        for _ in range(calls):
            fn(*args)
        times.append((time.perf_counter() - t0) / calls * 1e6)
    return times


#: Further loops of the kernels that time a loop's start.
LOOPS = 31


@ti.kernel
def loops(a: nd, m: ti.i32, count: ti.template(), serial: ti.template()):
    """`count` loops over the first m items of a, each a task of its own: on the thread pool, or
    with `serial` on the calling thread."""
    for k in ti.static(range(count)):
        ti.loop_config(serialize=serial)
        for i in range(m):
            a[i] = a[i] * 0.5 + k


def loop_start(calls, runs):
    """Microseconds per further loop of a kernel, parallel and serialized, by items per loop."""
    a = ti.ndarray(ti.f32, shape=100_000)
    rows = []
    for m in (1, 1000, 100_000):
        row = [m]
        for serial in (False, True):
            timed = []
            for count in (LOOPS + 1, 1):
                loops(a, m, count, serial)  # compiles
                ti.sync()
                # The kernel returns nothing: each call is timed up to a synchronisation.
                timed.append(per_call(lambda: (loops(a, m, count, serial), ti.sync()), (), calls, runs))
            row.append([(x - y) / LOOPS for x, y in zip(*timed)])
        rows.append(row)
    return rows


def spread(times):
    """'median [min, max]' of microseconds."""
    return f"{statistics.median(times):6.2f} [{min(times):.2f}, {max(times):.2f}]"


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--calls", type=int, default=5000, help="calls per run (at least 1; default: 5000)")
    parser.add_argument("--runs", type=int, default=5, help="runs of each kind of call (at least 1; default: 5)")
    args = parser.parse_args()
    if args.calls < 1:
        parser.error(f"--calls {args.calls}: give 1 or more calls per run (thousands for a steady figure)")
    if args.runs < 1:
        parser.error(f"--runs {args.runs}: give 1 or more runs")
    circles.init(arch="cpu")
    program = ti.lang.impl.get_runtime().prog
    print(f"microseconds per call, median [min, max] over {args.runs} runs of {args.calls} calls")
    for name, fn, count in (("1 array", one_array, 1), ("30 arrays", thirty_arrays, 30)):
        arrays = [ti.ndarray(ti.f64, shape=4) for _ in range(count)]
        call_args = arrays + [1.0, 2.0]
        fast = launch.kernel(fn)
        plain = ti.kernel(fn)
        fast_us = per_call(fast, call_args, args.calls, args.runs)
        plain_us = per_call(plain, call_args, args.calls, args.runs)
        # The fast path's binding for these arrays: its context and the kernel it launches
        # (an engine whose bindings keep no kernel, an older one, has no such column).
        binding = next(iter(fast._bindings.values()))
        alone = ""
        if hasattr(binding, "launchable"):
            launch_us = per_call(lambda: program.launch_kernel(binding.launchable, binding.ctx), (), args.calls,
                                 args.runs)
            alone = f"   of which Taichi's launch alone {spread(launch_us)}"
        print(f"  {name:10s} fast call {spread(fast_us)}   Taichi's call {spread(plain_us)}{alone}")
    # A call of the kernel of LOOPS + 1 parallel loops takes a few milliseconds where a loop's start
    # costs tens of microseconds: a twentieth of the calls keeps this section to seconds.
    calls = max(1, args.calls // 20)
    print(f"microseconds per further loop of a kernel ({LOOPS} further loops against one), median [min, max] over "
          f"{args.runs} runs of {calls} calls, on {backend.cpu_threads()} threads")
    for m, parallel, serial in loop_start(calls, args.runs):
        print(f"  {m:6d} items  parallel {spread(parallel)}   serialized {spread(serial)}")


if __name__ == "__main__":
    main()
