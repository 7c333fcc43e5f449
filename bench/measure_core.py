"""Core throughput at large N: both schemes at N = 1e5 and 1e6, f32, area fraction 0.3, walls.

    python bench/measure_core.py [--arch cpu|gpu]

One warm-up step (compilation) is excluded; each row times single steps and reports the
median with min and max, the pair collisions per wall second, placement time, and the
relative energy change and largest overlap at the end (the error that comes with the speed).
"""
import argparse
import time

import numpy as np

import circles

ROWS = [(100_000, "discrete", 10), (100_000, "event", 5), (1_000_000, "discrete", 5), (1_000_000, "event", 2)]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--arch", default="cpu", choices=["cpu", "gpu"])
    args = parser.parse_args()
    circles.init(arch=args.arch)
    r, fraction = 0.001, 0.3
    for n, scheme, steps in ROWS:
        side = float(np.sqrt(n * np.pi * r * r / fraction))
        t = time.perf_counter()
        sim = circles.Simulation(circles.Scene(n=n, box=(side, side), radius=r, speed=(0.5, 1.0), scheme=scheme,
                                               precision="f32"))
        placement = time.perf_counter() - t
        sim.step(1)
        start = sim.stats()
        times = []
        for _ in range(steps):
            t = time.perf_counter()
            sim.step(1)
            times.append(time.perf_counter() - t)
        end = sim.stats()
        times = np.array(times)
        collisions = (end["pair_collisions"] - start["pair_collisions"]) / times.sum()
        print(f"N={n:>8} {scheme:8s} f32 fraction={fraction} walls dt={sim.dt:.3g}: "
              f"{n / np.median(times) / 1e6:.3f} M circle-steps/s (median of {steps} steps; "
              f"min {n / times.max() / 1e6:.3f}, max {n / times.min() / 1e6:.3f}), "
              f"{collisions / 1e6:.4f} M collisions/s, placement {placement:.1f} s, "
              f"energy change {end['kinetic_energy'] / start['kinetic_energy'] - 1:.1e}, "
              f"max overlap {end['max_overlap']:.1e}", flush=True)


if __name__ == "__main__":
    main()
