"""Random placement: every circle placed, none overlapping, all inside the
walls, radii, speeds and masses as asked, at low and high density.

No tolerance on overlaps and walls: placement keeps every pair (r_i + r_j)
(1 + 1e-6) apart and every circle r (1 + 1e-6) inside the walls, checked on the
stored positions, so every distance is at least the sum of the radii and no
circle crosses a wall, exactly (see also test_placement_methods.py).
Speeds are |v| of a vector built from a speed and a direction: 1e-12 relative
covers the rounding of cos, sin and the norm.
"""

import math

import numpy as np
import pytest

from reference import outside_walls, pair_overlap


def box_for(n, radius, fraction, aspect=1.0):
    rlo, rhi = (radius, radius) if np.isscalar(radius) else radius
    mean_area = math.pi * (rlo * rlo + rlo * rhi + rhi * rhi) / 3
    area = n * mean_area / fraction
    return (math.sqrt(area * aspect), math.sqrt(area / aspect))


CASES = [
    # name, n, radius, fraction, boundary
    ("equal_0.10", 2000, 0.01, 0.10, "walls"),
    ("equal_0.50", 2000, 0.01, 0.50, "walls"),
    ("equal_0.85", 400, 0.01, 0.85, "walls"),
    ("poly_0.60", 1000, (0.005, 0.015), 0.60, "walls"),
    ("equal_0.50_periodic", 2000, 0.01, 0.50, "periodic"),
    ("poly_0.75_periodic", 400, (0.005, 0.015), 0.75, "periodic"),
    ("poly_0.80", 600, (0.005, 0.015), 0.80, "walls"),
]


@pytest.mark.parametrize("name, n, radius, fraction, boundary", CASES, ids=[c[0] for c in CASES])
def test_placement(circles_cpu, name, n, radius, fraction, boundary):
    box = box_for(n, radius, fraction, aspect=16 / 9)
    speed = (0.3, 0.9)
    scene = circles_cpu.Scene(n=n, box=box, radius=radius, speed=speed, mass="radius",
                              boundary=boundary, scheme="event", precision="f64", seed=3)
    sim = circles_cpu.Simulation(scene)
    s = sim.state()
    assert sim.n == n
    assert s.pos.shape == (n, 2) and s.vel.shape == (n, 2)
    assert s.radius.shape == (n,) and s.mass.shape == (n,) and s.color.shape == (n, 3)
    assert np.all(np.isfinite(s.pos)) and np.all(np.isfinite(s.vel))

    rlo, rhi = (radius, radius) if np.isscalar(radius) else radius
    assert np.all((s.radius >= rlo) & (s.radius <= rhi))
    if rlo < rhi:  # a real spread, not a few values
        assert s.radius.max() - s.radius.min() > 0.8 * (rhi - rlo)
    phi = np.sum(np.pi * s.radius**2) / (box[0] * box[1])
    assert phi == pytest.approx(fraction, rel=0.05)

    if boundary == "walls":
        crossing = outside_walls(s.pos, s.radius, box)
        assert crossing <= 0.0, f"a circle crosses a wall by {crossing:.3g} of its radius"
    else:
        assert np.all(s.pos >= 0.0) and np.all(s.pos <= np.array(box))
    worst = pair_overlap(s.pos, s.radius, box if boundary == "periodic" else None)
    assert worst <= 0.0, f"{name}: pairs overlap by up to {worst:.3g} of the contact distance"
    reported = sim.stats()["max_overlap"]
    assert reported == 0.0, f"{name}: stats()['max_overlap'] = {reported:.3g}"

    v = np.hypot(s.vel[:, 0], s.vel[:, 1])
    assert np.all(v >= speed[0] * (1 - 1e-12)) and np.all(v <= speed[1] * (1 + 1e-12)), \
        f"speeds in [{v.min()}, {v.max()}], asked {speed}"
    assert v.max() - v.min() > 0.8 * (speed[1] - speed[0])  # the range is used, not one value
    # mass proportional to radius: the same ratio for every circle
    ratio = s.mass / s.radius
    assert np.all(np.abs(ratio / ratio[0] - 1) <= 1e-12)


def test_placement_is_spread_over_the_box(circles_cpu):
    """At low density the circles cover the box evenly: each of the 4 x 4
    blocks holds 1/16 of them within 5 standard deviations of a binomial
    count (a placement biased to a corner or a lattice fails)."""
    n = 4000
    box = box_for(n, 0.004, 0.1, aspect=2.0)
    sim = circles_cpu.Simulation(circles_cpu.Scene(n=n, box=box, radius=0.004, speed=(0.5, 1.0),
                                                   seed=4))
    pos = sim.state().pos
    counts, _, _ = np.histogram2d(pos[:, 0], pos[:, 1], bins=4, range=[[0, box[0]], [0, box[1]]])
    expected, sd = n / 16, math.sqrt(n / 16 * 15 / 16)
    # the wall margin r leaves the edge blocks slightly less area
    assert np.all(np.abs(counts - expected) <= 5 * sd + 0.02 * expected)


@pytest.mark.parametrize("mass, expect", [("area", lambda r: r * r), ("equal", lambda r: np.ones_like(r))],
                         ids=["area", "equal"])
def test_mass_models(circles_cpu, mass, expect):
    """'area': m proportional to r^2; 'equal': all masses the same."""
    sim = circles_cpu.Simulation(circles_cpu.Scene(n=300, box=(1.0, 1.0), radius=(0.01, 0.03),
                                                   mass=mass, seed=5))
    s = sim.state()
    ratio = s.mass / expect(s.radius)
    assert np.all(np.abs(ratio / ratio[0] - 1) <= 1e-12)


def test_same_seed_same_placement_other_seed_differs(circles_cpu):
    def placed(seed):
        return circles_cpu.Simulation(circles_cpu.Scene(n=500, box=(1.0, 1.0), radius=0.01,
                                                        seed=seed)).state()
    a, b, c = placed(8), placed(8), placed(9)
    assert np.array_equal(a.pos, b.pos) and np.array_equal(a.vel, b.vel)
    assert not np.array_equal(a.pos, c.pos)
    # Seeds that differ only above bit 31 place apart too (the placement's hash keys on 31
    # bits; a larger seed's key is drawn from all of its bits, not cut to the low ones).
    for far in (8 + 2 ** 31, 8 + 2 ** 32, 8 + 2 ** 64):
        assert not np.array_equal(placed(far).pos, a.pos)


def test_wide_radius_spread_places_large_circles_first(circles_cpu):
    """1% of the circles 50 times larger, area fraction 0.3 (the large ones hold 0.29 of it).

    Placed all at once, the small circles sprinkle the box before most large ones have a
    place, and then no hole of a large radius is left: random sequential addition jams.
    Placed by size class, largest first, every circle finds room. Tolerances as above.
    """
    from circles import placement

    n, r = 2000, 0.01
    radius = np.full(n, r)
    radius[:20] = 50 * r
    area = float(np.sum(np.pi * radius ** 2)) / 0.3
    box = (math.sqrt(area * 16 / 9), math.sqrt(area * 9 / 16))
    pos = placement.random_sequential(radius, box, False, seed=3)
    assert pos is not None
    assert pair_overlap(pos, radius) <= 0.0
    assert outside_walls(pos, radius, box) <= 0.0
