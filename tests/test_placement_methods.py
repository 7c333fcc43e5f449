"""The placement methods one by one: random sequential addition (low density), the filled
lattice with its overlaps removed (the fluid), the jittered lattice with Monte Carlo (above
freezing), and the hard-disk Monte Carlo itself.

Tolerances:
- No overlap at all: every pair distance, computed in float64 from the positions as the
  simulation stores them (float32 values in a float32 simulation), is at least the sum of
  the radii, and every circle is inside the walls, with no tolerance. Placement keeps a
  clearance of 1e-6 of the contact distance and checks it after rounding, so an exact
  comparison is the claim.
- Lattice memory in the fluid: S(G) = |sum_j exp(i G.x_j)|^2 / N at the first reciprocal
  vectors G of the hexagonal lattice the start was built on is about 1 for a random
  placement (exponentially distributed with mean 1: above 40 with probability e^-40) and
  0.8 N on the jittered lattice; the bound 40 fails for any memory above 40 / N (0.01 at
  N = 4000; 3e-5 of N is measured at N = 1e6). The global bond order |<psi_6>| is about
  N^-1/2 / 2 ~ 0.01 when the orientations are random and above 0.5 on the jittered
  lattice: bound 0.1.
- Above freezing the lattice stays (no method forgets it); the Monte Carlo must still move
  every circle about its gap: rms displacement from the start above 0.5 of the lattice gap
  (about 1 is measured; a run that moves nothing gives 0), and the lattice's S(G) / N falls
  below 0.95 (0.99 at the start, about 0.75 after the sweeps).
"""

import math

import numpy as np
import pytest

from reference import outside_walls, pair_overlap


def box_for(n, radius, fraction, aspect=16 / 9):
    rlo, rhi = (radius, radius) if np.isscalar(radius) else radius
    mean_area = math.pi * (rlo * rlo + rlo * rhi + rhi * rhi) / 3
    area = n * mean_area / fraction
    return (math.sqrt(area * aspect), math.sqrt(area / aspect))


def no_overlap(pos, radius, box, periodic):
    """(worst relative overlap, worst wall crossing): both must be <= 0 exactly."""
    worst = pair_overlap(pos, radius, box if periodic else None)
    wall = -1.0 if periodic else outside_walls(pos, radius, box)
    return worst, wall


def lattice_vectors(placement, n, radius, box, periodic, single):
    """The first reciprocal vectors of the lattice `hexagonal` builds for this scene."""
    rmax = float(np.max(radius))
    edge = rmax * (1.0 + placement.CLEARANCE) + placement.rounding_margin(box, single)
    uw, uh = box if periodic else (box[0] - 2 * edge, box[1] - 2 * edge)
    _, _, ax, ay, _ = placement._lattice_shape(n, uw, uh, periodic)
    return [np.array([0.0, 2 * np.pi / ay]), np.array([2 * np.pi / ax, np.pi / ay]),
            np.array([2 * np.pi / ax, -np.pi / ay])]


def structure_factor(pos, g):
    return float(abs(np.exp(1j * (pos @ g)).sum()) ** 2 / len(pos))


def bond_order(pos, cut):
    """|<psi_6>|: the mean over circles of their neighbours' exp(6 i theta), averaged, in modulus."""
    n = len(pos)
    total = 0j
    for start in range(0, n, 500):
        d = pos[None, :, :] - pos[start:start + 500, None, :]
        r2 = np.sum(d * d, axis=-1)
        near = (r2 > 0) & (r2 < cut * cut)
        phase = np.where(near, np.exp(6j * np.arctan2(d[..., 1], d[..., 0])), 0)
        total += np.sum(phase.sum(axis=1) / np.maximum(near.sum(axis=1), 1))
    return abs(total / n)


