"""Invariants of the exact (event) scheme over long runs of many circles.

Why 1e-12 for energy and momentum (f64): each collision changes the energy of
the pair it touches by round-off, ~1e-16 of that pair's energy. Over 1e5
collisions among ~3000 circles each circle takes part in ~70 of them; even if
every error had the same sign the total would move by ~1e-14 relative. The
sums are accumulated in float64 (and re-checked here with math.fsum), so 1e-12
leaves a factor 100 for the engine and nothing for a real leak.

Overlap: the event scheme collides circles at contact, so the only overlap is
the round-off of a contact distance, ~1e-16 of the coordinates (~1) over a
contact distance of ~0.02, i.e. ~1e-14 relative; 1e-9 is the bound held here
(the tolerance `from_arrays` allows its input, simulation.INPUT_OVERLAP_TOLERANCE).
"""

import math

import numpy as np
import pytest

from reference import outside_walls, pair_overlap

TARGET_COLLISIONS = 100_000


def energy(s):
    return math.fsum(0.5 * s.mass * np.sum(s.vel * s.vel, axis=1))


def momentum(s):
    return np.array([math.fsum(s.mass * s.vel[:, 0]), math.fsum(s.mass * s.vel[:, 1])])


def run_until_collisions(sim, target):
    """Advance until at least ``target`` pair collisions, in a few chunks
    sized from the rate measured so far."""
    sim.advance(0.02)
    for _ in range(20):
        done = sim.stats()["pair_collisions"]
        if done >= target:
            return done
        rate = max(done, 1) / sim.time
        sim.advance(min(1.1 * (target - done) / rate, 10 * sim.time) + 1e-3)
    return sim.stats()["pair_collisions"]


@pytest.mark.parametrize("boundary", ["walls", pytest.param("periodic", marks=pytest.mark.slow)])
def test_energy_and_momentum_over_1e5_collisions(circles_cpu, boundary):
    """3000 circles, radii 0.005 to 0.009 (area fraction 0.25), masses
    proportional to area. Energy (engine's stats and math.fsum over state())
    to 1e-12 relative. Periodic box: no external force, so sum m v is
    conserved too; its error is measured against sum m |v|, the scale of the
    terms that cancel in it."""
    scene = circles_cpu.Scene(n=3000, box=(1.6, 1.2), radius=(0.005, 0.009), speed=(0.5, 1.0),
                              mass="area", boundary=boundary, scheme="event", precision="f64",
                              seed=11)
    sim = circles_cpu.Simulation(scene)
    s0 = sim.state()
    e0, p0 = energy(s0), momentum(s0)
    scale = math.fsum(s0.mass * np.hypot(s0.vel[:, 0], s0.vel[:, 1]))
    assert sim.stats()["kinetic_energy"] == pytest.approx(e0, rel=1e-14)
    assert np.array(sim.stats()["momentum"]) == pytest.approx(p0, abs=1e-14 * scale)

    done = run_until_collisions(sim, TARGET_COLLISIONS)
    assert done >= TARGET_COLLISIONS
    st = sim.stats()
    s = sim.state()
    assert abs(st["kinetic_energy"] - e0) <= 1e-12 * e0, st["kinetic_energy"] / e0 - 1
    assert abs(energy(s) - e0) <= 1e-12 * e0, energy(s) / e0 - 1
    if boundary == "walls":
        assert st["wall_collisions"] > 0
    else:
        assert st["wall_collisions"] == 0
        assert np.abs(np.array(st["momentum"]) - p0).max() <= 1e-12 * scale
        assert np.abs(momentum(s) - p0).max() <= 1e-12 * scale


