"""Cost per unit of simulated time against the step length, the lengths measured in turn in one process.

    python bench/diagnostics/step_length.py [--scheme event|discrete] [--n 1000000] [--factors 0.25 0.5 1 2 3]
                                [--warm 6] [--span 0.9] [--rounds 12] [--arch cpu|gpu]

The scene is bench.py's throughput scene (area fraction 0.3, 16:9 walls, f32, radius 0.5,
speeds in (0.5, 1.0), seed 0), once for each step length `dt`: each factor times the
scheme's default dt (for the event scheme 0.3 mean radii over the fastest start speed, 0.15
here). Each copy first runs `--warm` units of simulated time (6: 40 of the event scheme's
default steps), so that its speeds have spread out from their start. Then each round runs
every copy in turn for about
`--span` of simulated time (whole steps: the span over the copy's dt, rounded, at least one),
the order reversed every other round, so that the load of a shared machine falls on all alike.

Reported for each dt: collisions per circle-step, circle-steps/s and collisions/s (the median
over the rounds with [min, max]), the pair collisions per unit of simulated time, the energy
change, and the cost per
unit of simulated time relative to the default dt's, as the median over rounds of each
round's ratio with its quartiles (above 1: dearer). The cost per simulated
time is what a user pays for a run; circle-steps/s alone rewards short steps, each of which
does less. The event scheme's result is the same physics at every dt (its collisions are
exact at any step length), so the pair collisions per unit of simulated time agree across
the rows to within the chaos of the runs; the discrete scheme's errors grow with dt (see
bench.py's work-precision section).

A step costs at least about 0.1 ms (its kernel launches) whatever N, and about 0.1 s at 1e6
circles on a 2-core CPU: factors whose warm-up and rounds would take more than
MAX_STEPS_PER_COPY steps of one copy (a tiny factor, say 1e-9) are refused before any work.
"""
import argparse
import dataclasses
import math
import os
import sys
import time

import numpy as np
import taichi as ti

import circles

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # bench/, for bench.py
from bench import R, SPEED  # noqa: E402
from kernel_profile import bench_scene  # noqa: E402

#: The most steps one copy may take (warm-up and rounds): 1e5 steps are 10 s at the least and
#: hours at 1e6 circles; a step length that needs more measures the launches, not the physics.
MAX_STEPS_PER_COPY = 100_000


def steps_per_copy(scheme, factor, warm, span, rounds):
    """About how many steps a copy at `factor` times the default dt takes, from the scene's largest
    start speed (SPEED's upper end: the default dt it gives is the least, so this is an upper
    estimate), before anything is placed."""
    dt = factor * circles.schemes.default_dt(scheme, np.full(1, R), np.array([[SPEED[1], 0.0]]))
    return math.ceil(warm / dt) + rounds * max(1, round(span / dt)), dt


def check_steps(parser, args, factors):
    """Refuse step lengths whose copy would take more than MAX_STEPS_PER_COPY steps."""
    steps, dt = steps_per_copy(args.scheme, factors[0], args.warm, args.span, args.rounds)
    if steps > MAX_STEPS_PER_COPY:
        least = factors[0] * steps / MAX_STEPS_PER_COPY
        parser.error(f"--factors {factors[0]:g}: dt {dt:.3g} would take about {steps:.3g} steps of a copy (warm-up "
                     f"{args.warm:g} and {args.rounds} rounds of {args.span:g} of simulated time), above the limit of "
                     f"{MAX_STEPS_PER_COPY} (a step costs 0.1 ms at the least, 0.1 s at 1e6 circles); give factors of "
                     f"{least:.2g} or more, or less --warm, --span or --rounds")


def spread(rates):
    """'median [min, max] M' of per-round rates."""
    return f"{np.median(rates) / 1e6:.3g} M [{rates.min() / 1e6:.3g}, {rates.max() / 1e6:.3g}]"


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scheme", choices=("event", "discrete"), default="event",
                        help="scheme of every copy (default: event)")
    parser.add_argument("--n", type=int, default=1_000_000, help="circles of each copy (default: 1000000)")
    parser.add_argument("--factors", type=float, nargs="+", default=[0.25, 0.5, 1.0, 2.0, 3.0],
                        help="step lengths, as multiples of the default dt (1 must be among them; default: 0.25 0.5 "
                             "1 2 3)")
    parser.add_argument("--warm", type=float, default=6.0,
                        help="simulated time of each copy before the timed rounds (default: 6)")
    parser.add_argument("--span", type=float, default=0.9,
                        help="simulated time of each copy in a round (default: 0.9)")
    parser.add_argument("--rounds", type=int, default=12, help="rounds, each running every copy once (default: 12)")
    parser.add_argument("--arch", choices=("cpu", "gpu"), default="cpu", help="where the kernels run (default: cpu)")
    args = parser.parse_args()
    factors = sorted(set(args.factors))
    if 1.0 not in factors or factors[0] <= 0:
        parser.error(f"--factors {' '.join(map(str, args.factors))}: give positive factors, 1 (the default dt) "
                     "among them")
    if args.n < 1 or args.warm < 0 or args.span <= 0 or args.rounds < 1:
        parser.error(f"--n {args.n}, --warm {args.warm}, --span {args.span}, --rounds {args.rounds}: give N >= 1, "
                     "warm >= 0, span > 0 and one round at least")
    check_steps(parser, args, factors)
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
    pairs = {f: [] for f in factors}  # pair collisions of each round
    for k in range(args.rounds):
        for f in (factors if k % 2 == 0 else factors[::-1]):
            sim = sims[f]
            before = sim.stats()["pair_collisions"]
            ti.sync()
            t0 = time.perf_counter()
            sim.step(steps[f])
            ti.sync()
            walls[f].append(time.perf_counter() - t0)
            pairs[f].append(sim.stats()["pair_collisions"] - before)
    # Wall seconds per unit of simulated time, each round.
    cost = {f: np.array(walls[f]) / (steps[f] * sims[f].dt) for f in factors}
    print(f"{args.scheme}, N = {args.n}, after {args.warm:g} of simulated time, {args.rounds} rounds of about "
          f"{args.span:g} each, on the {args.arch}; default dt {default.dt:.4g}:")
    print("| dt / default | dt | collisions per circle-step | circle-steps/s median [min, max] | collisions/s "
          "median [min, max] | pair collisions per unit of time | cost per unit of time, relative [q25, q75] "
          "| energy change |")
    print("|---|---|---|---|---|---|---|---|")
    for f in factors:
        sim = sims[f]
        end = sim.stats()
        total = end["pair_collisions"] - start[f]["pair_collisions"]
        span = args.rounds * steps[f] * sim.dt
        circle_steps = args.n * args.rounds * steps[f]
        rel = cost[f] / cost[1.0]
        energy = end["kinetic_energy"] / start[f]["kinetic_energy"] - 1
        print(f"| {f:g} | {sim.dt:.4g} | {total / circle_steps:.3g} | "
              f"{spread(args.n * steps[f] / np.array(walls[f]))} | {spread(np.array(pairs[f]) / walls[f])} | "
              f"{total / span:.4g} | {np.median(rel):.3f} "
              f"[{np.percentile(rel, 25):.3f}, {np.percentile(rel, 75):.3f}] | {energy:.1e} |")


if __name__ == "__main__":
    main()
