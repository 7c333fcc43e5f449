"""Scene: the static description of a run (what is simulated, not how far it has got).

Every field is checked when the Scene is made, so a bad value fails before any work with a
message that names the value, the limit and the fix.
"""
from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, fields, asdict
from numbers import Integral, Real

import numpy as np

MASS_MODELS = ("radius", "area", "equal")
STARTS = ("fluid", "crystal", "compressed")
BOUNDARIES = ("walls", "periodic")
SCHEMES = ("event", "discrete")
PRECISIONS = ("f32", "f64")

#: Densest packing of equal disks in the plane (hexagonal), pi / sqrt(12).
DENSEST_PACKING = math.pi / math.sqrt(12.0)


def scalar(x):
    """A 0-d numpy array of numbers (not of bools) as its number; anything else as it is."""
    if isinstance(x, np.ndarray) and x.ndim == 0 and np.issubdtype(x.dtype, np.number):
        return x.item()
    return x


def _finite(name, value):
    value = scalar(value)
    if isinstance(value, bool) or not isinstance(value, Real):
        raise ValueError(f"{name} = {value!r} is not a number")
    if not math.isfinite(float(value)):
        raise ValueError(f"{name} = {value!r} is not finite: give a finite number")
    return float(value)


def check_count(name, value, meaning=""):
    """A whole number >= 0 (not a bool); `meaning`, when given, is said in the error."""
    value = scalar(value)
    if isinstance(value, bool) or not isinstance(value, Integral) or value < 0:
        raise ValueError(f"{name} = {value!r} must be a whole number >= 0" + (f" ({meaning})" if meaning else ""))
    return int(value)


def _choice(name, value, allowed, hint=""):
    if not isinstance(value, str) or value not in allowed:
        raise ValueError(f"{name} {value!r} is unknown: use one of {', '.join(map(repr, allowed))}{hint}")
    return value


def read_toml(path, what="scene file") -> dict:
    """The tables of a TOML file; a ValueError of one line naming the file (`what` says what
    kind) when it cannot be read or is not TOML."""
    try:
        with open(path, "rb") as file:
            return tomllib.load(file)
    except FileNotFoundError:
        raise ValueError(f"{what} {path} not found") from None
    except IsADirectoryError:
        raise ValueError(f"{what} {path} is a folder: give a .toml file") from None
    except UnicodeDecodeError as error:
        raise ValueError(f"{path}: not UTF-8 text (byte {error.object[error.start]:#04x} at offset "
                         f"{error.start}): save the {what} as UTF-8") from None
    except OSError as error:
        raise ValueError(f"cannot read {what} {path}: {error.strerror}") from None
    except tomllib.TOMLDecodeError as error:
        raise ValueError(f"{path}: not valid TOML ({error})") from None


def read_scene_toml(path) -> dict:
    """The top-level tables of a scene file, without its [run] table (that is for the command line)."""
    data = read_toml(path)
    data.pop("run", None)
    return data


def check_box(box):
    try:
        w, h = box
    except (TypeError, ValueError):
        raise ValueError(f"box = {box!r} must be a pair (W, H)") from None
    w, h = _finite("box width", w), _finite("box height", h)
    if w <= 0 or h <= 0:
        raise ValueError(f"box = ({w}, {h}): both sides must be > 0")
    return w, h


def check_pair_range(name, value, lower_ok):
    """A scalar or a (low, high) pair, returned as (low, high)."""
    value = scalar(value)
    if isinstance(value, Real) and not isinstance(value, bool):
        lo = hi = _finite(name, value)
    else:
        try:
            lo, hi = value
        except (TypeError, ValueError):
            raise ValueError(f"{name} = {value!r} must be a number or a pair (min, max)") from None
        lo, hi = _finite(name, lo), _finite(name, hi)
    if not lower_ok(lo):
        raise ValueError(f"{name} = {value!r}: the smallest value {lo} is out of range "
                         f"({'must be > 0' if name == 'radius' else 'must be >= 0'})")
    if hi < lo:
        raise ValueError(f"{name} = {value!r}: max {hi} is below min {lo}")
    return lo, hi


#: The longest step. Times within a step, and the keys that order collisions, are kept below
#: `geometry.NEVER` (1e30, the mark of "no event"); a step 1000 times shorter leaves them room
#: (a pair in a box 1e35 wide, its speeds 1, with the default step of 3e33, collided without end).
MAX_DT = 1e27