@pytest.mark.parametrize("fraction", [0.3, 0.5, 0.8])
@pytest.mark.parametrize("precision", ["f32", "f64"])
def test_no_overlap_exactly(circles_cpu, fraction, precision):
    """One scene per method, both precisions: distances >= sums of radii, inside the walls, exactly;
    the float32 positions are float32 values; stats() agrees (largest overlap 0)."""
    n, r = 3000, 0.5
    box = box_for(n, r, fraction)
    sim = circles_cpu.Simulation(circles_cpu.Scene(n=n, box=box, radius=r, speed=(0.5, 1.0), scheme="discrete",
                                                   precision=precision, seed=11))
    s = sim.state()
    worst, wall = no_overlap(s.pos, s.radius, box, False)
    assert worst <= 0.0, f"pairs overlap by up to {worst:.3g} of the contact distance"
    assert wall <= 0.0, f"a circle crosses a wall by {wall:.3g} of its radius"
    assert sim.stats()["max_overlap"] == 0.0
    if precision == "f32":
        assert np.array_equal(s.pos, s.pos.astype(np.float32).astype(np.float64))


@pytest.mark.parametrize("periodic", [False, True], ids=["walls", "periodic"])
def test_spread_radii_no_overlap_float32(circles_cpu, periodic):
    """Radii spread 1:3, float32, in the fluid (0.6) and above freezing (0.8, circles start
    shrunk and grow back): no overlap, exactly, with the float64 radii."""
    from circles import placement

    for fraction in (0.6, 0.8):
        n, radius = 1500, (0.005, 0.015)
        box = box_for(n, radius, fraction)
        rng = np.random.default_rng(5)
        rad = rng.uniform(*radius, n)
        pos = placement.place(rad, box, periodic, 5, rng, single=True)
        worst, wall = no_overlap(pos, rad, box, periodic)
        assert worst <= 0.0 and wall <= 0.0, (fraction, worst, wall)
        assert np.array_equal(pos, pos.astype(np.float32).astype(np.float64))
        if periodic:
            assert np.all((pos >= 0.0) & (pos < np.array(box)))


@pytest.mark.parametrize("periodic", [False, True], ids=["walls", "periodic"])
def test_fluid_forgets_the_lattice(circles_cpu, periodic):
    """At 0.5 the placement keeps no Bragg peak and no bond orientation of the lattice its
    start was built on (see the module docstring for the bounds); the jittered lattice
    itself, as a control, fails both."""
    from circles import placement

    n, r, fraction = 4000, 0.5, 0.5
    box = box_for(n, r, fraction)
    radius = np.full(n, r)
    pos = placement.place(radius, box, periodic, 2, np.random.default_rng(2))
    gs = lattice_vectors(placement, n, radius, box, periodic, False)
    peaks = [structure_factor(pos, g) for g in gs]
    spacing = math.sqrt(2 * box[0] * box[1] / (math.sqrt(3) * n))
    psi6 = bond_order(pos, 1.35 * spacing)
    assert max(peaks) < 40, f"Bragg peaks of the lattice: {peaks}"
    assert psi6 < 0.1, f"bond order {psi6:.3f}"

    start, _ = placement.hexagonal(radius, box, periodic, np.random.default_rng(2))
    assert max(structure_factor(start, g) for g in gs) > 0.5 * n
    assert bond_order(start, 1.35 * spacing) > 0.5


def test_monte_carlo_moves_circles_above_freezing(circles_cpu):
    """At 0.8, from the jittered lattice: the sweeps move each circle about its gap (rms
    displacement > 0.5 gap) and shrink the lattice's Bragg peaks (S(G) / N < 0.95), keep
    every gap, and give the same result from the same seed."""
    from circles import placement

    n, r, fraction = 3000, 0.5, 0.8
    box = box_for(n, r, fraction)
    radius = np.full(n, r)
    start, order = placement.hexagonal(radius, box, False, np.random.default_rng(4))
    gap = math.sqrt(placement.DENSEST_PACKING / fraction) - 1.0  # in diameters (here 1)

    def run():
        return placement.hard_disk_monte_carlo(start, radius, radius, box, False, np.random.default_rng(9),
                                               placement.MC_SOLID_SWEEPS, gap)

    end, sweeps = run()
    assert sweeps == placement.MC_SOLID_SWEEPS
    rms = math.sqrt(np.mean(np.sum((end - start) ** 2, axis=1)))
    assert rms > 0.5 * gap, f"rms displacement {rms:.4f}, gap {gap:.4f}"
    gs = lattice_vectors(placement, n, radius, box, False, False)
    before = max(structure_factor(start, g) for g in gs) / n
    after = max(structure_factor(end, g) for g in gs) / n
    assert before > 0.98 and after < 0.95, (before, after)
    worst, wall = no_overlap(end, radius, box, False)
    assert worst <= 0.0 and wall <= 0.0
    again, _ = run()
    assert np.array_equal(end, again)


