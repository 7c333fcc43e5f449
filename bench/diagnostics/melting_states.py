"""The states of 870 dense disks that a run samples: pressure and the crystal's orientation over time.

    python bench/diagnostics/melting_states.py [--fraction 0.718] [--duration 400000] [--block 2000]
                                               [--seed 11] [--start crystal] [--ecmc PATH --ecmc-length 10]

The melting sweep's system (870 equal disks in the periodic 29 : 30 sqrt(3)/2 box, radius 0.5,
speeds 1), started from the crystal or a compressed fluid, run for `--duration` time units on
one thread. Each block of `--block` time units gives a row: beta P d^2 over the block, the
global hexatic order |psi_6| at its end, and the orientation of the mean psi_6, arg / 6 in
degrees: 0 when the crystal's rows lie along the box's x axis, as in the start; a crystal
turned in the box must hold defects, since the box fits the crystal only unturned.

The summary splits the blocks by orientation (within `ALIGNED_DEGREES` of 0, or turned) and
gives each state's share of the time and its mean pressure, and counts the switches between
states with the CPU seconds of the run (the peer's include the writing of its samples): a pressure that averages over
states is only as good as the sampling of the switches between them.

With `--ecmc PATH`, Li et al.'s event-chain Monte Carlo program (bench/peer_ecmc.py) runs the
same disks from the same crystal, and its 1000 samples are read in 40 blocks of 25 the same way.
"""
import argparse
import itertools
import math
import os
import resource
import subprocess
import sys
import tempfile
import time

import numpy as np

#: An orientation within this many degrees of the box's axes counts as aligned.
ALIGNED_DEGREES = 1.0


def orientation_degrees(local):
    """The orientation of the mean psi_6, in degrees in (-30, 30]."""
    return float(np.degrees(np.angle(np.mean(local)) / 6.0))


def summary(rows):
    """{state: (share of the rows, mean pressure)} for "aligned" and "turned" rows (p, order, degrees)."""
    out = {}
    for state, pick in (("aligned", lambda d: abs(d) <= ALIGNED_DEGREES), ("turned", lambda d: abs(d) > ALIGNED_DEGREES)):
        chosen = [p for p, _, d in rows if pick(d)]
        out[state] = (len(chosen) / len(rows), float(np.mean(chosen)) if chosen else math.nan)
    return out


def switches(rows):
    """How many times the state changes from one block to the next."""
    turned = [abs(d) > ALIGNED_DEGREES for _, _, d in rows]
    return sum(a != b for a, b in itertools.pairwise(turned))


def print_summary(name, rows, cpu):
    states = summary(rows)
    mean = float(np.mean([p for p, _, _ in rows]))
    print(f"{name}: beta P d^2 over all {len(rows)} blocks {mean:.4f}; "
          + "; ".join(f"{s} {share:.0%} of the time, beta P d^2 {p:.4f}" for s, (share, p) in states.items())
          + f"; {switches(rows)} switches in {cpu:.0f} CPU s")


def run_circles(args):
    import circles
    from circles.observables import interval
    from circles.order import hexatic_order, psi6

    circles.init(arch="cpu", cpu_max_num_threads=1)
    scene = circles.Scene(n=870, crystal=(29, 30), area_fraction=args.fraction, radius=0.5, speed=(1.0, 1.0),
                          mass="equal", boundary="periodic", start=args.start, seed=args.seed)
    sim = circles.Simulation(scene)
    started = time.process_time()
    rows, before = [], sim.stats()
    print("| time | beta P d^2 | abs psi_6 | orientation, degrees |")
    print("|---|---|---|---|")
    while sim.time < args.duration - 1e-9:
        sim.advance(args.block)
        after = sim.stats()
        p = interval(before, after, scene.n, scene.box, scene.boundary, 0.5, 1.0)["reduced_pressure"]
        local = psi6(sim.state().pos, sim.box, True)
        rows.append((p, hexatic_order(local), orientation_degrees(local)))
        print(f"| {sim.time:.0f} | {p:.4f} | {rows[-1][1]:.3f} | {rows[-1][2]:.2f} |", flush=True)
        before = after
    return rows, time.process_time() - started


def run_ecmc(args):
    import h5py

    from circles.order import hexatic_order, psi6

    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    import peer_ecmc

    if peer_ecmc.missing(args.ecmc):
        sys.exit(peer_ecmc.missing(args.ecmc))
    with tempfile.TemporaryDirectory() as scratch:
        out = os.path.join(scratch, "ecmc.h5")
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        subprocess.run([args.ecmc, "29", "30", str(args.fraction), "0", str(args.ecmc_length), "crystal", out,
                        os.path.join(scratch, "none.h5")], capture_output=True, check=True, cwd=scratch)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu = (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)
        rows = []
        with h5py.File(out) as f:
            box = np.array(f["parameters/L"], dtype=float)
            pressure = np.array(f["pressure"], dtype=float) * peer_ecmc.TO_REDUCED
            per = len(pressure) // 40
            print("| samples | beta P d^2 | abs psi_6 | orientation, degrees |")
            print("|---|---|---|---|")
            for k in range(40):
                local = psi6(np.array(f[f"config-{(k + 1) * per - 1}"]) + box / 2, tuple(box), True)
                rows.append((float(pressure[k * per:(k + 1) * per].mean()), hexatic_order(local),
                             orientation_degrees(local)))
                print(f"| {k * per} to {(k + 1) * per - 1} | {rows[-1][0]:.4f} | {rows[-1][1]:.3f} | {rows[-1][2]:.2f} |")
    return rows, cpu


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fraction", type=float, default=0.718)
    ap.add_argument("--duration", type=float, default=400000.0, help="time units (default 400000; 0 runs only the peer)")
    ap.add_argument("--block", type=float, default=2000.0, help="time units a row (default 2000)")
    ap.add_argument("--seed", type=int, default=11)
    ap.add_argument("--start", choices=("crystal", "compressed"), default="crystal")
    ap.add_argument("--ecmc", help="the StraightEcmc program (bench/peer_ecmc.py), run from the crystal too")
    ap.add_argument("--ecmc-length", type=int, default=10, help="its length factor (default 10)")
    args = ap.parse_args()
    peer = run_ecmc(args) if args.ecmc else None
    ours = run_circles(args) if args.duration > 0 else None
    if peer:
        print_summary("event-chain Monte Carlo", *peer)
    if ours:
        print_summary("circles", *ours)


if __name__ == "__main__":
    main()
