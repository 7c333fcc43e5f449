"""Cost per circle-step at a small and a large N, measured in turn in one process.

    python bench/flatness.py [--scheme event|discrete] [--small 10000] [--large 1000000]
                             [--warm 60] [--rounds 30] [--arch cpu|gpu]

Both scenes are bench.py's throughput scene (area fraction 0.3, 16:9 walls, f32, radius 0.5,
speeds in (0.5, 1.0), default dt, seed 0). Each is first stepped `--warm` times, so that its
speeds have spread out from their start (the fastest circle, and with it the event scheme's
cells, grows over the first tens of steps). Then each round times one step of the large scene
and large / small steps of the small one, which take about as long, so that the load of a
shared machine falls on both alike. Reported: the median circle-steps/s of each with [min, max],
and the cost ratio (small's circle-steps/s over large's: above 1, a large-N circle-step costs
more) as the ratio of the medians and as the median over rounds with the quartiles.
"""
import argparse
import os
import sys
import time

import numpy as np
import taichi as ti

import circles

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from kernel_profile import bench_scene  # noqa: E402


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scheme", choices=("event", "discrete"), default="event")
    parser.add_argument("--small", type=int, default=10_000)
    parser.add_argument("--large", type=int, default=1_000_000)
    parser.add_argument("--warm", type=int, default=60, help="steps of each scene before the timed ones")
    parser.add_argument("--rounds", type=int, default=30)
    parser.add_argument("--arch", choices=("cpu", "gpu"), default="cpu")
    args = parser.parse_args()
    if not 0 < args.small < args.large:
        parser.error(f"--small {args.small} and --large {args.large}: give 0 < small < large")
    if args.warm < 16 or args.rounds < 1:
        parser.error(f"--warm {args.warm} and --rounds {args.rounds}: give at least 16 warm-up steps (the first "
                     "reorder compiles) and one round")
    circles.init(arch=args.arch)
    large = circles.Simulation(bench_scene(args.large, args.scheme))
    small = circles.Simulation(bench_scene(args.small, args.scheme))
    large.step(args.warm)
    small.step(args.warm)
    k = args.large // args.small
    rates = {"large": [], "small": []}
    for _ in range(args.rounds):
        for name, sim, steps in (("large", large, 1), ("small", small, k)):
            ti.sync()
            t0 = time.perf_counter()
            sim.step(steps)
            ti.sync()
            rates[name].append(sim.n * steps / (time.perf_counter() - t0))
    big, little = np.array(rates["large"]), np.array(rates["small"])
    per_round = little / big
    print(f"{args.scheme}, after {args.warm} steps, {args.rounds} rounds of 1 step at N = {args.large} and {k} at "
          f"N = {args.small}, on the {args.arch}:")
    for name, r in (("large", big), ("small", little)):
        n = args.large if name == "large" else args.small
        print(f"  N = {n}: {np.median(r) / 1e6:.3g} M circle-steps/s [{r.min() / 1e6:.3g}, {r.max() / 1e6:.3g}]")
    print(f"  cost per circle-step, N = {args.large} over N = {args.small}: {np.median(little) / np.median(big):.2f} "
          f"(ratio of medians), {np.median(per_round):.2f} [{np.percentile(per_round, 25):.2f}, "
          f"{np.percentile(per_round, 75):.2f}] (median over rounds, quartiles)")


if __name__ == "__main__":
    main()
