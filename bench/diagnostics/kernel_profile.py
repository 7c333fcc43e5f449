"""Where a step's time goes: per-kernel-task times from Taichi's kernel profiler.

    python bench/diagnostics/kernel_profile.py [--arch cpu|gpu] [--n 1e6 ...] [--scheme discrete event] [--steps 20]
                                   [--warm 2]

The bench scene (radius 0.5, area fraction 0.3, 16:9 walled box, speeds 0.5 to 1, float32,
default dt). For each N and scheme: the scene is built and warmed up by `--warm` steps (2 by
default; 60 to profile a relaxed scene, as bench.py's throughput rows time), then
`steps` steps are timed one by one without the profiler (circle-steps/s: the median with
[min, max] over the steps),
then `steps` more with it, and the profiler's table is printed: each row one offloaded task
of a kernel (on the GPU a task is one device kernel; `serial` tasks run on one thread),
with its calls and total time. The profiler adds a synchronisation per task, so the timed
pass, not the profiled one, gives the speed. `bench/diagnostics/versus.py` times steps the same way.
"""

import argparse
import os
import sys
import time

import numpy as np
import taichi as ti

import circles

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # bench/, for bench.py
from bench import AREA_FRACTION, ASPECT, R, SPEED, box_for  # noqa: E402


def bench_scene(n, scheme, seed=0):
    """The throughput rows' scene of bench.py, float32."""
    return circles.Scene(n=n, box=box_for(n, AREA_FRACTION, ASPECT), radius=R, speed=SPEED, scheme=scheme,
                         precision="f32", seed=seed)


def time_steps(sim, steps):
    """Times `steps` single steps; returns (seconds per step, pair collisions, relative energy
    change, largest overlap at the end)."""
    start = sim.stats()
    times = []
    for _ in range(steps):
        t0 = time.perf_counter()
        sim.step(1)
        times.append(time.perf_counter() - t0)
    end = sim.stats()
    return (np.array(times), end["pair_collisions"] - start["pair_collisions"],
            end["kinetic_energy"] / start["kinetic_energy"] - 1, end["max_overlap"])


def profile(n, scheme, steps, warm=2):
    t0 = time.perf_counter()
    sim = circles.Simulation(bench_scene(n, scheme))
    place_s = time.perf_counter() - t0
    sim.step(warm)
    rounds0, sweeps0 = sim.rounds, sim.sweeps
    times, pairs, energy_change, overlap = time_steps(sim, steps)
    rates = n / times / 1e6
    print(f"\n{scheme} N={n}: placement {place_s:.2f} s; {np.median(rates):.3g} M circle-steps/s median "
          f"[{rates.min():.3g}, {rates.max():.3g}] over {steps} steps; {pairs / (n * steps):.3g} collisions per "
          "circle-step; "
          f"{(sim.rounds - rounds0) / steps:.1f} rounds and {(sim.sweeps - sweeps0) / steps:.1f} bound sweeps per step; "
          f"energy change {energy_change:.2e}; "
          f"largest overlap {overlap:.2e}", flush=True)
    ti.profiler.clear_kernel_profiler_info()
    t0 = time.perf_counter()
    sim.step(steps)
    ti.sync()
    wall = time.perf_counter() - t0
    print(f"profiled pass: {wall / steps * 1e3:.3g} ms per step wall, "
          f"{ti.profiler.get_kernel_profiler_total_time() / steps * 1e3:.3g} ms per step in tasks", flush=True)
    ti.profiler.print_kernel_profiler_info("count")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--arch", choices=("cpu", "gpu"), default="cpu", help="where the kernels run (default: cpu)")
    ap.add_argument("--n", type=float, nargs="+", default=[1e6], help="circles, one scene each (default: 1e6)")
    ap.add_argument("--scheme", nargs="+", default=["discrete", "event"], choices=("discrete", "event"),
                    help="schemes, one scene each (default: discrete event)")
    ap.add_argument("--steps", type=int, default=20,
                    help="steps timed, and then steps profiled (at least 1; default: 20)")
    ap.add_argument("--warm", type=int, default=2, help="steps before the timed ones (at least 1; default: 2)")
    args = ap.parse_args(argv)
    bad = [f"{n:g}" for n in args.n if not (n >= 1 and n.is_integer())]
    if bad:
        ap.error(f"--n {' '.join(bad)}: give whole numbers of circles, 1 or more (1e6 or 1000000)")
    if args.steps < 1:
        ap.error(f"--steps {args.steps}: give at least 1 step to time")
    if args.warm < 1:
        ap.error(f"--warm {args.warm}: give at least 1 (the first step compiles)")
    arch = circles.init(arch=args.arch, kernel_profiler=True)
    print(f"arch {arch}, taichi {'.'.join(map(str, ti.__version__))}", flush=True)
    for n in args.n:
        for scheme in args.scheme:
            profile(int(n), scheme, args.steps, args.warm)


if __name__ == "__main__":
    main()
