"""Hard-disk equation of state and collision rate, both schemes, against Liu and Enskog.

    python bench/validation_table.py [--out outputs/bench/validation.md]

The same runs as tests/test_physics.py (equal disks of diameter 1, m = 1, all starting at
speed 1, periodic square box, f64, equilibrated for 10 collisions per circle, then measured
in 10 blocks): Z = 1 + virial / (2 t N kT) against Liu's fit, and the collision rate per
circle against Enskog's 2 rho sigma g(sigma) sqrt(pi kT / m). The event scheme runs at its
default dt; the discrete scheme at its default dt (the fastest circle moves 0.2 radii per
step). Errors are the standard errors of the block means.
"""
import argparse
import os
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "tests"))

import circles  # noqa: E402
from physics_util import box_for, enskog_rate, liu_z, measure_periodic  # noqa: E402

R = 0.5
# eta -> (N, pair collisions to average over): as in tests/test_physics.py.
RUNS = {0.1: (2000, 25_000), 0.3: (1000, 60_000), 0.5: (1000, 70_000), 0.65: (1000, 80_000)}
BLOCKS = 10
EQ_COLLISIONS_PER_CIRCLE = 10


def measure(eta, scheme, seed=1):
    n, pairs = RUNS[eta]
    side = box_for(n, R, eta)
    sim = circles.Simulation(circles.Scene(n=n, box=(side, side), radius=R, speed=(1.0, 1.0), mass="equal",
                                           boundary="periodic", scheme=scheme, precision="f64", seed=seed))
    omega = enskog_rate(eta, n / side ** 2, 2 * R, 0.5, 1.0)
    t0 = time.perf_counter()
    m = measure_periodic(sim, EQ_COLLISIONS_PER_CIRCLE, BLOCKS, 2 * pairs / (n * omega) / BLOCKS)
    m["wall_s"] = time.perf_counter() - t0
    m["omega"] = enskog_rate(eta, n / side ** 2, 2 * R, m["kT"], 1.0)
    m["dt"] = sim.dt
    return m


def check_out(ap, path):
    """Make the folder of `path` (none for a bare file name) and check that `path` can be written,
    before the runs: a bad path is a command-line error, not a crash after minutes of measuring."""
    folder = os.path.dirname(path)
    try:
        if folder:
            os.makedirs(folder, exist_ok=True)
    except OSError as e:
        ap.error(f"--out {path}: cannot make the folder {folder} ({e.strerror}): give a path you can write to")
    if os.path.isdir(path):
        ap.error(f"--out {path} is a folder: give a file name, e.g. {os.path.join(path, 'validation.md')}")
    try:
        if os.path.exists(path):
            open(path, "a").close()  # opened to append, not changed
        else:
            tempfile.TemporaryFile(dir=folder or ".").close()
    except OSError as e:
        ap.error(f"--out {path}: cannot write there ({e.strerror}): give a path you can write to")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=os.path.join("outputs", "bench", "validation.md"),
                    help="the markdown table (default: %(default)s)")
    args = ap.parse_args()
    check_out(ap, args.out)
    circles.init(arch="cpu")
    rows = ["| eta | scheme | dt | Z | Liu Z | Z error | collision rate | Enskog | rate error | pairs | max overlap "
            "| wall s |", "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for eta in RUNS:
        for scheme in ("event", "discrete"):
            m = measure(eta, scheme)
            z = liu_z(eta)
            row = (f"| {eta} | {scheme} | {m['dt']:.3g} | {m['Z']:.4f} ± {m['Z_err']:.4f} | {z:.4f} | "
                   f"{m['Z'] / z - 1:+.2%} | {m['rate']:.4f} ± {m['rate_err']:.4f} | {m['omega']:.4f} | "
                   f"{m['rate'] / m['omega'] - 1:+.2%} | {m['collisions']} | {m['max_overlap']:.2g} | "
                   f"{m['wall_s']:.1f} |")
            print(row, flush=True)
            rows.append(row)
    text = "\n".join(["# Hard-disk validation: both schemes against Liu and Enskog", "",
                      f"Command: `python bench/validation_table.py`. {__doc__.split(chr(10), 3)[3].strip()}", "",
                      *rows, ""])
    with open(args.out, "w") as f:
        f.write(text)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
