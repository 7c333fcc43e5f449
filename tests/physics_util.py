"""Helpers for the physics validation tests: hard-disk theory and measurements.

Units: equal disks of diameter sigma = 2 r and mass m; kT = kinetic energy / N
(two translational degrees of freedom, kinetic energy = N kT).
"""

import math

import numpy as np

from circles.theory import contact_g, enskog_rate, liu_z  # noqa: F401 (the tests' names)


def box_for(n, r, eta):
    """Side of the square box holding n disks of radius r at area fraction eta."""
    return math.sqrt(n * math.pi * r * r / eta)


def ks_statistic(sample, cdf):
    """One-sample Kolmogorov-Smirnov statistic D = sup |F_n - F|."""
    x = np.sort(np.asarray(sample, dtype=np.float64))
    n = len(x)
    f = cdf(x)
    i = np.arange(1, n + 1)
    return float(max(np.max(i / n - f), np.max(f - (i - 1) / n)))


def ks_critical_1pct(n):
    """Asymptotic KS critical value at the 1% level: 1.63 / sqrt(n)."""
    return 1.63 / math.sqrt(n)


def rayleigh_cdf(kT, m):
    """Speed distribution of a 2D Maxwell-Boltzmann gas: F(v) = 1 - exp(-m v^2 / (2 kT))."""
    return lambda v: 1.0 - np.exp(-m * v * v / (2.0 * kT))


def measure_periodic(sim, eq_collisions_per_circle, blocks, block_time):
    """Equilibrate, then measure Z and the collision rate per circle in `blocks` blocks.

    Returns dict with Z and rate (over the whole measurement), their standard errors from
    the spread of the block values, the pair collisions counted and kT.
    """
    n = sim.n
    target = eq_collisions_per_circle * n / 2
    while sim.stats()["pair_collisions"] < target:
        sim.advance(block_time / 4)
    s0 = sim.stats()
    first = s0
    zs, rates = [], []
    for _ in range(blocks):
        sim.advance(block_time)
        s1 = sim.stats()
        t = s1["time"] - s0["time"]
        kT = s1["kinetic_energy"] / n
        zs.append(1 + (s1["virial"] - s0["virial"]) / (2 * t * n * kT))
        rates.append(2 * (s1["pair_collisions"] - s0["pair_collisions"]) / (n * t))
        s0 = s1
    t = s0["time"] - first["time"]
    kT = s0["kinetic_energy"] / n
    zs, rates = np.array(zs), np.array(rates)
    return dict(
        Z=1 + (s0["virial"] - first["virial"]) / (2 * t * n * kT),
        Z_err=float(zs.std(ddof=1) / math.sqrt(blocks)),
        rate=2 * (s0["pair_collisions"] - first["pair_collisions"]) / (n * t),
        rate_err=float(rates.std(ddof=1) / math.sqrt(blocks)),
        collisions=s0["pair_collisions"] - first["pair_collisions"],
        kT=kT,
        max_overlap=s0["max_overlap"],
    )


def two_size_mixture(precision, n=1000, n_large=20):
    """(pos, vel, radius, box): n circles of radius 0.05, the first n_large of radius 0.5, at area
    fraction 0.5 in a 1.5:1 walled box, placed in the storage precision, speeds 0.5 to 3: a
    scene with a two-level grid (simulation.LARGE_RADIUS_RATIO)."""
    from circles import placement

    rng = np.random.default_rng(3)
    radius = np.full(n, 0.05)
    radius[:n_large] = 0.5
    area = float(np.sum(np.pi * radius ** 2)) / 0.5
    box = (math.sqrt(area * 1.5), math.sqrt(area / 1.5))
    pos = placement.random_sequential(radius, box, False, 5, single=precision == "f32")
    angle = rng.uniform(0, 2 * np.pi, n)
    vel = rng.uniform(0.5, 3.0, (n, 1)) * np.stack([np.cos(angle), np.sin(angle)], axis=1)
    return pos, vel, radius, box
