"""Random non-overlapping placement, from a seed.

Every placement keeps each pair at least (r_i + r_j)(1 + CLEARANCE) apart and each circle
r (1 + CLEARANCE) inside the walls, checked on the positions as the simulation will store
them (float32 values for a float32 simulation), so the largest overlap is exactly 0. Random
numbers come from a counter-based hash of (seed, circle, draw), not from a per-thread
generator, and every sum that feeds a position is taken in a fixed order, so the result does
not depend on the thread count or on thread timing.

`place` picks the method by area fraction:

Up to `RSA_LIMIT`: parallel random sequential addition. In each round every unplaced circle
tries a few random positions against the circles already placed and proposes the first free
one; a proposal that overlaps a proposal of a lower id is dropped. Circles are placed in size
classes, largest first (radii within a factor `CLASS_RATIO` of the largest unplaced one): a
large circle needs a hole free of small ones, which a box already sprinkled with small circles
no longer has, while small circles always find room between large ones. Towards its jamming
limit (0.547 for equal disks) it needs ever more darts and rounds per circle (a minute for a
million circles at 0.5), so it stops well before.

Up to `FILL_LIMIT` (the fluid: equal hard disks freeze near 0.70), and above it when the radii
are too spread for a lattice of the largest one (that lattice would have to start shrunk and
grow back, which is slower and jams sooner; wide mixtures do not order anyway): a filled
lattice with its overlaps removed, then a few sweeps of hard-disk Monte Carlo (`fluid`). Each
circle starts uniform over FILL_BRICKS x FILL_BRICKS bricks around a site of a hexagonal
lattice of about n sites (a brick is the spacing along a row times the row spacing; the
bricks tile the plane, so the start has no Bragg peak of the lattice, while each few bricks
hold their share of circles, so density is even on large scales as in the fluid). Parallel
Jacobi passes then push overlapping pairs apart until none is left (`_relax`), each pair
towards a random distance up to RELAX_GAP past contact. Little of the lattice is left: its
Bragg peaks S(G) / N are below 1e-4 at a million circles (1 for the lattice, 1 / N for a
random placement), the bond orientations are random. The MC_FLUID_SWEEPS Monte Carlo sweeps
then bring the pairs near contact close to the fluid's (at 0.5, g(r) within 25% of its
equilibrium values up to 1.05 diameters).

Above, or when a method before gives up: a hexagonal lattice whose spacing is the largest
that fits, each site jittered by at most half the free gap, circles assigned to sites in a
random order, then MC_SOLID_SWEEPS sweeps of hard-disk Monte Carlo (`lattice_monte_carlo`).
Above the freezing point the equilibrium state is itself (quasi-)ordered and no method
forgets the lattice: the sweeps move every circle about its gap around its site (tens of
accepted moves each), the rows and their orientation stay. When the radii are too spread for
a lattice of the largest one, the lattice takes the circles shrunk by a common factor, and
they grow back between sweeps, each by at most its share of its smallest gap.

Hard-disk Monte Carlo (`hard_disk_monte_carlo`): one trial move per circle per sweep, uniform
in a square, kept when the circle overlaps nothing and stays inside the walls; this samples
the uniform distribution over non-overlapping configurations. It runs race-free in parallel
on a checkerboard: cells at least a contact distance wide in four colours (x and y parity),
one colour at a time with one thread per row of that colour's cells and the circles of a
cell one after another; a move that would leave its cell is refused, and the grid is shifted
by a random offset every sweep.

These replace the melt of a lattice with the event scheme (ten collisions per circle), which
took minutes for a million circles: overlap removal and Monte Carlo cost a few passes over
the circles each.
"""

import math

import numpy as np

from ..inputs import masses_for, random_colors
from ..scene import DENSEST_PACKING, area_fraction, check_area_fraction, rounding_margin
from .lattice import _lattice_shape, hexagonal, hexagonal_shrunk  # noqa: F401 (hexagonal: one of the methods)
from .monte_carlo import GrowthStalled, hard_disk_monte_carlo
from .relax import relaxed_fill
from .sampling import CLEARANCE
from .sequential import random_sequential

