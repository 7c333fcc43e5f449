"""The event-chain Monte Carlo peer of the dense section: Li et al.'s straight ECMC program.

    python bench/peer_ecmc.py PATH [--length 8]

PATH is the program `StraightEcmc` built from its public source (github.com/jellyfysh/HistoricDisks,
folder CPP/StraightECMC; it needs Boost, HDF5 and HighFive: on Debian `apt-get install
libboost-dev libboost-system-dev libboost-serialization-dev libhdf5-dev`, HighFive as the
folder's submodule, then `cmake . -B build && cmake --build build`). Its code never enters
this project: the benchmark runs the program the user built, if given, and reads its output
with h5py (`pip install h5py`).

`run(path, nx, ny, eta, length)` runs it on nx x ny disks at area fraction eta in the box that
fits the crystal (its "crystal" shape, the melting sweep's box for 29 x 30), from the crystal,
with its run length times `length` (about 2e8 chain events each), and returns its pressure:
the program samples it 1000 times in a run (its equation 21); the first EQUILIBRATION of the
samples are dropped, and the standard error comes from BLOCKS blocks of the rest. Its unit,
beta P V0 / N with V0 the area of the close-packed crystal (N sqrt(3)/2 d^2), is turned into
beta P d^2 (times 2 / sqrt 3). The CPU seconds are the program's, as the kernel counts them
for this child, times the share of the samples kept.
"""
import argparse
import math
import os
import resource
import subprocess
import sys
import tempfile

#: Samples dropped at the start (the crystal melting towards equilibrium), as a share.
EQUILIBRATION = 0.2
#: Blocks of the samples kept, for the standard error.
BLOCKS = 10
#: beta P d^2 per unit of the program's pressure, beta P V0 / N with V0 = N sqrt(3) / 2 d^2.
TO_REDUCED = 2.0 / math.sqrt(3.0)


def missing(path):
    """Why `path` cannot run as the peer (the words of an --ecmc error), or None when it can."""
    if os.path.isfile(path) and os.access(path, os.X_OK):
        return None
    return (f"--ecmc {path}: no such program; give the path of StraightEcmc as built from CPP/StraightECMC "
            "(see bench/peer_ecmc.py)")


def run(path, nx, ny, eta, length):
    """Run the program; returns a dict of its pressure, standard error and CPU seconds."""
    import h5py
    import numpy as np
    if missing(path):
        raise FileNotFoundError(missing(path))
    with tempfile.TemporaryDirectory() as scratch:
        out = os.path.join(scratch, "ecmc.h5")
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        done = subprocess.run([path, str(nx), str(ny), str(eta), "0", str(length), "crystal", out,
                               os.path.join(scratch, "none.h5")], capture_output=True, text=True, cwd=scratch)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        if done.returncode != 0:
            raise RuntimeError(f"{path} failed ({done.returncode}): {done.stderr[-500:]}")
        with h5py.File(out) as f:
            pressure = np.array(f["pressure"], dtype=float) * TO_REDUCED
            events = int(np.array(f["stats/collisions"]))
    cpu = (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)
    kept = pressure[int(EQUILIBRATION * len(pressure)):]
    m = len(kept) // BLOCKS
    means = kept[: m * BLOCKS].reshape(BLOCKS, m).mean(axis=1)
    se = float(means.std(ddof=1) / math.sqrt(BLOCKS))
    cpu_kept = cpu * len(kept) / len(pressure)
    return dict(peer="event-chain Monte Carlo (Li et al. 2022, StraightEcmc)", n=nx * ny, area_fraction=eta,
                length=length, events=events, cpu_s=cpu, events_per_cpu_s=events / cpu, mean=float(kept.mean()),
                se=se, cpu_s_measured=cpu_kept, merit=se * math.sqrt(cpu_kept),
                cpu_s_to_se_0_01=cpu_kept * (se / 0.01) ** 2)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("path", help="the StraightEcmc program")
    ap.add_argument("--length", type=int, default=8, help="its length factor (default 8: about 1.6e9 events)")
    args = ap.parse_args()
    r = run(args.path, 29, 30, 0.698, args.length)
    print(", ".join(f"{k} {v:.4g}" if isinstance(v, float) else f"{k} {v}" for k, v in r.items()))


if __name__ == "__main__":
    sys.exit(main())
