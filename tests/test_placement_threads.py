"""Placement gives bit-identical positions with 1 and with 2 CPU threads, for every method:
random sequential addition, the filled lattice with its overlaps removed (equal and spread
radii, walls and periodic, float32 and float64, and a dense mixture where the push is
turned down), the jittered lattice with Monte Carlo, and circles that grow back on it.
Bit-identical, no tolerance: random numbers come from counters and every sum that feeds a
position is taken in a fixed order, so any difference is a race.

``ti.init`` is per process, so each thread count runs in its own process and writes the
positions to an npz file (the pattern of test_determinism.py).
"""

import json
import os
import pathlib
import subprocess
import sys
import textwrap

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]

# name -> (n, radius range, area fraction, periodic, float32, method)
CASES = {
    "rsa_f32": (3000, (0.5, 0.5), 0.3, False, True, "place"),
    "fluid_walls_f32": (3000, (0.5, 0.5), 0.5, False, True, "place"),
    "fluid_spread_periodic": (2000, (0.005, 0.015), 0.6, True, False, "place"),
    "spread_dense_walls": (1500, (0.005, 0.015), 0.8, False, True, "place"),
    "lattice_walls_f32": (2000, (0.5, 0.5), 0.8, False, True, "place"),
    "lattice_grow_periodic": (600, (0.005, 0.015), 0.75, True, False, "lattice"),
}

SCRIPT = textwrap.dedent("""
    import json, math, sys
    import numpy as np
    import circles
    from circles import placement

    threads, out, cases = int(sys.argv[1]), sys.argv[2], json.loads(sys.argv[3])
    circles.init(arch="cpu", cpu_max_num_threads=threads)
    arrays = {}
    for name, (n, (rlo, rhi), fraction, periodic, single, how) in cases.items():
        rng = np.random.default_rng(17)
        radius = rng.uniform(rlo, rhi, n) if rhi > rlo else np.full(n, rlo)
        area = float(np.sum(np.pi * radius ** 2)) / fraction
        box = (math.sqrt(area * 16 / 9), math.sqrt(area * 9 / 16))
        if how == "place":
            arrays[name] = placement.place(radius, box, periodic, 17, rng, single)
        else:
            arrays[name] = placement.lattice_monte_carlo(radius, box, periodic, rng, single, sweeps=5)
    np.savez(out, **arrays)
""")


def run_in_process(threads, out):
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")])
    done = subprocess.run([sys.executable, "-c", SCRIPT, str(threads), str(out), json.dumps(CASES)],
                          cwd=ROOT, env=env, capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr[-3000:]
    return np.load(out)


def test_same_placement_with_1_and_2_threads(tmp_path):
    one = run_in_process(1, tmp_path / "threads1.npz")
    two = run_in_process(2, tmp_path / "threads2.npz")
    assert sorted(one.files) == sorted(CASES)
    different = [name for name in CASES if not np.array_equal(one[name], two[name])]
    assert not different, f"placement differs between 1 and 2 threads: {different}"
