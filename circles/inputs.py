"""Checks of what a simulation is given: arrays of circles, masses, colours, places in the box,
the event log's capacity. Each refuses bad input with an error that names the value, the limit
and the fix, before any work; `Simulation`, `Simulation.from_arrays`, `Simulation.load` and the
scene files share them."""
import math

import numpy as np

from .memory import MOST_RECORDED, check_memory
from .scene import (BOUNDARIES, MASS_MODELS, PRECISIONS, SCHEMES, _choice, area_fraction, check_area_fraction,
                    check_box, check_count, check_dt, check_fits, check_scale, check_speed)
from .schemes import STEPPERS

#: Overlap (relative to contact distance) above which from_arrays refuses a configuration.
INPUT_OVERLAP_TOLERANCE = 1e-9
_NP_REAL = {"f32": np.float32, "f64": np.float64}


def masses_for(model, radius, precision=None):
    """The circles' masses from a mass model ("radius", "area", "equal") or (n,) given masses;
    with a precision, masses whose ratio that precision cannot carry are refused
    (`check_mass_ratio`)."""
    mass = _masses(model, radius)
    if precision is not None:
        check_mass_ratio(mass, precision)
    return mass


def _masses(model, radius):
    if isinstance(model, str):
        _choice("mass model", model, MASS_MODELS)
        if model == "radius":
            return radius.copy()
        if model == "area":
            return np.pi * radius * radius
        return np.ones_like(radius)
    mass = real_numbers("mass", model)
    if mass.shape != radius.shape:
        raise ValueError(f"mass has shape {mass.shape}, expected ({radius.shape[0]},): one mass per circle")
    if not np.all(np.isfinite(mass)) or np.any(mass <= 0):
        bad = mass[~(np.isfinite(mass) & (mass > 0))][0]
        raise ValueError(f"mass {bad} must be finite and > 0")
    least = float(np.finfo(np.float64).tiny)
    if np.any(mass < least):
        raise ValueError(f"mass {mass[mass < least][0]:g} is below {least:g}, the least normal float64 (its "
                         "inverse overflows): give the masses in a larger unit, as only their ratios matter")
    return mass


#: The largest ratio of two circles' masses each precision carries. The kernels hold inverse
#: masses in a unit of mass of their own (`mass_unit`, a power of two near the middle of the
#: masses, so the scaling is exact and the motion is that of the masses as given), so only the
#: ratio is bounded: inverse masses then stay normal numbers, and impulses (a mass in that unit
#: times a speed up to MAX_SPEED) stay finite, with a factor of 1000 to spare in float32.
MAX_MASS_RATIO = {"f32": 1e36, "f64": 1e300}


def check_mass_ratio(mass, precision):
    """Refuse masses whose largest and least differ by more than MAX_MASS_RATIO[precision]."""
    heavy, light = int(np.argmax(mass)), int(np.argmin(mass))
    ratio = float(mass[heavy]) / float(mass[light])
    if not ratio <= MAX_MASS_RATIO[precision]:
        shown = f"{ratio:.3g}"
        if not math.isfinite(ratio):  # beyond float64 (1e200 over 1e-200): shown from its logarithm
            exponent = math.log10(float(mass[heavy])) - math.log10(float(mass[light]))
            shown = f"{10 ** (exponent % 1):.3g}e+{math.floor(exponent)}"
        raise ValueError(f"circle {heavy} (mass {mass[heavy]:g}) is {shown} times as heavy as circle {light} "
                         f"(mass {mass[light]:g}), more than the {MAX_MASS_RATIO[precision]:g} that {precision} "
                         "arithmetic carries: bring the masses closer"
                         + (", or use precision 'f64'" if precision == "f32" else ""))


