"""Placement gives bit-identical positions with 1 and with 2 CPU threads, for every method:
random sequential addition, the filled lattice with its overlaps removed (equal and spread
radii, walls and periodic, float32 and float64, and a dense mixture where the push is
turned down), the jittered lattice with Monte Carlo, and circles that grow back on it.
Bit-identical, no tolerance: random numbers come from counters and every sum that feeds a
position is taken in a fixed order, so any difference is a race.

When the suite runs on the GPU, two GPU runs are compared instead. Each run is a process of
its own (see process_util).
"""

import json
import textwrap

import numpy as np

from process_util import INIT, compared_runs, run_script

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

    out, cases = sys.argv[2], json.loads(sys.argv[3])
""") + INIT + textwrap.dedent("""
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


def test_same_placement_with_1_and_2_threads(tmp_path):
    first, second = compared_runs()
    one = run_script(SCRIPT, first, tmp_path / "first.npz", json.dumps(CASES))
    two = run_script(SCRIPT, second, tmp_path / "second.npz", json.dumps(CASES))
    assert sorted(one.files) == sorted(CASES)
    different = [name for name in CASES if not np.array_equal(one[name], two[name])]
    assert not different, f"placement differs between runs {first} and {second}: {different}"