#: Area fraction up to which random sequential addition is used.
RSA_LIMIT = 0.35
#: Area fraction up to which a filled lattice with its overlaps removed is used (the fluid).
FILL_LIMIT = 0.70
#: Monte Carlo sweeps after overlap removal (relaxing the pairs it left near contact).
MC_FLUID_SWEEPS = 4
#: Monte Carlo sweeps from a jittered lattice (after the circles have grown to their radii).
MC_SOLID_SWEEPS = 60


def lattice_monte_carlo(radius: np.ndarray, box, periodic: bool, rng: np.random.Generator, single: bool = False,
                        sweeps: int = MC_SOLID_SWEEPS):
    """Positions (n, 2) in creation order: a jittered lattice (shrunk if need be), then Monte Carlo."""
    pos, order, scale = hexagonal_shrunk(radius, box, periodic, rng, single)
    target = radius[order]
    placed, _ = hard_disk_monte_carlo(pos, target * scale, target, box, periodic, rng, sweeps,
                                      _mean_gap(radius, box), single)
    out = np.empty_like(placed)
    out[order] = placed
    return out


def fluid(radius: np.ndarray, box, periodic: bool, rng: np.random.Generator, single: bool = False,
          sweeps: int = MC_FLUID_SWEEPS):
    """Positions (n, 2) in creation order: `relaxed_fill`, then Monte Carlo; None if overlaps remain."""
    filled = relaxed_fill(radius, box, periodic, rng, single)
    if filled is None:
        return None
    pos, rad, order, _ = filled
    placed, _ = hard_disk_monte_carlo(pos, rad, radius[order], box, periodic, rng, sweeps, _mean_gap(radius, box),
                                      single)
    out = np.empty_like(placed)
    out[order] = placed
    return out


def _mean_gap(radius, box):
    """The mean gap between neighbours of a hexagonal lattice at this area fraction: a first trial step."""
    fraction = area_fraction(radius, box)
    mean_r = float(radius.mean())
    gap = 2.0 * mean_r * (math.sqrt(DENSEST_PACKING / fraction) - 1.0)
    return max(gap, 1e-3 * mean_r)


def lattice_fits(radius: np.ndarray, box, periodic: bool, single: bool = False) -> bool:
    """Whether a hexagonal lattice of the largest radius holds the circles (else `hexagonal` shrinks them)."""
    rmax = float(radius.max())
    rounding = rounding_margin(box, single)
    edge = rmax * (1.0 + CLEARANCE) + rounding
    uw, uh = box if periodic else (box[0] - 2 * edge, box[1] - 2 * edge)
    spacing = _lattice_shape(radius.shape[0], uw, uh, periodic)[4]
    return spacing >= 2.0 * rmax * (1.0 + 4 * CLEARANCE) + 2.0 * rounding


def method(radius: np.ndarray, box, periodic: bool = False, single: bool = False) -> str:
    """The method `place` tries first for these circles."""
    fraction = area_fraction(radius, box)
    if fraction <= RSA_LIMIT:
        return "random sequential addition"
    if fraction <= FILL_LIMIT or not lattice_fits(radius, box, periodic, single):
        return "filled lattice, overlaps removed, Monte Carlo"
    return "jittered lattice, Monte Carlo"


def place(radius: np.ndarray, box, periodic: bool, seed: int, rng: np.random.Generator, single: bool = False):
    """Positions (n, 2) float64 in creation order (float32 values with `single`).

    Random sequential addition up to RSA_LIMIT; the filled lattice with its overlaps removed
    up to FILL_LIMIT, and above it too when the radii are too spread for a lattice of the
    largest one; else, or when the method before gives up
    (random sequential addition jams, overlaps remain after RELAX_PASSES passes), the jittered
    lattice. `seed` keys random sequential addition; the other methods draw from `rng`.
    Raises ValueError when the circles cannot be placed.
    """
    fraction = area_fraction(radius, box)
    pos = None
    try:
        if fraction <= RSA_LIMIT:
            pos = random_sequential(radius, box, periodic, seed, single=single)
        if pos is None and (fraction <= FILL_LIMIT or not lattice_fits(radius, box, periodic, single)):
            pos = fluid(radius, box, periodic, rng, single)
        if pos is None:
            pos = lattice_monte_carlo(radius, box, periodic, rng, single)
    except GrowthStalled as stalled:
        raise ValueError(_stalled_message(stalled, radius, box, periodic, single, fraction)) from None
    return pos