def check_dt(dt):
    if dt is None:
        return None
    dt = _finite("dt", dt)
    if dt <= 0:
        raise ValueError(f"dt = {dt:g} must be > 0: give a step length in simulated seconds, or leave dt out to "
                         "choose it from the scene")
    if dt > MAX_DT:
        raise ValueError(f"dt = {dt:g} is above {MAX_DT:g}, the longest step (times within a step stay below 1e30, "
                         "the mark of no event): give a shorter dt, or measure times in a smaller unit")
    return dt


#: The largest speed a scene may hold, by precision: sqrt of the largest float over 1000. Times
#: of impact and kinetic energies square speeds (and differences of velocities, up to twice a
#: speed), so the squares must stay well inside the range of the arithmetic.
MAX_SPEED = {"f32": 1.8e16, "f64": 1.3e151}


def check_speed(vmax, precision, what="speed"):
    """Refuse a largest speed `vmax` above MAX_SPEED[precision]."""
    limit = MAX_SPEED[precision]
    if not vmax <= limit:
        raise ValueError(f"{what} {vmax:g} is above {limit:g}, the largest speed {precision} arithmetic holds "
                         "with room (times of impact and energies square it): measure lengths and times in "
                         "other units, so that speeds come out smaller")


#: The bounds of a scene's lengths, and of their products with its largest speed, by
#: precision. Times of impact square contact distances and their products with speeds, and
#: take differences of such squares. Least: the square root of the least normal number over
#: the unit round-off, so that those squares keep the precision's full relative precision
#: (Taichi's CPU code also flushes numbers below the least normal to 0: a collision of circles
#: 1e-17 wide and as slow was never found in f32). Largest: the square root of an eighth of
#: the largest number, so that a difference of two such squares of a box's side and twice a
#: speed stays finite (a box 1e25 wide in f32 overflowed every squared distance, and its
#: circles passed through each other). The least radius, and its product with the largest
#: speed, must be at least the least; the box's sides, and their products with the largest
#: speed, at most the largest.
MIN_LENGTH = {"f32": 4.5e-16, "f64": 1.5e-146}
MAX_LENGTH = {"f32": 6.5e18, "f64": 4.7e153}


def check_scale(box, rmin, vmax, precision):
    """Refuse a scene whose lengths, or their products with its largest speed, lie beyond
    MIN_LENGTH and MAX_LENGTH of its precision."""
    lo, hi = MIN_LENGTH[precision], MAX_LENGTH[precision]
    side = max(box)
    other = ", or use precision 'f64'" if precision == "f32" else ""
    room = (f"{precision} arithmetic squares with full precision (times of impact square lengths and their "
            "products with speeds)")
    if side > hi:
        raise ValueError(f"the box side {side:g} is above {hi:g}, the longest length {room}: measure lengths in a "
                         f"larger unit{other}")
    if rmin < lo:
        raise ValueError(f"radius {rmin:g} is below {lo:g}, the least length {room}: measure lengths in a smaller "
                         f"unit{other}")
    if vmax > 0 and side * vmax > hi:
        raise ValueError(f"the box side {side:g} times the largest speed {vmax:g} is {side * vmax:.3g}, above "
                         f"{hi:g}, the most {room}: measure lengths or times in other units, so that it comes out "
                         f"smaller{other}")
    if vmax > 0 and rmin * vmax < lo:
        raise ValueError(f"the least radius {rmin:g} times the largest speed {vmax:g} is {rmin * vmax:.3g}, below "
                         f"{lo:g}, the least {room}: measure lengths or times in other units, so that it comes out "
                         f"larger{other}")


def check_fits(rmax, box, boundary):
    w, h = box
    if boundary == "walls" and 2 * rmax > min(w, h):
        raise ValueError(f"radius {rmax} is larger than the box {w} x {h} allows "
                         f"(diameter {2 * rmax} > side {min(w, h)}): use smaller circles or a bigger box")
    if boundary == "periodic" and 4 * rmax >= min(w, h):
        raise ValueError(f"radius {rmax} is too large for the periodic box {w} x {h}: each side must exceed "
                         f"two diameters ({4 * rmax}) so a circle never meets two images of one neighbour; "
                         "use smaller circles or a bigger box")


