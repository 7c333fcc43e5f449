"""Where a dense event step's time goes: the grid, the queue's kernels, and Python between them.

    python bench/diagnostics/dense_profile.py [--n 870] [--fraction 0.698] [--threads 1] [--span 100]
                                              [--warm 20]

bench/dense.py's scene (equal disks from a triangular crystal in a periodic box, speeds 1 at
the start, f64). The scene runs `--warm` time units, then `--span` at its default step and
`--span` / 8 at an eighth of it, each stage's wall time taken around its call (every stage
returns a value or reads one back, so each call ends when its kernel has). Reported per step:
the collisions, the microseconds of each stage and of the rest (Python), and, from the two
step lengths, the cost a step pays whatever its collisions (the fixed cost) and the cost of
each collision: t(step) = fixed + per collision x collisions, solved from the two.
"""
import argparse
import os
import sys
import time

import circles

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from dense import scene  # bench/dense.py's scene, after the path above


def run(n, fraction, threads, dt_factor, warm, span):
    sim = circles.Simulation(scene(circles, n, fraction))
    sim.dt = sim.dt * dt_factor
    sim.advance(warm)
    from circles.event import queue, split
    spent = {}

    def timed(owner, name, label):
        f = getattr(owner, name)

        def g(*a, **k):
            t = time.perf_counter()
            out = f(*a, **k)
            spent[label] = spent.get(label, 0.0) + time.perf_counter() - t
            return out
        setattr(owner, name, g)
        return f

    saved = [(sim.grid, "build", timed(sim.grid, "build", "grid")),
             (queue, "queue_step", timed(queue, "queue_step", "one queue")),
             (split, "split_parts", timed(split, "split_parts", "parts: split")),
             (split, "queue_parts", timed(split, "queue_parts", "parts: queues")),
             (split, "repredict", timed(split, "repredict", "parts: predictions again")),
             (queue, "apply_sums", timed(queue, "apply_sums", "parts: sums"))]
    before, steps = sim.stats()["pair_collisions"], sim.steps
    t = time.perf_counter()
    sim.advance(span)
    wall = time.perf_counter() - t
    for owner, name, f in saved:
        setattr(owner, name, f)
    k = sim.steps - steps
    pairs = sim.stats()["pair_collisions"] - before
    per_step = {label: s / k * 1e6 for label, s in spent.items()}
    per_step["Python and the rest"] = wall / k * 1e6 - sum(per_step.values())
    return dict(dt=sim.dt, steps=k, pairs_per_step=pairs / k, us_per_step=wall / k * 1e6, stages=per_step,
                rate=pairs / wall)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=870)
    ap.add_argument("--fraction", type=float, default=0.698)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--span", type=float, default=100.0)
    ap.add_argument("--warm", type=float, default=20.0)
    args = ap.parse_args()
    circles.init(arch="cpu", cpu_max_num_threads=args.threads)
    full = run(args.n, args.fraction, args.threads, 1.0, args.warm, args.span)
    short = run(args.n, args.fraction, args.threads, 0.125, args.warm, args.span / 8)
    per = (full["us_per_step"] - short["us_per_step"]) / (full["pairs_per_step"] - short["pairs_per_step"])
    fixed = full["us_per_step"] - per * full["pairs_per_step"]
    print(f"N = {args.n}, area fraction {args.fraction}, {args.threads} thread(s)")
    print("| step | collisions a step | microseconds a step | collisions/s | " +
          " | ".join(full["stages"]) + " |")
    print("|---" * (4 + len(full["stages"])) + "|")
    for r in (full, short):
        print(f"| {r['dt']:.4g} | {r['pairs_per_step']:.0f} | {r['us_per_step']:.1f} | {r['rate'] / 1e6:.3f} M | " +
              " | ".join(f"{r['stages'].get(label, 0.0):.1f}" for label in full["stages"]) + " |")
    print(f"fixed cost {fixed:.1f} microseconds a step; {per:.3f} microseconds a collision")


if __name__ == "__main__":
    main()