def mass_unit(mass):
    """The unit of mass of the kernels' inverse masses (and of the impulses they sum): the power
    of two nearest the geometric mean of the least and largest mass. Scaling by a power of two
    is exact, so velocities come out bit for bit as with the masses as given wherever those
    fit the precision, and masses of any magnitude fit (`MAX_MASS_RATIO`)."""
    lo, hi = float(np.min(mass)), float(np.max(mass))
    return 2.0 ** min(round(0.5 * (math.log2(lo) + math.log2(hi))), 1023)


def check_colors(color, n):
    """`color` as an (n, 3) uint8 array of 0-255 RGB values; ValueError for anything else (floats
    in [0, 1], as some libraries write colours, would otherwise truncate to nearly black)."""
    c = np.asarray(color)
    if c.shape != (n, 3) or c.dtype == bool or not np.issubdtype(c.dtype, np.number):
        raise ValueError(f"color has shape {c.shape} and type {c.dtype}, expected ({n}, 3) numbers: one 0-255 "
                         "RGB triple per circle")
    whole = np.isfinite(c) & (c >= 0) & (c <= 255) & (c == np.round(c))
    if not np.all(whole):
        i = int(np.flatnonzero(~np.all(whole, axis=1))[0])
        hint = " (for fractions in [0, 1], multiply by 255)" if np.all((c >= 0) & (c <= 1)) else ""
        raise ValueError(f"color of circle {i}, {c[i].tolist()}, is not three whole numbers from 0 to 255{hint}")
    if np.issubdtype(c.dtype, np.floating) and c.max() <= 1 and c.max() > 0:
        raise ValueError("color holds floats from 0 to 1 only, as fractions in [0, 1] would: give 0-255 RGB values "
                         "(multiply by 255)")
    return c.astype(np.uint8)


def real_numbers(name, value):
    """`value` as a float64 array, when it holds real numbers (integers or floats); ValueError
    for booleans, complex numbers, strings or objects, which numpy would convert silently (or,
    for complex, drop a part of)."""
    try:
        arr = np.asarray(value)
    except ValueError as error:  # ragged nested lists
        raise ValueError(f"{name} is not an array of numbers ({error}): give a list or array of real "
                         "numbers") from None
    if arr.dtype.kind not in "iuf":
        raise ValueError(f"{name} holds values of type {arr.dtype}, not real numbers: give integers or floats")
    return arr.astype(np.float64)


def check_circles(pos, vel, radius, box, precision):
    """Given circles (`Simulation.from_arrays`, `Simulation.load`): pos and vel (n, 2) and
    finite, no speed above MAX_SPEED[precision], for n radii that are finite and > 0, and
    lengths and speeds that the precision squares with room (`scene.check_scale`)."""
    n = radius.shape[0]
    for name, arr in (("pos", pos), ("vel", vel)):
        if arr.shape != (n, 2):
            raise ValueError(f"{name} has shape {arr.shape}, expected ({n}, 2): one (x, y) row per circle, as "
                             f"many as the {n} radii")
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"{name} holds a non-finite value {arr[~np.isfinite(arr)][0]}")
    speeds = np.hypot(vel[:, 0], vel[:, 1])
    fastest = int(np.argmax(speeds))
    check_speed(float(speeds[fastest]), precision, f"the speed of circle {fastest},")
    if not np.all(np.isfinite(radius)) or np.any(radius <= 0):
        raise ValueError(f"radius {radius[~(np.isfinite(radius) & (radius > 0))][0]} must be finite and > 0")
    check_scale(box, float(radius.min()), float(speeds[fastest]), precision)


def outside_walls(pos, radius, box, slack):
    """Which circles cross a wall of the box by more than `slack` (a length): (n,) booleans."""
    lo, hi = radius - slack, np.array(box) - radius[:, None] + slack
    return np.any((pos < lo[:, None]) | (pos > hi), axis=1)