def test_monte_carlo_grows_shrunk_circles(circles_cpu):
    """Circles started at 0.7 of their radii on a jittered lattice grow back to them between
    sweeps (1:3 radii at area fraction 0.75, a periodic box), never overlapping."""
    from circles import placement

    n = 800
    rng = np.random.default_rng(6)
    radius = rng.uniform(0.005, 0.015, n)
    box = box_for(n, (0.005, 0.015), 0.75, aspect=1.0)
    start, order, scale = placement.hexagonal_shrunk(radius, box, True, rng)
    assert scale < 0.8  # a lattice of the largest radius does not fit: they must grow
    target = radius[order]
    end, sweeps = placement.hard_disk_monte_carlo(start, target * scale, target, box, True, rng, 5, 0.001)
    assert sweeps > 5
    worst, _ = no_overlap(end, target, box, True)
    assert worst <= 0.0


def test_overlap_removal_gives_up_and_placement_goes_on(circles_cpu):
    """relaxed_fill returns None when its passes run out; place() then uses the jittered
    lattice (the scene is still placed, without overlap)."""
    from circles import placement

    n, r = 1000, 0.5
    box = box_for(n, r, 0.6)
    radius = np.full(n, r)
    assert placement.relaxed_fill(radius, box, False, np.random.default_rng(3), max_passes=1) is None
    pos = placement.lattice_monte_carlo(radius, box, False, np.random.default_rng(3), sweeps=3)
    worst, wall = no_overlap(pos, radius, box, False)
    assert worst <= 0.0 and wall <= 0.0


@pytest.mark.parametrize("fraction", [0.5, 0.8])
def test_same_seed_same_placement_other_seed_differs(circles_cpu, fraction):
    def placed(seed):
        n = 1000
        return circles_cpu.Simulation(circles_cpu.Scene(n=n, box=box_for(n, 0.5, fraction), radius=0.5,
                                                        seed=seed)).state().pos
    a, b, c = placed(8), placed(8), placed(9)
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)


def test_method_by_area_fraction_and_spread():
    """Equal radii: random sequential addition at 0.3, the filled lattice at 0.5, the jittered
    lattice at 0.8; radii spread 1:3 at 0.8 (no lattice of the largest fits): the filled lattice."""
    from circles import placement

    n = 1000
    equal = np.full(n, 0.5)
    assert placement.method(equal, box_for(n, 0.5, 0.3)) == "random sequential addition"
    assert placement.method(equal, box_for(n, 0.5, 0.5)).startswith("filled lattice")
    assert placement.method(equal, box_for(n, 0.5, 0.8)).startswith("jittered lattice")
    spread = np.random.default_rng(1).uniform(0.005, 0.015, n)
    box = box_for(n, (0.005, 0.015), 0.8)
    assert not placement.lattice_fits(spread, box, False)
    assert placement.method(spread, box).startswith("filled lattice")


def test_a_spread_no_lattice_holds_is_refused_with_its_own_radii():
    """Two circles of radius 25 among 198 of radius 0.5 at area fraction 0.6: no lattice of the
    largest radius holds 200 sites, even shrunk to 0.3. The refusal names the radii and the
    area fraction given (it named the shrunk ones: radius up to 7.4, area fraction 0.053)."""
    from circles import placement

    radius = np.full(200, 0.5)
    radius[:2] = 25.0
    side = math.sqrt(float(np.sum(np.pi * radius ** 2)) / 0.6)
    with pytest.raises(ValueError, match=r"cannot place 200 circles of radius up to 25\.0 .* \(area fraction "
                                         r"0\.6000\).*narrower spread"):
        placement.hexagonal_shrunk(radius, (side, side), False, np.random.default_rng(0))
