"""Measurements on trajectories (`circles.trajectory` GSD frames): the pair distribution at
contact (with freud, from the ``test`` extra), mean squared displacements from image flags, and
the kinetic theory they are compared with. Used by the validation tests and by
``bench/data_validation.py``.

Hard disks of diameter sigma at number density n = N / A, area fraction eta = n pi sigma^2 / 4,
kT the kinetic energy per disk (two degrees of freedom), mass m:

- pressure from the pair distribution at contact (the virial theorem for hard disks):
  ``Z = P A / (N kT) = 1 + 2 eta g(sigma+)``;
- Enskog's collision frequency and self-diffusion coefficient (`circles.theory`). In two
  dimensions the velocity autocorrelation's long-time tail (Alder and Wainwright, Phys. Rev.
  A 1, 18 (1970)) makes the measured D drift up slowly with time, so the ratio D / D_E is a
  number near one, not a constant.
"""
import math

import numpy as np

from .theory import enskog_collision_rate, enskog_diffusion, henderson_compressibility  # noqa: F401


def mean_error(values):
    """(mean, standard error of the mean) of samples taken as independent."""
    values = np.asarray(values, np.float64)
    if len(values) < 2:
        return float(values.mean()), math.nan
    return float(values.mean()), float(values.std(ddof=1) / math.sqrt(len(values)))


def contact_values(frames, sigma, width=0.02, bins=6):
    """g(sigma+) of each gsd.hoomd frame (a periodic box of disks of one diameter sigma), from
    freud's radial distribution function: `bins` bins of `width` sigma from r = sigma, a
    straight line through ln g(r) at their centres, extrapolated to r = sigma. A line in ln g
    follows the steep fall of g near contact to second order in the bin width; with width 0.02
    and 6 bins its bias is below 0.5% at eta = 0.45 (measured against bins half as wide)."""
    import freud

    rdf = freud.density.RDF(bins=bins, r_max=sigma * (1 + bins * width), r_min=sigma)
    values = []
    for frame in frames:
        box = freud.box.Box.from_box(frame.configuration.box[:2], dimensions=2)
        points = np.asarray(frame.particles.position, np.float32)
        rdf.compute(system=(box, points), reset=True)
        r, g = rdf.bin_centers, rdf.rdf
        slope, intercept = np.polyfit(r - sigma, np.log(g), 1)
        values.append(math.exp(intercept))
    return np.array(values)


def squared_displacements(frames, origins=None):
    """Mean squared displacement of the disks between frames, from unwrapped positions
    (`trajectory.unwrapped`): (lags in frames, MSD per lag averaged over time origins)."""
    from .trajectory import unwrapped

    positions = np.stack([unwrapped(frame) for frame in frames])
    count = len(positions)
    lags = np.arange(1, count)
    msd = np.array([np.mean(np.sum((positions[lag:] - positions[:-lag]) ** 2, axis=2)) for lag in lags])
    return lags, msd