#: Circles placed at random keep this relative clearance from each other and from the walls
#: (`placement.CLEARANCE`), so that rounding their places never makes an overlap.
PLACE_CLEARANCE = 1e-6


def rounding_margin(box, single: bool) -> float:
    """A bound on how far rounding a position to the storage precision (and wrapping it) moves it."""
    eps = 2.0 ** -24 if single else 2.0 ** -53
    return max(box) * (4.0 * eps)  # in this order, finite for any finite box


def check_room(rmax, box, boundary, precision):
    """Refuse a walled scene whose largest circle leaves no room to place it at random: its
    diameter with the placement's clearance (twice PLACE_CLEARANCE of it) and the rounding of a
    place in the precision (`rounding_margin`, at each wall) must fit the smaller side."""
    w, h = box
    rounding = rounding_margin(box, precision == "f32")
    if boundary == "walls" and 2 * rmax * (1 + 2 * PLACE_CLEARANCE) + 2 * rounding > min(w, h):
        if 2 * rounding >= min(w, h):
            raise ValueError(f"the box {w} x {h} is too thin to place circles at random in {precision}: rounding a "
                             f"place to {precision} at this box's size moves it by up to {rounding:.3g}, and twice "
                             f"that leaves no room across the side {min(w, h)}: use a box whose sides differ less"
                             + (", or precision 'f64'" if precision == "f32" else ""))
        most = (min(w, h) - 2 * rounding) / (2 * (1 + 2 * PLACE_CLEARANCE))
        most = float(f"{most * (1 - 1e-8):.9g}")  # printed below the limit, not rounded above it
        raise ValueError(f"radius {rmax} leaves no room to place the circle at random in the box {w} x {h} (its "
                         f"diameter, with a clearance of {2 * PLACE_CLEARANCE:g} of it for rounding, must fit the "
                         f"side {min(w, h)}): use a radius of at most {most:.9g}, a bigger box, or give the places "
                         "yourself with Simulation.from_arrays")


def area_fraction(radius, box) -> float:
    """The circles' area over the box's, as pi sum (r / W)(r / H): no square of a length, so
    neither underflow nor overflow for any finite box and radii."""
    r = np.asarray(radius, dtype=np.float64)
    return float(np.pi * np.sum((r / box[0]) * (r / box[1])))


#: The area fraction that the too-dense error proposes: random placement reaches it quickly.
SUGGESTED_AREA_FRACTION = 0.5


def _round_up(x, digits=3):
    """x rounded up to `digits` significant digits (a box side that, printed, still fits)."""
    if not x > 0 or not math.isfinite(x):
        return x
    scale = 10.0 ** (math.floor(math.log10(x)) - digits + 1)
    return math.ceil(x / scale * (1 - 1e-12)) * scale


def check_area_fraction(fraction, n, box):
    if fraction > DENSEST_PACKING:
        digits = 4  # as many as show the two apart
        while f"{fraction:.{digits}f}" == f"{DENSEST_PACKING:.{digits}f}" and digits < 17:
            digits += 1
        grow = math.sqrt(fraction / SUGGESTED_AREA_FRACTION)
        w, h = (_round_up(side * grow) for side in box)
        raise ValueError(f"area fraction {fraction:.{digits}f} of {n} circles in a {box[0]} x {box[1]} box "
                         f"exceeds the densest packing {DENSEST_PACKING:.{digits}f}: use fewer or smaller circles "
                         f"or a bigger box: {w:.3g} x {h:.3g} holds them at area fraction "
                         f"{SUGGESTED_AREA_FRACTION} (box = [{w:.3g}, {h:.3g}], or area_fraction = "
                         f"{SUGGESTED_AREA_FRACTION} in place of the box)")


#: The box of a Scene given neither a box nor an area fraction; its aspect is that of the
#: box made for an area fraction.
DEFAULT_BOX = (16.0, 9.0)


def check_area_fraction_value(value):
    """An area fraction given to size a box: a finite number in (0, DENSEST_PACKING]."""
    value = _finite("area_fraction", value)
    if not 0 < value <= DENSEST_PACKING:
        raise ValueError(f"area_fraction = {value!r} is out of range: give a fraction > 0 and at most the densest "
                         f"packing {DENSEST_PACKING:.4f} (below about 0.7 for a fluid)")
    return value


