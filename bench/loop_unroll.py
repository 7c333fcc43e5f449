"""What taking several items per loop iteration buys a streaming Taichi loop on the CPU.

    python bench/loop_unroll.py [--n 1e7] [--repeats 9]

Times y[i] = 1.5 x[i] over n float32 (8 bytes moved per item) as a Taichi kernel through
`circles.loops.each` compiled to take 1, 2, 4, 8 or 16 items per iteration (the package uses
`loops.CPU_UNROLL`), on one thread and on all, and the
same operation in numpy (one thread), in one process, the variants alternating. Prints GB/s:
the median over the repeats, with the lowest and highest in brackets. Taichi reloads each
array's address from the kernel's arguments at every access (a store might have changed
them), which is what makes the one-item loop slow; see circles/loops.py.
"""
import argparse
import os
import subprocess
import sys
import time

import numpy as np


def run_one(n, repeats, threads):
    import taichi as ti
    ti.init(arch=ti.cpu, cpu_max_num_threads=threads, offline_cache=False, log_level=ti.ERROR)
    from circles import loops

    @ti.func
    def _scale(i, a: ti.template()):
        a[1][i] = a[0][i] * 1.5

    def variant(u, x, y):
        """A fresh kernel over `each`, compiled (by a first call) with u items per iteration:
        loops.unroll() is read when a kernel compiles."""
        @ti.kernel
        def scale(x: ti.types.ndarray(ndim=1), y: ti.types.ndarray(ndim=1)):
            loops.each(x.shape[0], _scale, (x, y), False)

        loops.CPU_UNROLL = u
        scale(x, y)
        return scale

    x = ti.ndarray(ti.f32, n)
    y = ti.ndarray(ti.f32, n)
    x.from_numpy(np.random.default_rng(0).random(n, dtype=np.float32))
    kernels = {u: variant(u, x, y) for u in (1, 2, 4, 8, 16)}
    times = {u: [] for u in kernels}
    for _ in range(repeats + 1):
        for u, k in kernels.items():
            t0 = time.perf_counter()
            k(x, y)
            ti.sync()
            times[u].append(time.perf_counter() - t0)
    assert np.allclose(y.to_numpy(), 1.5 * x.to_numpy())
    return {u: [8 * n / t / 1e9 for t in ts[1:]] for u, ts in times.items()}


def fmt(rates):
    return f"{np.median(rates):.1f} [{min(rates):.1f}, {max(rates):.1f}]"


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=float, default=1e7)
    ap.add_argument("--repeats", type=int, default=9)
    ap.add_argument("--threads", type=int, default=0, help=argparse.SUPPRESS)
    args = ap.parse_args()
    n = int(args.n)
    if args.threads:
        rates = run_one(n, args.repeats, args.threads)
        print(repr(rates))
        return
    cores = os.cpu_count() or 1
    rows = {}
    for threads in sorted({1, cores}):
        # One process per thread count: Taichi's thread count is fixed at init.
        out = subprocess.run([sys.executable, __file__, "--n", str(n), "--repeats", str(args.repeats),
                              "--threads", str(threads)], check=True, capture_output=True, text=True).stdout
        rows[threads] = eval(out.strip().splitlines()[-1])
    x = np.random.default_rng(0).random(n, dtype=np.float32)
    y = np.empty_like(x)
    npr = []
    for _ in range(args.repeats + 1):
        t0 = time.perf_counter()
        np.multiply(x, 1.5, out=y)
        npr.append(8 * n / (time.perf_counter() - t0) / 1e9)
    print(f"y = 1.5 x over {n:.0e} float32, GB/s (median [min, max] of {args.repeats})\n")
    print("| items per iteration | " + " | ".join(f"{t} thread{'s' if t > 1 else ''}" for t in rows) + " |")
    print("|---|" + "---|" * len(rows))
    for u in (1, 2, 4, 8, 16):
        print(f"| {u} | " + " | ".join(fmt(rows[t][u]) for t in rows) + " |")
    print(f"\nnumpy, one thread: {fmt(npr[1:])}")


if __name__ == "__main__":
    main()
