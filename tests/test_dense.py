"""Dense hard disks against published Monte Carlo pressures (circles.reference)."""

import math

import numpy as np
import pytest

from circles import observables, reference


@pytest.mark.slow
def test_the_pressure_at_224_disks_agrees_with_event_chain_monte_carlo(circles_cpu):
    """N = 224 in a square periodic box at area fraction 0.692, 30 000 time units after 1000 of
    equilibration: beta P d^2 within 3 combined standard errors of Li et al.'s 8.84651 +- 0.00055.
    The run's standard error, about 0.011, is a fifth of the shift (about 0.05) that a temperature
    blind to the conserved momentum (K / N) gives at this N, so that mistake fails here."""
    eta, n = 0.692, 224
    side = math.sqrt(n * math.pi * 0.25 / eta)
    sim = circles_cpu.Simulation(circles_cpu.Scene(n=n, box=(side, side), radius=0.5, speed=1.0, mass="equal",
                                                   boundary="periodic", seed=3))
    sim.advance(1000.0)
    values, before = [], sim.stats()
    for _ in range(30):
        sim.advance(1000.0)
        after = sim.stats()
        z = observables.interval(before, after, n, sim.box, "periodic", 0.5)["compressibility"]
        values.append(reference.reduced_pressure(z, eta))
        before = after
    mean, se = float(np.mean(values)), float(np.std(values, ddof=1) / math.sqrt(len(values)))
    (published,) = [p for p in reference.pressures("Li2022", n=224) if p.eta == eta]
    assert se < 0.02
    assert abs(mean - published.beta_p_d2) < 3 * math.hypot(se, published.se), (mean, se, published)
