"""Published pressures of equal hard disks in a periodic box near melting, as reference data.

The table (`data/hard_disk_pressures.csv`, shipped with the package) holds the reduced pressure
beta P d^2 (d the diameter) and its standard error at area fractions 0.670 to 0.722, where the
fluid turns hexatic through a first-order transition (a Mayer-Wood loop in the pressure between
about 0.700 and 0.716 at large N, deeper at small N). Its columns: source, method,
pressure_estimator, n, aspect (width over height: a number or an expression in sqrt), eta,
beta_p_d2, se.

Sources (data as the authors published them, collected in the HistoricDisks repository,
github.com/jellyfysh/HistoricDisks, folder DigitizedData):

- Li2022: B. Li, Y. Nishikawa, P. Hoellmer, L. Carillo, A. C. Maggs, W. Krauth, "Hard-disk
  pressure computations - a historic perspective", J. Chem. Phys. 157, 234111 (2022).
  Event-chain Monte Carlo, N = 224 in a square box and N = 870 in a box of 29 : 30 sqrt(3)/2.
- Engel2013: M. Engel, J. A. Anderson, S. C. Glotzer, M. Isobe, E. P. Bernard, W. Krauth,
  "Hard-disk equation of state: first-order liquid-hexatic transition in two dimensions with
  three simulation methods", Phys. Rev. E 87, 042134 (2013). Massively parallel Monte Carlo
  and event-driven molecular dynamics, N = 256^2 to 1024^2, square boxes.

Where each reference holds: Liu's fit (`theory.liu_z`) to about 0.1% up to area fraction 0.6,
and 1.5% high at 0.67 against these data (8.10 against 7.987 at N = 870); these data from 0.67
to 0.72. Monte Carlo has no momentum: compare it with circles' pressure in a periodic box,
whose temperature counts the conserved momentum (`observables.temperature`).
"""
from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from importlib import resources

#: The aspect of a box that a triangular crystal of 29 columns and 30 rows fits (Li et al.'s N = 870).
ASPECT_29_30 = 29 / (30 * math.sqrt(3) / 2)


@dataclass(frozen=True)
class Pressure:
    """One published point: beta P d^2 and its standard error at area fraction eta."""

    source: str
    method: str
    estimator: str
    n: int
    aspect: float
    eta: float
    beta_p_d2: float
    se: float


def _aspect(text):
    """A box's aspect as the table writes it: a number, or 29/(30*sqrt(3)/2)."""
    text = text.strip()
    if text == "29/(30*sqrt(3)/2)":
        return ASPECT_29_30
    return float(text)


def pressures(source=None, method=None, n=None) -> list[Pressure]:
    """The published points, optionally only those of a source ("Li2022", "Engel2013"), a
    method ("ECMC", "MPMC", "EDMD") and a number of disks, in the table's order."""
    with resources.files(__package__).joinpath("data/hard_disk_pressures.csv").open(newline="") as file:
        rows = [Pressure(r["source"], r["method"], r["pressure_estimator"], int(r["n"]), _aspect(r["aspect"]),
                         float(r["eta"]), float(r["beta_p_d2"]), float(r["se"])) for r in csv.DictReader(file)]
    return [p for p in rows if (source is None or p.source == source) and (method is None or p.method == method)
            and (n is None or p.n == n)]


def reduced_pressure(z, eta):
    """beta P d^2 of equal disks from the compressibility factor Z = P A / (N kT) at area
    fraction eta: beta P d^2 = Z rho d^2 = 4 eta Z / pi."""
    return 4.0 * eta * z / math.pi


def series(n, aspect):
    """The published points of N = n disks in a box of this aspect (width over height, to 1e-9),
    sorted by area fraction: what a run of that N and box shape is compared with."""
    found = [p for p in pressures(n=n) if math.isclose(p.aspect, aspect, rel_tol=1e-9)]
    return sorted(found, key=lambda p: (p.eta, p.source, p.method))
