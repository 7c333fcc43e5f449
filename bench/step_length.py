"""Cost per unit of simulated time against the step length, the lengths measured in turn in one process.

    python bench/step_length.py [--scheme event|discrete] [--n 1000000] [--factors 0.25 0.5 1 2 3]
                                [--warm 6] [--span 0.9] [--rounds 12] [--arch cpu|gpu]

The scene is bench.py's throughput scene (area fraction 0.3, 16:9 walls, f32, radius 0.5,
speeds in (0.5, 1.0), seed 0), once for each step length `dt`: each factor times the
scheme's default dt (for the event scheme 0.3 mean radii over the fastest start speed, 0.15
here). Each copy first runs `--warm` units of simulated time (6: 40 of the event scheme's
default steps), so that its speeds have spread out from their start. Then each round runs
every copy in turn for about
`--span` of simulated time (whole steps: the span over the copy's dt, rounded, at least one),
the order reversed every other round, so that the load of a shared machine falls on all alike.

Reported for each dt: collisions per circle-step, circle-steps/s and collisions/s over all the
rounds, the pair collisions per unit of simulated time, the energy change, and the cost per
unit of simulated time relative to the default dt's, as the median over rounds of each
round's ratio with its quartiles (above 1: dearer). The cost per simulated
time is what a user pays for a run; circle-steps/s alone rewards short steps, each of which
does less. The event scheme's result is the same physics at every dt (its collisions are
exact at any step length), so the pair collisions per unit of simulated time agree across
the rows to within the chaos of the runs; the discrete scheme's errors grow with dt (see
bench.py's work-precision section).
"""
import argparse
import dataclasses
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
    parser.add_argument("--n", type=int, default=1_000_000)
    parser.add_argument("--factors", type=float, nargs="+", default=[0.25, 0.5, 1.0, 2.0, 3.0],
                        help="step lengths, as multiples of the default dt (1 must be among them)")
    parser.add_argument("--warm", type=float, default=6.0, help="simulated time of each copy before the timed rounds")
    parser.add_argument("--span", type=float, default=0.9, help="simulated time of each copy in a round")
    parser.add_argument("--rounds", type=int, default=12)
    parser.add_argument("--arch", choices=("cpu", "gpu"), default="cpu")
    args = parser.parse_args()
    factors = sorted(set(args.factors))
    if 1.0 not in factors or factors[0] <= 0:
        parser.error(f"--factors {' '.join(map(str, args.factors))}: give positive factors, 1 (the default dt) "
                     "among them")
    if args.n < 1 or args.warm < 0 or args.span <= 0 or args.rounds < 1:
        parser.error(f"--n {args.n}, --warm {args.warm}, --span {args.span}, --rounds {args.rounds}: give N >= 1, "
                     "warm >= 0, span > 0 and one round at least")
    circles.init(arch=args.arch)
    base = bench_scene(args.n, args.scheme)
    default = circles.Simulation(base)
    sims = {f: default if f == 1.0 else circles.Simulation(dataclasses.replace(base, dt=default.dt * f))
            for f in factors}
    for sim in sims.values():
        sim.advance(args.warm)
    steps = {f: max(1, round(args.span / sim.dt)) for f, sim in sims.items()}
    start = {f: sim.stats() for f, sim in sims.items()}
    walls = {f: [] for f in factors}  # wall seconds of each round
    for k in range(args.rounds):
        for f in (factors if k % 2 == 0 else factors[::-1]):
            sim = sims[f]
            ti.sync()
            t0 = time.perf_counter()
            sim.step(steps[f])
            ti.sync()
            walls[f].append(time.perf_counter() - t0)
    # Wall seconds per unit of simulated time, each round, and all the rounds' wall seconds.
    cost = {f: np.array(walls[f]) / (steps[f] * sims[f].dt) for f in factors}
    wall = {f: sum(walls[f]) for f in factors}
    print(f"{args.scheme}, N = {args.n}, after {args.warm:g} of simulated time, {args.rounds} rounds of about "
          f"{args.span:g} each, on the {args.arch}; default dt {default.dt:.4g}:")
    print("| dt / default | dt | collisions per circle-step | circle-steps/s | collisions/s | pair collisions per "
          "unit of time | cost per unit of time, relative [q25, q75] | energy change |")
    print("|---|---|---|---|---|---|---|---|")
    for f in factors:
        sim = sims[f]
        end = sim.stats()
        pairs = end["pair_collisions"] - start[f]["pair_collisions"]
        span = args.rounds * steps[f] * sim.dt
        circle_steps = args.n * args.rounds * steps[f]
        rel = cost[f] / cost[1.0]
        energy = end["kinetic_energy"] / start[f]["kinetic_energy"] - 1
        print(f"| {f:g} | {sim.dt:.4g} | {pairs / circle_steps:.3g} | {circle_steps / wall[f] / 1e6:.3g} M | "
              f"{pairs / wall[f] / 1e6:.3g} M | {pairs / span:.4g} | {np.median(rel):.3f} "
              f"[{np.percentile(rel, 25):.3f}, {np.percentile(rel, 75):.3f}] | {energy:.1e} |")


if __name__ == "__main__":
    main()
