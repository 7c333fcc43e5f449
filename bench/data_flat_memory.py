"""Memory of a long trajectory: the process's resident memory after each of FRAMES GSD frames of
a simulation of N circles (a periodic box at area fraction 0.2, stepping a little between
frames). Flat when frames stream to the file.

    python bench/data_flat_memory.py [N] [FRAMES] [PATH]
"""
import math
import resource
import sys
import time

import circles
from circles.trajectory import GSDWriter


def resident_mb():
    with open("/proc/self/statm") as file:
        return int(file.read().split()[1]) * resource.getpagesize() / 2**20


def main():
    n = int(float(sys.argv[1])) if len(sys.argv) > 1 else 1_000_000
    frames = int(sys.argv[2]) if len(sys.argv) > 2 else 30
    path = sys.argv[3] if len(sys.argv) > 3 else "flat.gsd"
    circles.init("cpu")
    side = math.sqrt(n * math.pi * 0.09 / 0.2)
    sim = circles.Simulation(circles.Scene(n=n, box=(side, side), radius=0.3, boundary="periodic", seed=1))
    with GSDWriter(path) as writer:
        for k in range(frames):
            tick = time.perf_counter()
            writer.write(sim)
            seconds = time.perf_counter() - tick
            print(f"frame {k:3d}  resident {resident_mb():7.1f} MiB  write+stats {seconds:.3f} s", flush=True)
            sim.step(1)


if __name__ == "__main__":
    main()