def box_for_area_fraction(n, radius, fraction, aspect=DEFAULT_BOX[0] / DEFAULT_BOX[1], species=None):
    """The box (W, H), W / H = aspect, in which n circles of radius r (or uniform in (rmin,
    rmax)) fill the area fraction `fraction` on average: W H = n pi E[r^2] / fraction. With
    `species` ((count, radius) pairs, `Scene.species`) the radii are those, exactly."""
    n = scalar(n)
    if isinstance(n, bool) or not isinstance(n, Integral):
        raise ValueError(f"n = {n!r} must be a whole number of circles")
    if n <= 0:
        raise ValueError(f"n = {n} must be > 0")
    fraction = check_area_fraction_value(fraction)
    rlo, rhi = check_pair_range("radius", radius, lambda v: v > 0)
    aspect = _finite("box aspect", aspect)
    if not aspect > 0:
        raise ValueError(f"box aspect {aspect!r} must be > 0")
    if species is not None:
        # sum of count (r / rhi)^2, in units of the largest radius as below
        h = rhi * math.sqrt(math.pi * sum(c * (r / rhi) ** 2 for c, r in species) / (fraction * aspect))
        return aspect * h, h
    a = rlo / rhi  # E[r^2] = rhi^2 (a^2 + a + 1) / 3, in units of rhi: no square of a length
    h = rhi * math.sqrt(n * math.pi * (a * a + a + 1.0) / (3.0 * fraction * aspect))
    return aspect * h, h


def _species(value, n):
    """`species` as ((count, radius), ...) with the counts summing to n: from entries
    {count = C, radius = R} or {fraction = F, radius = R} (all counts or all fractions, the
    fractions summing to 1; the last species takes what rounding leaves), or [C, R] pairs.
    n is None for counts alone, which then fix it."""
    if not isinstance(value, (list, tuple)) or not value:
        raise ValueError(f"species = {value!r} must be a non-empty list of {{count = C, radius = R}} or "
                         "{fraction = F, radius = R} entries")
    entries = []
    for k, entry in enumerate(value):
        if isinstance(entry, (list, tuple)) and len(entry) == 2:
            entry = {"count": entry[0], "radius": entry[1]}
        if not isinstance(entry, dict) or set(entry) not in ({"count", "radius"}, {"fraction", "radius"}):
            raise ValueError(f"species[{k}] = {entry!r} must be {{count = C, radius = R}} or {{fraction = F, "
                             "radius = R}")
        radius = _finite(f"species[{k}] radius", entry["radius"])
        if not radius > 0:
            raise ValueError(f"species[{k}] radius = {radius!r} must be > 0")
        entries.append((entry.get("count"), entry.get("fraction"), radius))
    if all(c is not None for c, _, _ in entries):
        counts = [check_count(f"species[{k}] count", c) for k, (c, _, _) in enumerate(entries)]
        if any(c < 1 for c in counts):
            raise ValueError(f"species counts {counts} must each be >= 1")
        if n is not None and sum(counts) != n:
            raise ValueError(f"n = {n} but the species count {' + '.join(map(str, counts))} = {sum(counts)} circles: "
                             f"give n = {sum(counts)}, or leave n out")
    elif all(f is not None for _, f, _ in entries):
        fractions = [_finite(f"species[{k}] fraction", f) for k, (_, f, _) in enumerate(entries)]
        if any(not 0 < f < 1 for f in fractions) or not math.isclose(sum(fractions), 1.0, rel_tol=1e-9):
            raise ValueError(f"species fractions {fractions} must each be between 0 and 1 and sum to 1")
        counts = [round(f * n) for f in fractions[:-1]]
        counts.append(n - sum(counts))
        if any(c < 1 for c in counts):
            raise ValueError(f"species fractions {fractions} of n = {n} leave a species with no circle: give more "
                             "circles or counts")
    else:
        raise ValueError("species mix counts and fractions: give every species a count, or every one a fraction")
    return tuple((c, r) for c, (_, _, r) in zip(counts, entries))