def largest_lattice_scale(radius: np.ndarray, box, periodic: bool, single: bool = False, lowest: float = 0.3):
    """The largest s in [lowest, 1] (to 1e-6) for which a hexagonal lattice of the largest radius
    times s holds the circles times s (`lattice_fits`), or None below `lowest`."""
    if not lattice_fits(radius * lowest, box, periodic, single):
        return None
    lo, hi = lowest, 1.0
    while hi - lo > 1e-6:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if lattice_fits(radius * mid, box, periodic, single) else (lo, mid)
    return lo


def _stalled_message(stalled, radius, box, periodic, single, fraction):
    """Why a placement stopped, with the area fraction and, when a lattice holds the circles at
    smaller radii, the area fraction it places them at."""
    w, h = box
    said = (f"cannot place {stalled.n} circles at area fraction {fraction:.4f} in a {w} x {h} box with "
            f"{'a periodic boundary' if periodic else 'walls'}: Monte Carlo could not grow {stalled.short} of "
            "them to their radii from a start at smaller radii (too close to jamming for these radii)")
    scale = largest_lattice_scale(radius, box, periodic, single)
    if scale is None:
        return said + "; use fewer or smaller circles, a narrower spread of radii, or a bigger box"
    reach = fraction * scale * scale
    return (said + f"; a hexagonal lattice of the largest radius holds them with every radius {scale:.6f} times "
            f"its own (area fraction {reach:.4f}), which places: use radii at most that many times these, fewer "
            "circles or a bigger box")


def scene_circles(scene):
    """(pos, vel, radius, mass, color) of the circles of `scene`: radii, speeds, directions and
    colours drawn from its seed, masses from its mass model, places at random without overlap
    (`place`), or on the perfect crystal for a crystal start; the area fraction is checked
    before any is placed."""
    rng = np.random.default_rng(scene.seed)
    n = scene.n
    vlo, vhi = scene.speed
    radius = scene.radii(rng)
    speed = rng.uniform(vlo, vhi, n) if vhi > vlo else np.full(n, vlo)
    angle = rng.uniform(0.0, 2.0 * np.pi, n)
    vel = np.stack([speed * np.cos(angle), speed * np.sin(angle)], axis=1)
    color = random_colors(n, rng)
    mass = masses_for(scene.mass, radius, scene.precision)
    fraction = area_fraction(radius, scene.box)
    check_area_fraction(fraction, n, scene.box)
    periodic = scene.boundary == "periodic"
    if scene.start == "crystal":
        from .lattice import crystal_positions
        pos = crystal_positions(*scene.crystal, scene.box)
    elif scene.start == "compressed":
        pos, vel, radius = compressed(radius, vel, mass, scene, rng)
    else:
        pos = place(radius, scene.box, periodic, scene.seed, rng, single=scene.precision == "f32")
    return pos, vel, radius, mass, color


def compressed(radius, vel, mass, scene, rng):
    """(pos, vel, radius) of a compressed start: the circles placed at random at half the area
    fraction (radii over sqrt 2), then grown at `compress.RATE` to their radii while they
    collide. Above freezing this is the fluid side: placement there keeps the lattice's rows.
    The radii come back within round-off of the scene's, trimmed so that no pair overlaps."""
    from ..backend import ensure_init
    from ..compress import RATE, grow

    ensure_init()  # the growth engine's kernels
    periodic = scene.boundary == "periodic"
    half = radius / math.sqrt(2.0)
    pos = place(half, scene.box, periodic, scene.seed, rng)
    target = area_fraction(radius, scene.box)
    pos, vel, grown, done = grow(pos, vel, half, mass, scene.box, scene.boundary, target, RATE)
    if done.stopped != "target":
        raise ValueError(f"start = 'compressed': the circles jammed at area fraction {done.area_fraction:.4f}, short "
                         f"of {target:.4f}; give a smaller area_fraction, or start = 'fluid' or 'crystal'")
    return pos, vel, grown
