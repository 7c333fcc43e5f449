"""Cost per circle-step across N, the scenes measured in turn in one process.

    python bench/diagnostics/flatness.py [--scheme event|discrete] [--n 10000 100000 1000000]
                             [--warm 60] [--rounds 30] [--arch cpu|gpu]

Every scene is bench.py's throughput scene (area fraction 0.3, 16:9 walls, f32, radius 0.5,
speeds in (0.5, 1.0), default dt, seed 0). Each is first stepped `--warm` times, so that its
speeds have spread out from their start (the fastest circle, and with it the event scheme's
cells, grows over the first tens of steps). Then each round times one step of the largest
scene and largest / N steps of each smaller one, which take about as long, so that the load
of a shared machine falls on all alike. Reported: the median circle-steps/s of each N with
[min, max] and its cost per circle-step relative to the largest N's (above 1: dearer), and
the spread of the costs, the dearest N's over the cheapest's (the flatness target: at most
1.5 from 1e4 to 1e6), as the ratio of the medians and, with quartiles, as the median over
rounds of the same ratio of each round's speeds (noisier: the slowest and fastest of one
round's speeds).
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
    parser.add_argument("--scheme", choices=("event", "discrete"), default="event",
                        help="scheme of every scene (default: event)")
    parser.add_argument("--n", type=int, nargs="+", default=[10_000, 100_000, 1_000_000],
                        help="circles of each scene, two or more (default: 10000 100000 1000000)")
    parser.add_argument("--warm", type=int, default=60,
                        help="steps of each scene before the timed ones (at least 16; default: 60)")
    parser.add_argument("--rounds", type=int, default=30, help="rounds, each timing every scene once (default: 30)")
    parser.add_argument("--arch", choices=("cpu", "gpu"), default="cpu", help="where the kernels run (default: cpu)")
    args = parser.parse_args()
    ns = sorted(set(args.n))
    if len(ns) < 2 or ns[0] < 1:
        parser.error(f"--n {' '.join(map(str, args.n))}: give two or more different N, each at least 1")
    if args.warm < 16 or args.rounds < 1:
        parser.error(f"--warm {args.warm} and --rounds {args.rounds}: give at least 16 warm-up steps (the first "
                     "reorder compiles) and one round")
    circles.init(arch=args.arch)
    sims = {n: circles.Simulation(bench_scene(n, args.scheme)) for n in ns}
    for sim in sims.values():
        sim.step(args.warm)
    top = ns[-1]
    rates = {n: [] for n in ns}
    for _ in range(args.rounds):
        for n, sim in sims.items():
            steps = max(1, top // n)
            ti.sync()
            t0 = time.perf_counter()
            sim.step(steps)
            ti.sync()
            rates[n].append(n * steps / (time.perf_counter() - t0))
    r = {n: np.array(v) for n, v in rates.items()}
    med = {n: float(np.median(v)) for n, v in r.items()}
    print(f"{args.scheme}, after {args.warm} steps, {args.rounds} rounds, each of {top // ns[0]} to 1 steps of "
          f"N = {ns[0]} to {top}, on the {args.arch}:")
    for n in ns:
        print(f"  N = {n}: {med[n] / 1e6:.3g} M circle-steps/s [{r[n].min() / 1e6:.3g}, {r[n].max() / 1e6:.3g}], "
              f"cost {med[top] / med[n]:.2f} times N = {top}'s")
    each_round = np.stack([r[n] for n in ns])
    per_round = each_round.max(axis=0) / each_round.min(axis=0)
    dear, cheap = min(ns, key=med.get), max(ns, key=med.get)
    print(f"  dearest over cheapest circle-step (N = {dear} over N = {cheap}): {med[cheap] / med[dear]:.2f} (ratio "
          f"of medians), {np.median(per_round):.2f} [{np.percentile(per_round, 25):.2f}, "
          f"{np.percentile(per_round, 75):.2f}] (median over rounds of each round's slowest over fastest, quartiles)")


if __name__ == "__main__":
    main()
