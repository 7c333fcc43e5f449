"""The observables and trajectories against physics, not only against ourselves.

- The pressure two independent ways: the virial of the collisions (stats rows) and freud's
  RDF of the GSD frames extrapolated to contact, Z = 1 + 2 eta g(sigma+), at eta = 0.45.
- The wall pressure against the virial pressure in a walled box.
- The mean squared displacement from the image flags against Enskog's diffusion coefficient
  (Gass 1971, see circles.analysis).

Errors are standard errors of the mean over frames or intervals one time unit apart (about
four collisions a disk at eta = 0.45: close to independent); agreement is asserted within
4 standard errors plus the RDF extrapolation's bias bound (0.5% of g, `analysis.contact_values`).
"""

import math

import gsd.hoomd
import numpy as np
import pytest

from circles import analysis
from circles.trajectory import GSDWriter, ImageTracker
from circles.writers import Run, StatsWriter, read_stats


def bulk_run(circles, tmp_path, n, eta, frames, equilibrate, seed=1):
    radius = 0.5
    side = math.sqrt(n * math.pi * radius ** 2 / eta)
    sim = circles.Simulation(circles.Scene(n=n, box=(side, side), radius=radius, speed=(1.0, 1.0), mass="equal",
                                           boundary="periodic", seed=seed))
    sim.advance(equilibrate)
    path, table = tmp_path / "bulk.gsd", tmp_path / "bulk.csv"
    with GSDWriter(path, tracker=ImageTracker(sim)) as trajectory, StatsWriter(table) as rows:
        for _ in Run(sim, float(frames), 1.0, at_frame=[trajectory], at_interval=[rows]):
            pass
    with gsd.hoomd.open(str(path)) as traj:
        snaps = list(traj)
    return sim, read_stats(table), snaps, n / side ** 2


def check_pressure_two_ways(rows, snaps, eta):
    z_virial, z_virial_err = analysis.mean_error(rows["compressibility"])
    g, g_err = analysis.mean_error(analysis.contact_values(snaps, 1.0))
    z_rdf, z_rdf_err = 1 + 2 * eta * g, 2 * eta * g_err
    bias = 2 * eta * 0.005 * g
    assert abs(z_rdf - z_virial) < 4 * math.hypot(z_rdf_err, z_virial_err) + bias, (z_rdf, z_virial)
    # Both near Henderson's equation of state (a reference within about 1% here).
    assert z_virial == pytest.approx(analysis.henderson_compressibility(eta), rel=0.03)
    return g


def test_pressure_two_ways_small(circles_cpu, tmp_path):
    """N = 400 at eta = 0.45 over 12 frames: the same check with errors about three times those of
    the slow test's, so it tells a wrong Z (a factor of the virial) apart. The pressure's area is
    checked by P = Z N kT / A with A the periodic box's area, worked out here from the density."""
    _, rows, snaps, density = bulk_run(circles_cpu, tmp_path, 400, 0.45, 12, 5.0)
    check_pressure_two_ways(rows, snaps, 0.45)
    np.testing.assert_allclose(rows["pressure"], rows["compressibility"] * density * rows["temperature"], rtol=1e-12)


@pytest.mark.slow
def test_pressure_two_ways_and_diffusion(circles_cpu, tmp_path):
    """N = 4000 at eta = 0.45, 40 frames one time unit apart after 20 of equilibration."""
    eta = 0.45
    sim, rows, snaps, density = bulk_run(circles_cpu, tmp_path, 4000, eta, 40, 20.0)
    g = check_pressure_two_ways(rows, snaps, eta)
    kT, mass = float(np.mean(rows["temperature"])), float(sim.state().mass[0])
    # The collision rate against Enskog's, with the measured g(sigma+).
    rate = float(np.mean(rows["collision_rate"]))
    assert rate == pytest.approx(analysis.enskog_collision_rate(density, 1.0, g, kT, mass), rel=0.05)
    # MSD: grows about linearly after a few mean free times (1 / rate, about 0.26 here), with a
    # slope of the order of 4 D_E: the 2D long-time tail and collective motion make D / D_E a
    # number near one that creeps up with time, so it is asserted within a factor of two.
    lags, msd = analysis.squared_displacements(snaps)
    slopes = np.diff(msd)[4:20]  # lags from 5 to 20 time units: 20 to 80 mean free times
    assert np.all(slopes > 0)
    assert slopes.max() / slopes.min() < 1.5  # about linear
    d_ratio = np.mean(slopes) / 4 / analysis.enskog_diffusion(density, 1.0, g, kT, mass)
    assert 0.5 < d_ratio < 2.0, d_ratio


@pytest.mark.slow
def test_wall_pressure_equals_the_virial_pressure(circles_cpu):
    """A walled box at area fraction 0.3 of the area open to the centres: over 40 intervals of one
    time unit, the wall's pressure and the virial's agree within 4 standard errors of their
    interval-by-interval difference."""
    n, radius, eta = 1000, 0.5, 0.3
    side = math.sqrt(n * math.pi * radius ** 2 / eta) + 2 * radius
    sim = circles_cpu.Simulation(circles_cpu.Scene(n=n, box=(side, side), radius=radius, speed=(1.0, 1.0),
                                                   mass="equal", boundary="walls", seed=2))
    sim.advance(20.0)
    rows = []

    class Rows:
        def write(self, row):
            rows.append(row)

    for _ in Run(sim, 40.0, 1.0, at_interval=[Rows()]):
        pass
    wall = np.array([row["wall_pressure"] for row in rows])
    virial = np.array([row["pressure"] for row in rows])
    difference, error = analysis.mean_error(wall - virial)
    assert abs(difference) < 4 * error, (difference, error)
    assert error < 0.05 * virial.mean()  # a test that can tell a pressure 20% off