@dataclass(frozen=True)
class Scene:
    """What is simulated. Units are world units (box [0, W] x [0, H], y up) and seconds.

    n: number of circles. box: (W, H), by default DEFAULT_BOX; or, in its place,
    area_fraction: the box is then made for the circles to fill that fraction on average, with
    the aspect of DEFAULT_BOX (`box_for_area_fraction`). Once made, a Scene holds both, the
    box and the expected area fraction; both given is refused unless they agree. radius: r or (rmin, rmax), uniform in the range.
    speed: (vmin, vmax), uniform speeds in random directions. mass: "radius" (m = r, the
    default), "area" (m = pi r^2) or "equal" (m = 1). boundary: "walls" or "periodic".
    scheme: "event" (exact) or "discrete" (fast, approximate). precision: "f32" or "f64".
    dt: step length in simulated seconds, None to choose it from the scene. seed: int.
    crystal: (nx, ny), the columns and rows of a triangular crystal of equal disks in a periodic
    box: n = nx ny, ny even, and the box of aspect nx : ny sqrt(3)/2 that the crystal fits
    exactly (from area_fraction, or a box of that aspect). start: "fluid" (circles placed at
    random, `circles.placement`), "crystal" (on the perfect crystal; needs crystal) or
    "compressed" (placed at half the area fraction and compressed to it, `circles.compress`: a
    fluid above freezing too; f64). All starts of one crystal shape share the box, so runs from
    each can be set side by side.
    species: circles of several sizes in place of radius, as entries {"count": C, "radius": R}
    or {"fraction": F, "radius": R} (fractions of n, the last species taking what rounding
    leaves); held as ((count, radius), ...), the circles in that order, radius then their range.
    aspect: the width over the height of the box made from area_fraction (16:9 without it; a
    crystal fixes its own): 1.0 for a square box.
    """

    n: int = 10_000
    box: tuple | None = None
    radius: tuple | float = (0.02, 0.05)
    speed: tuple = (0.5, 1.0)
    mass: str = "radius"
    boundary: str = "walls"
    scheme: str = "event"
    precision: str = "f64"
    dt: float | None = None
    seed: int = 0
    area_fraction: float | None = None
    crystal: tuple | None = None
    start: str = "fluid"
    species: tuple | None = None
    aspect: float | None = None

    def __post_init__(self):
        object.__setattr__(self, "n", scalar(self.n))
        if isinstance(self.n, bool) or not isinstance(self.n, Integral):
            raise ValueError(f"n = {self.n!r} must be a whole number of circles")
        if self.n <= 0:
            raise ValueError(f"n = {self.n} must be > 0")
        rlo, rhi = check_pair_range("radius", self.radius, lambda v: v > 0)
        if self.species is not None:
            # Counts fix n: Scene(species=...) without n takes their sum, as a scene file does.
            counts_only = isinstance(self.species, (list, tuple)) and all(
                isinstance(e, dict) and "count" in e or isinstance(e, (list, tuple)) for e in self.species)
            given_n = None if counts_only and self.n == Scene.n else self.n
            species = _species(self.species, given_n)
            object.__setattr__(self, "n", sum(c for c, _ in species))
            radii = (min(r for _, r in species), max(r for _, r in species))
            if (rlo, rhi) not in (radii, (0.02, 0.05)):
                raise ValueError(f"radius = {self.radius!r} and species are both given: the species give the radii; "
                                 "drop radius")
            rlo, rhi = radii
            object.__setattr__(self, "species", species)
        _choice("start", self.start, STARTS)
        crystal = self._crystal_of(rlo, rhi)
        box = self._box_of(rlo, rhi)
        vlo, vhi = check_pair_range("speed", self.speed, lambda v: v >= 0)
        _choice("mass model", self.mass, MASS_MODELS, " (masses of your own go to Simulation.from_arrays)")
        _choice("boundary", self.boundary, BOUNDARIES)
        _choice("scheme", self.scheme, SCHEMES)
        _choice("precision", self.precision, PRECISIONS)
        check_speed(vhi, self.precision)
        if self.start == "compressed" and self.precision != "f64":
            raise ValueError("start = 'compressed' needs precision = 'f64': a compression leaves pairs at contact, "
                             "which positions rounded to float32 would overlap; give precision = 'f64'")
        if self.start == "compressed" and not vhi > 0:
            raise ValueError(f"start = 'compressed' needs moving circles, not speed = {self.speed!r}: the disks "
                             "grow while they collide; give a speed above 0")
        dt = check_dt(self.dt)
        check_count("seed", self.seed)
        check_fits(rhi, box, self.boundary)
        check_room(rhi, box, self.boundary, self.precision)
        check_scale(box, rlo, vhi, self.precision)
        check_area_fraction(self._expected_area_fraction(box, rlo, rhi), self.n, box)
        object.__setattr__(self, "n", int(self.n))
        object.__setattr__(self, "box", box)
        object.__setattr__(self, "radius", (rlo, rhi))
        object.__setattr__(self, "speed", (vlo, vhi))
        object.__setattr__(self, "dt", dt)
        object.__setattr__(self, "seed", int(self.seed))
        object.__setattr__(self, "crystal", crystal)
        object.__setattr__(self, "area_fraction", self._expected_area_fraction(box, rlo, rhi))

    def _expected_area_fraction(self, box, rlo, rhi):
        """The area fraction the scene's circles fill on average in `box` (exactly, for species)."""
        if self.species is not None:
            return sum(c * math.pi * (r / box[0]) * (r / box[1]) for c, r in self.species)
        return self.expected_area_fraction_of(self.n, box, rlo, rhi)

    def radii(self, rng):
        """The circles' radii: each species' in turn, or drawn from `rng` uniform in the range."""
        import numpy as np

        if self.species is not None:
            return np.concatenate([np.full(c, r) for c, r in self.species])
        rlo, rhi = self.radius
        return rng.uniform(rlo, rhi, self.n) if rhi > rlo else np.full(self.n, rlo)

    def _crystal_of(self, rlo, rhi):
        """(nx, ny) checked, or None; refuses a crystal start without a crystal."""
        if self.crystal is None:
            if self.start == "crystal":
                raise ValueError("start = 'crystal' needs the crystal's shape: give crystal = [nx, ny], its columns "
                                 "and rows (n = nx ny, ny even)")
            return None
        shape = self.crystal
        if not isinstance(shape, (tuple, list)) or len(shape) != 2:
            raise ValueError(f"crystal = {shape!r} must be [nx, ny]: the columns and rows of the triangular crystal")
        nx, ny = (check_count(f"crystal[{k}]", value) for k, value in enumerate(shape))
        if nx < 1 or ny < 2 or ny % 2:
            raise ValueError(f"crystal = [{nx}, {ny}]: give nx >= 1 columns and an even number ny >= 2 of rows (a "
                             "periodic box stacks the rows of a triangular crystal in pairs)")
        if self.n != nx * ny:
            raise ValueError(f"n = {self.n} but crystal = [{nx}, {ny}] holds {nx * ny} circles: give n = {nx * ny} "
                             "(a scene file or sweep file may leave n out)")
        if rhi != rlo:
            raise ValueError(f"crystal = [{nx}, {ny}] with radii from {rlo:g} to {rhi:g}: a crystal is of equal "
                             "circles; give one radius")
        if self.boundary != "periodic":
            raise ValueError(f"crystal = [{nx}, {ny}] in a box with {self.boundary}: the crystal fills a periodic "
                             "box; give boundary = 'periodic'")
        return nx, ny

    def crystal_aspect(self):
        """Width over height of the box a crystal of `crystal` columns and rows fits: nx / (ny sqrt(3)/2)."""
        nx, ny = self.crystal
        return nx / (ny * math.sqrt(3.0) / 2.0)

    def _aspect(self):
        """The aspect of the box made from the area fraction: `aspect`, or DEFAULT_BOX's."""
        if self.aspect is None:
            return DEFAULT_BOX[0] / DEFAULT_BOX[1]
        aspect = _finite("aspect", self.aspect)
        if not aspect > 0:
            raise ValueError(f"aspect = {aspect!r} must be > 0: give the box's width over its height, e.g. 1.0 for "
                             "a square")
        return aspect

    def _box_of(self, rlo, rhi):
        """The box given, the box made for the area fraction given (of `aspect`, DEFAULT_BOX's
        without it), or DEFAULT_BOX; for a crystal, of the crystal's aspect."""
        if self.aspect is not None:
            if self.crystal is not None:
                raise ValueError(f"aspect = {self.aspect!r} and crystal = {list(self.crystal)!r} are both given: the "
                                 "crystal fixes the box's aspect (nx : ny sqrt(3)/2); drop aspect")
            if self.box is not None or self.area_fraction is None:
                raise ValueError(f"aspect = {self.aspect!r} shapes the box made from area_fraction: give "
                                 "area_fraction with it, in place of a box")
        if self.area_fraction is None:
            if self.crystal is not None and self.box is None:
                raise ValueError(f"crystal = {list(self.crystal)!r}: give area_fraction (the box is then made of "
                                 "the crystal's aspect) or a box of aspect nx : ny sqrt(3)/2")
            box = check_box(DEFAULT_BOX if self.box is None else self.box)
            if self.crystal is not None:
                aspect = self.crystal_aspect()
                if not math.isclose(box[0] / box[1], aspect, rel_tol=1e-9):
                    raise ValueError(f"box = {list(box)!r} has aspect {box[0] / box[1]:.9g}, and crystal = "
                                     f"{list(self.crystal)!r} fits a box of aspect {aspect:.9g} (nx : ny sqrt(3)/2): "
                                     "give area_fraction in place of the box, or a box of that aspect")
            return box
        fraction = check_area_fraction_value(self.area_fraction)
        if self.box is None:
            if self.crystal is not None:
                return box_for_area_fraction(self.n, (rlo, rhi), fraction, self.crystal_aspect())
            return box_for_area_fraction(self.n, (rlo, rhi), fraction, self._aspect(), species=self.species)
        box = check_box(self.box)
        held = self._expected_area_fraction(box, rlo, rhi)
        if not math.isclose(held, fraction, rel_tol=1e-9):
            raise ValueError(f"box = {list(box)!r} and area_fraction = {fraction!r} are both given, and the box "
                             f"holds these circles at area fraction {held:.6g}: give one of them")
        return box

    @staticmethod
    def expected_area_fraction_of(n, box, rlo, rhi):
        # E[r^2] / (W H) for r uniform in [rlo, rhi], in lengths over the box's sides (see area_fraction)
        (aw, ah), (bw, bh) = (rlo / box[0], rlo / box[1]), (rhi / box[0], rhi / box[1])
        return n * math.pi * (aw * ah + 0.5 * (aw * bh + bw * ah) + bw * bh) / 3.0

    def to_dict(self) -> dict:
        d = asdict(self)
        d["box"] = list(self.box)
        d["radius"] = list(self.radius)
        d["speed"] = list(self.speed)
        del d["area_fraction"], d["aspect"]  # the box says them
        if self.crystal is None:
            del d["crystal"]
        else:
            d["crystal"] = list(self.crystal)
        if self.species is None:
            del d["species"]
        else:
            del d["radius"]  # the species say it
            d["species"] = [{"count": c, "radius": r} for c, r in self.species]
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "Scene":
        if "circle" in d:
            raise ValueError("the scene lists its circles ([[circle]] entries), which a random Scene "
                             "cannot hold: read it with circles.scenefile.read_circle_list and "
                             "simulate it with circles.Simulation.from_arrays")
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(d) - known)
        if unknown:
            raise ValueError(f"unknown scene key(s) {', '.join(unknown)}: known keys are {', '.join(sorted(known))}")
        if d.get("box") is not None and d.get("area_fraction") is not None:
            raise ValueError(f"box = {d['box']!r} and area_fraction = {d['area_fraction']!r} are both given: give "
                             "one of them (area_fraction makes a box of aspect 16:9 for the circles, or of the "
                             "aspect given)")
        kw = dict(d)
        if kw.get("species") is not None:
            if "radius" in kw:
                raise ValueError("radius and species are both given: the species give the radii; drop radius")
            if "n" not in kw and isinstance(kw["species"], list) and kw["species"] and all(
                    isinstance(e, dict) and isinstance(e.get("count"), int) for e in kw["species"]):
                kw["n"] = sum(e["count"] for e in kw["species"])
            if isinstance(kw["species"], list):
                kw["species"] = tuple(kw["species"])
        if kw.get("crystal") is not None and "n" not in kw and isinstance(kw["crystal"], (list, tuple)) \
                and len(kw["crystal"]) == 2 and all(isinstance(v, int) for v in kw["crystal"]):
            kw["n"] = kw["crystal"][0] * kw["crystal"][1]
        for key in ("box", "radius", "speed", "crystal"):
            if isinstance(kw.get(key), list):
                kw[key] = tuple(kw[key])
        return cls(**kw)

    @classmethod
    def from_toml(cls, path) -> "Scene":
        """Read a scene from TOML: the Scene fields at top level; a [run] table (for the command line) is ignored.

        A file that lists its circles ([[circle]] entries) is refused with a ValueError: read it
        with `circles.scenefile.read_circle_list`.
        """
        return cls.from_dict(read_scene_toml(path))
