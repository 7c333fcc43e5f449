"""Observables of a run, from the totals that `Simulation.stats` keeps.

Units: Boltzmann's constant is 1, and lengths, times and masses are the scene's own.

Temperature counts the degrees of freedom that exchange energy (`temperature`). Walls exchange
momentum with the circles: each circle has two translational degrees of freedom, and
``kT = K / N`` with K the kinetic energy. A periodic box conserves the total momentum P: the
centre of mass carries ``|P|^2 / (2 M)`` (M the total mass) that never becomes heat, and 2 of
the 2N degrees of freedom are frozen, so ``kT = (K - |P|^2 / (2 M)) / (N - 1)``. The
difference is of order 1/N: at N = 224 it moves the reduced pressure of a dense fluid by
several standard errors of a long run, and it is what a comparison with Monte Carlo (which has
no momentum) needs.

Pressure comes two ways:

- the virial, from the pair collisions: in 2D, over a time t,
  ``P A = N kT + virial / (2 t)``, where virial is the sum over pair collisions of
  ``(r_i + r_j) |J|`` (J the impulse). The compressibility factor is
  ``Z = P A / (N kT) = 1 + virial / (2 t N kT)``. In a walled box the wall's own virial
  closes the identity with A the area open to the centres, ``(W - 2r)(H - 2r)``; in a
  periodic box A is the box's area;
- the walls, in a walled box: ``P = wall_impulse / (t L)``, with wall_impulse the sum over
  wall hits of ``2 m |v_n|`` and L the perimeter open to the centres,
  ``2 (W - 2r) + 2 (H - 2r)``.

The reduced pressure of equal disks of diameter d is ``beta P d^2 = P d^2 / kT`` (from the
virial pressure), the number the literature on hard disks gives; NaN for circles of several
radii.

Both pressures are exact identities for circles of one radius r; with several radii the walled box's
areas use the mean radius, an approximation. Over a time of zero (at t = 0) the pressures
are not defined and are NaN.
"""
from __future__ import annotations

import math

import numpy as np

#: The columns of a stats table (`interval`), in order.
COLUMNS = ("time", "kinetic_energy", "temperature", "momentum_x", "momentum_y", "pair_collisions",
           "wall_collisions", "collision_rate", "pressure", "compressibility", "reduced_pressure", "wall_pressure",
           "max_overlap")


def centre_box(box, boundary, radius):
    """(width, height) of the region the circles' centres move in: the box itself when it is
    periodic, the box less a radius at each wall (`radius`: the mean radius) when walled."""
    w, h = float(box[0]), float(box[1])
    if boundary == "periodic":
        return w, h
    return w - 2.0 * radius, h - 2.0 * radius


def temperature(kinetic_energy, momentum, total_mass, n, boundary):
    """kT from the kinetic energy: K / N in a walled box; in a periodic box, whose total momentum
    is conserved, the kinetic energy in the centre-of-mass frame over N - 1 (NaN for a single
    circle, which has no thermal motion there)."""
    if boundary != "periodic":
        return kinetic_energy / n
    if n < 2:
        return math.nan
    px, py = momentum
    return (kinetic_energy - (px * px + py * py) / (2.0 * total_mass)) / (n - 1)


def equal_diameter(radius):
    """The circles' common diameter, or None when their radii differ."""
    radius = np.asarray(radius)
    return float(2.0 * radius[0]) if radius.size and np.all(radius == radius[0]) else None


def pressures(duration, virial, wall_impulse, kT, n, box, boundary, radius, diameter=None):
    """{pressure, compressibility, reduced_pressure, wall_pressure} over `duration` of simulated
    time, from the growth of the virial and of the wall impulse over it, at the temperature kT
    given (`temperature`). reduced_pressure needs the `diameter` of equal disks (NaN without);
    wall_pressure is NaN in a periodic box; every value is NaN over a duration of 0."""
    w, h = centre_box(box, boundary, radius)
    if duration > 0 and kT > 0:
        z = 1.0 + virial / (2.0 * duration * n * kT)
        p = z * n * kT / (w * h)
    else:
        z = p = math.nan
    if boundary == "periodic" or not duration > 0:
        wall = math.nan
    else:
        wall = wall_impulse / (duration * 2.0 * (w + h))
    reduced = p * diameter * diameter / kT if diameter is not None and math.isfinite(p) else math.nan
    return {"pressure": p, "compressibility": z, "reduced_pressure": reduced, "wall_pressure": wall}


def since_start(stats, n, box, boundary, radius, diameter=None):
    """The pressures averaged from time 0 to `stats["time"]` (see `pressures`), at the
    temperature of `stats`."""
    return pressures(stats["time"], stats["virial"], stats["wall_impulse"], stats["temperature"], n, box,
                     boundary, radius, diameter)


def interval(before, after, n, box, boundary, radius, diameter=None):
    """A row of the stats table (`COLUMNS`) for the interval between two `stats()` taken by one
    simulation: the state at its end, the collision counts since the start, and the rates and
    pressures over the interval, at the temperature of its end. collision_rate is the
    collisions a circle takes part in per unit time, 2 pair collisions / (N t): the collision
    frequency of kinetic theory (Enskog's)."""
    duration = after["time"] - before["time"]
    pairs = after["pair_collisions"] - before["pair_collisions"]
    row = {
        "time": after["time"],
        "kinetic_energy": after["kinetic_energy"],
        "temperature": after["temperature"],
        "momentum_x": after["momentum"][0],
        "momentum_y": after["momentum"][1],
        "pair_collisions": after["pair_collisions"],
        "wall_collisions": after["wall_collisions"],
        "collision_rate": 2.0 * pairs / (n * duration) if duration > 0 else math.nan,
        **pressures(duration, after["virial"] - before["virial"], after["wall_impulse"] - before["wall_impulse"],
                    after["temperature"], n, box, boundary, radius, diameter),
        "max_overlap": after["max_overlap"],
    }
    return {name: row[name] for name in COLUMNS}
