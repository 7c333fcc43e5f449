"""Hard-disk theory to set measurements beside: the equation of state and the collision rate.

Units: equal disks of diameter sigma = 2 r and mass m at area fraction eta (packing
fraction), number density rho = N / A; kT = kinetic energy / N (two translational degrees
of freedom).
"""

import math


def liu_z(eta):
    """Compressibility factor Z = P A / (N kT) of the hard-disk fluid, Liu's fit (accurate to
    about 0.1% in the fluid): Z = (1 + eta^2/8 + eta^3/18 - 4 eta^4/21) / (1 - eta)^2."""
    return (1 + eta ** 2 / 8 + eta ** 3 / 18 - 4 * eta ** 4 / 21) / (1 - eta) ** 2


def contact_g(eta):
    """Radial distribution at contact from the virial route: Z = 1 + 2 eta g(sigma)."""
    return (liu_z(eta) - 1) / (2 * eta)


def enskog_rate(eta, rho, sigma, kT, m):
    """Enskog's collision frequency, collisions per circle per unit time:
    omega = 2 rho sigma g(sigma) sqrt(pi kT / m)."""
    return 2 * rho * sigma * contact_g(eta) * math.sqrt(math.pi * kT / m)
