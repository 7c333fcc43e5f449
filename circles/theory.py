"""Hard-disk theory to set measurements beside: the equation of state, the collision rate and
self-diffusion.

Units: equal disks of diameter sigma = 2 r and mass m at area fraction eta (packing
fraction), number density rho = N / A; kT per degree of freedom that takes heat
(`circles.observables.temperature`).
"""

import math


def liu_z(eta):
    """Compressibility factor Z = P A / (N kT) of the hard-disk fluid, Liu's fit:
    Z = (1 + eta^2/8 + eta^3/18 - 4 eta^4/21) / (1 - eta)^2. A reference to about 0.1% up to
    eta = 0.6; 1.5% above the event-chain data at 0.67 (`circles.reference`), and no reference
    in the dense fluid and through melting, where `circles.reference` holds published data."""
    return (1 + eta ** 2 / 8 + eta ** 3 / 18 - 4 * eta ** 4 / 21) / (1 - eta) ** 2


def contact_g(eta):
    """Radial distribution at contact from the virial route: Z = 1 + 2 eta g(sigma)."""
    return (liu_z(eta) - 1) / (2 * eta)


def henderson_compressibility(eta):
    """Henderson's equation of state for hard disks, Z = (1 + eta^2 / 8) / (1 - eta)^2 (Mol.
    Phys. 30, 971 (1975)): within about 1% of simulations up to eta = 0.6, a reference only."""
    return (1.0 + eta * eta / 8.0) / (1.0 - eta) ** 2


def enskog_collision_rate(rho, sigma, contact, kT, m):
    """Enskog's collision frequency, collisions a circle takes part in per unit time, at the
    contact value g(sigma+) given: omega_E = 2 rho sigma g(sigma+) sqrt(pi kT / m)."""
    return 2.0 * rho * sigma * contact * math.sqrt(math.pi * kT / m)


def enskog_rate(eta, rho, sigma, kT, m):
    """Enskog's collision frequency with the contact value of Liu's equation of state."""
    return enskog_collision_rate(rho, sigma, contact_g(eta), kT, m)


def enskog_diffusion(rho, sigma, contact, kT, m):
    """Enskog's self-diffusion coefficient of hard disks, the first Chapman-Enskog
    approximation with Enskog's factor 1 / g(sigma+) (D. M. Gass, J. Chem. Phys. 54, 1898
    (1971)): D_E = sqrt(kT / (pi m)) / (2 rho sigma g(sigma+))."""
    return math.sqrt(kT / (math.pi * m)) / (2.0 * rho * sigma * contact)
