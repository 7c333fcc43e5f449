"""Collisions per second of dense disks against the event step's length, side by side in one process.

    python bench/diagnostics/dense_step.py [--n 870] [--fraction 0.698] [--dts 0.15 default]
                                           [--rounds 6] [--span 20] [--threads 1] [--warm 20]

bench/dense.py's scene (equal disks from a triangular crystal in a periodic box, speeds 1 at
the start, f64), once per step length: "default" is the scene's own (the event scheme's
collision bound, `EVENT_STEP_COLLISIONS`), 0.15 the radii's step alone (0.3 mean radii for the
fastest start speed, 1). Each copy warms up for `--warm` time units (20); then each round runs every
copy in turn for `--span` time units, the order reversed every other round, so that a shared
machine's load falls on all alike. Reported per dt: pair collisions per second, median
[min, max] over the rounds, and its ratio to the first dt's, median over the rounds.
"""
import argparse
import os
import statistics
import sys
import time

import circles

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from dense import crystal_of, scene  # bench/dense.py's scene, after the path above


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=870)
    ap.add_argument("--fraction", type=float, default=0.698)
    ap.add_argument("--dts", nargs="+", default=["0.15", "default"])
    ap.add_argument("--rounds", type=int, default=6)
    ap.add_argument("--span", type=float, default=20.0)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--warm", type=float, default=20.0, help="time units each copy runs first (default 20)")
    args = ap.parse_args()
    circles.init(arch="cpu", cpu_max_num_threads=args.threads)
    try:
        crystal_of(args.n)
    except ValueError as e:
        ap.error(f"--n: {e}")
    sims = []
    for dt in args.dts:
        sim = circles.Simulation(scene(circles, args.n, args.fraction))
        if dt != "default":
            sim.dt = float(dt)
        sim.advance(args.warm)
        sims.append(sim)
    rates = [[] for _ in sims]
    for r in range(args.rounds):
        order = range(len(sims)) if r % 2 == 0 else reversed(range(len(sims)))
        for k in order:
            sim = sims[k]
            before = sim.stats()["pair_collisions"]
            t = time.perf_counter()
            sim.advance(args.span)
            rates[k].append((sim.stats()["pair_collisions"] - before) / (time.perf_counter() - t))
    print(f"N = {args.n}, area fraction {args.fraction}, {args.threads} thread(s), {args.rounds} rounds of "
          f"{args.span:g} time units")
    print("| dt | pair collisions/s, median [min, max] | ratio to the first |")
    print("|---|---|---|")
    for k, sim in enumerate(sims):
        ratio = statistics.median(a / b for a, b in zip(rates[k], rates[0]))
        print(f"| {sim.dt:.4g} | {statistics.median(rates[k]) / 1e6:.3f} M [{min(rates[k]) / 1e6:.3f}, "
              f"{max(rates[k]) / 1e6:.3f}] | {ratio:.2f} |")


if __name__ == "__main__":
    main()