def check_placed(pos, radius, box, boundary, slack):
    """Given places for the radii: the largest circle fits the box, the circles' area fits the
    densest packing, and in a walled box every circle lies inside the walls, or crosses one by
    at most `slack` (a length)."""
    n = radius.shape[0]
    check_fits(float(radius.max()), box, boundary)
    w, h = box
    check_area_fraction(area_fraction(radius, box), n, box)
    if boundary == "walls":
        out = outside_walls(pos, radius, box, slack)
        if np.any(out):
            i = int(np.flatnonzero(out)[0])
            at = tuple(float(x) for x in pos[i])
            r = float(radius[i])
            raise ValueError(f"circle {i} at {at} with radius {r} is not inside the walls "
                             f"[0, {w}] x [0, {h}]: move it inside, its centre to x in [{r}, {w - r}] and y in "
                             f"[{r}, {h - r}] (to within {slack:.3g})")


def place_slack(precision, box):
    """How far a stored place can lie from where exact arithmetic puts it: 8 units in the last
    place of the box's larger side in the precision (float32 stores a place in a box of side L
    to within about 6e-8 L)."""
    return 8.0 * float(np.finfo(_NP_REAL[precision]).eps) * max(box)


def overlap_tolerance(precision, box, radius):
    """The overlap, as a fraction of the contact distance, up to which given circles count as in
    contact: INPUT_OVERLAP_TOLERANCE, plus what storing their places can make of a contact
    (`place_slack` over the least contact distance: in float32, touching circles given in
    float64 come out overlapping by up to that)."""
    return INPUT_OVERLAP_TOLERANCE + place_slack(precision, box) / (2.0 * float(radius.min()))


def random_colors(n, rng):
    return rng.integers(48, 256, size=(n, 3), dtype=np.uint8)


def check_record_events(record_events, scheme):
    """record_events: a whole number >= 0 (the log's capacity) up to MOST_RECORDED, above 0 only
    with the event scheme, the one whose collisions are events at known times."""
    check_count("record_events", record_events, "the most collisions the log keeps; 0 keeps none")
    if record_events > MOST_RECORDED:
        raise ValueError(f"record_events = {record_events} is more than the {MOST_RECORDED} collisions a log "
                         "holds (its arrays count their items in 32 bits): keep fewer")
    if record_events > 0 and not STEPPERS[scheme].LOGS_EVENTS:
        raise ValueError(f"record_events = {record_events} with scheme {scheme!r}: only the event scheme logs its "
                         "collisions (the discrete scheme resolves overlaps at the end of each step, with no "
                         "time of contact); use scheme='event', or record_events=0")


def given_circles(pos, vel, radius, mass, box, boundary, scheme, precision, dt, color, record_events):
    """The arguments of `Simulation.from_arrays`, checked and made whole: (pos, vel, radius, mass,
    color, box, dt), radius one per circle, positions in a periodic box wrapped into it."""
    box = check_box(box)
    _choice("boundary", boundary, BOUNDARIES)
    _choice("scheme", scheme, SCHEMES)
    _choice("precision", precision, PRECISIONS)
    check_record_events(record_events, scheme)
    dt = check_dt(dt)
    pos = real_numbers("pos", pos)
    vel = real_numbers("vel", vel)
    radius = real_numbers("radius", radius)
    if radius.ndim == 0:  # one radius for every circle
        radius = np.full(pos.shape[0] if pos.ndim == 2 else 1, float(radius))
    radius = radius.reshape(-1)
    n = radius.shape[0]
    if n == 0:
        raise ValueError("n = 0 circles: give at least one")
    check_memory(n, scheme, precision, record_events=record_events)
    check_circles(pos, vel, radius, box, precision)
    mass = masses_for("radius" if mass is None else mass, radius, precision)
    # A place given as the result of arithmetic (0.3 - 0.2 for a radius of 0.1) may cross a
    # wall by its rounding, as a saved one may (`load`).
    check_placed(pos, radius, box, boundary, place_slack(precision, box))
    if boundary == "periodic":
        pos = pos % np.array(box)
    color = random_colors(n, np.random.default_rng(0)) if color is None else check_colors(color, n)
    return pos, vel, radius, mass, color, box, dt