@pytest.mark.parametrize("boundary", ["walls", "periodic"])
def test_no_overlap_and_inside_walls_dense(circles_cpu, boundary):
    """Area fraction 0.7, mixed radii: at the start and after every one of 8
    chunks of time, no pair overlaps by more than 1e-9 of its contact distance
    (engine's max_overlap and a brute-force check of state()), no circle
    crosses a wall by more than 1e-9 of its radius, and circles did collide."""
    n = 600
    radius = (0.008, 0.012)
    mean_area = math.pi * (radius[0] ** 2 + radius[0] * radius[1] + radius[1] ** 2) / 3
    side = math.sqrt(n * mean_area / 0.7)
    box = (side, side)
    scene = circles_cpu.Scene(n=n, box=box, radius=radius, speed=(0.5, 1.0), mass="radius",
                              boundary=boundary, scheme="event", precision="f64", seed=5)
    sim = circles_cpu.Simulation(scene)
    s = sim.state()
    phi = np.sum(np.pi * s.radius**2) / (box[0] * box[1])
    assert phi == pytest.approx(0.7, abs=0.02)
    periodic = box if boundary == "periodic" else None
    last = -1
    for chunk in range(9):
        if chunk:
            sim.advance(0.005)
        st = sim.stats()
        s = sim.state()
        assert st["max_overlap"] <= 1e-9, f"t = {sim.time}: max_overlap {st['max_overlap']:.3g}"
        worst = pair_overlap(s.pos, s.radius, periodic)
        assert worst <= 1e-9, f"t = {sim.time}: pairs overlap by up to {worst:.3g}"
        if boundary == "walls":
            crossing = outside_walls(s.pos, s.radius, box)
            assert crossing <= 1e-9, f"t = {sim.time}: a circle crosses a wall by {crossing:.3g}"
        assert st["pair_collisions"] > last
        last = st["pair_collisions"]
    assert last > 5 * n


@pytest.mark.parametrize("radius, precision, bound", [pytest.param(0.5, "f32", 5e-6, marks=pytest.mark.slow),
                                                     (0.5, "f64", 2e-14), (0.3, "f64", 5e-15)])
def test_energy_round_off_does_not_drift_one_way(circles_cpu, radius, precision, bound):
    """2000 equal circles at area fraction 0.3 for 400 s, about 262 collisions a circle (524000 in
    all). Each collision rounds the pair's energy by about one unit in the last place, a 1000th
    of the total's; errors of either sign add up like a random walk, to about 700 such units
    of a pair, 1.6e-16 of the total in f64 and 9e-8 in f32. A rounding of the same sign at every
    collision adds up in a line instead: the impulse along d / |d| (|d| nearly the same at every
    contact) changed the energy by +7e-5 in f32 and +1.3e-13 in f64 at radius 0.5, and by the
    product (w_i + w_j) d.d (nearly the same for equal circles) by +1.7e-14 in f64 at radius
    0.3. The bounds sit about 10 times above what the engine keeps and 5 to 14 times below
    those drifts."""
    n = 2000
    h = math.sqrt(n * math.pi * radius ** 2 / 0.3 / (16 / 9))
    sim = circles_cpu.Simulation(circles_cpu.Scene(n=n, box=(16 / 9 * h, h), radius=radius, speed=(0.5, 1.0),
                                                   precision=precision, seed=1))
    e0 = sim.stats()["kinetic_energy"]
    sim.advance(400.0)
    st = sim.stats()
    assert st["pair_collisions"] > 200 * n
    assert abs(st["kinetic_energy"] / e0 - 1) < bound


# R: stats sums in float64, also in a float32 simulation.
def test_f32_stats_energy_is_the_float64_sum_over_the_state(circles_cpu):
    sim = circles_cpu.Simulation(circles_cpu.Scene(n=1000, box=(10.0, 10.0), radius=0.02, speed=(0.5, 1.5),
                                                   mass="area", precision="f32", seed=2))
    s = sim.state()
    energy = 0.5 * np.sum(s.mass * (s.vel ** 2).sum(axis=1))
    assert sim.stats()["kinetic_energy"] == pytest.approx(energy, rel=1e-14)
