"""Simulation: the time-varying state of a scene and the stepper that advances it.

A step of the event scheme reads as its stages: largest speed, grid, backup, then rounds
of predict / bound / bound / execute until no event is left before the step's end (on a CPU:
one queue of events instead of the rounds), then every circle advances to the end (see
`circles.event`). A step of the discrete scheme:
move, grid, rounds of pick / resolve, walls (see `circles.discrete`).
"""
from __future__ import annotations

import gc
import math
import os
import signal
import threading
import weakref
import zipfile
from dataclasses import dataclass
from numbers import Real
from pathlib import Path

import numpy as np
import taichi as ti

from . import discrete, event, launch, observables, placement, reductions, team
from .backend import current_arch, ensure_init, on_restart, runtime, serial_loops
from .geometry import NEVER, NO_EVENT, spans
from .grid import Grid, count_parts
from .scene import (BOUNDARIES, MASS_MODELS, MAX_DT, PRECISIONS, SCHEMES, Scene, _choice, area_fraction,
                    check_area_fraction, check_box, check_count, check_dt, check_fits, check_scale, check_speed)
from .scene import scalar as _scalar

#: Speeds may grow by this factor within an event step before the step is cut short. The grid's
#: cells, and the clusters a split into parts must keep whole, grow with it; a step cut short
#: runs in two pieces. At 1.1, side by side with 1.25 after 50 steps of the bench scene: 1.11
#: times the circle-steps/s at 1e6, 1.07 at 1e5, 1.03 at 1e4, with steps cut 0, 1.5 and 3.8
#: times in a hundred (more while the speeds spread out from their start, 16 in a hundred at
#: 1e6 over the first 50 steps); 1.05 was no faster than 1.1 at 1e6 and cut 10 in a hundred.
SPEED_MARGIN = 1.1
#: Default event-scheme step: the fastest circle moves this many mean radii per step (the mean, not
#: the largest: a few large circles must not make every step long and every grid cell wide).
EVENT_STEP_RADII = 0.3
#: Default discrete-scheme step: the fastest circle moves this fraction of the smallest radius.
DISCRETE_STEP_FRACTION = 0.2
#: Rounds of pair resolution per discrete step; what is left stays for the next step.
DISCRETE_MAX_ROUNDS = 16
#: Rounds run in the same launch as the move and the grid (more follow only when needed); even,
#: as the rounds alternate between two work lists. Rounds after the last busy one cost two
#: empty loops each: on a CPU serial ones (see DISCRETE_PARALLEL_ROUNDS), about a microsecond each.
DISCRETE_FUSED_ROUNDS = 8
#: Rounds of a discrete step whose loops run in parallel on a CPU; later ones run on one thread.
#: Starting a parallel loop on the CPU's thread pool costs some 15-25 microseconds (50-55 on
#: another host, `bench/launch_cost.py`) even when it has nothing to do, while one thread takes
#: 100-150 ns per listed circle. Round 3's list holds about 1% of the circles, round 5's about
#: 0.02% (at 1e6: 10062 and 195), none by round 8. So four rounds run in parallel (fewer, or a
#: number chosen from the lists, measured no better: bench/PERFORMANCE.md). A GPU runs every
#: round in parallel.
DISCRETE_PARALLEL_ROUNDS = 4
#: Discrete steps run in one launch, at most, where a step runs on one thread (see
#: backend.serial_loops): a launch and its call cost some 20 microseconds, more than the whole
#: step of a few hundred circles (`discrete.serial_steps`). A reorder (REORDER_EVERY) ends a
#: batch. 1: a launch a step.
DISCRETE_STEPS_AT_ONCE = 16
#: The event scheme on a CPU runs each step from one queue of events (`event.queue_step`): the
#: same events, in the same order, with the same arithmetic as the parallel rounds a GPU runs,
#: without the rounds' bound sweeps and passes over every circle. False: rounds on a CPU too.
EVENT_QUEUE_ON_CPU = True
#: Steps an event queue runs whole after its split into parts failed (`event.split_parts`:
#: clusters of linked circles too large, as in a dense packing) before it tries again.
SPLIT_RETRY_STEPS = 16
#: A split into parts claims at most n / PART_CLAIMS circles with their clusters across borders.
PART_CLAIMS = 4
#: The split's links (`event.split_parts`) reach this many units in the last place of the
#: largest coordinate further, against the round-off of the positions within a window.
LINK_ALLOWANCE_ULPS = 16
#: The arrays of a circle's state that the parts of an event step back up at its start (the
#: clocks aside, 0 then), in the order event.queue_parts takes them; the counts and sums are not
#: changed until the step is done (its events write to a sum log, `event.apply_sums`).
PARTS_BACKUP_ORDER = ("pos", "vel")
#: The parts' sum log (`event.queue_parts`): entries per circle at first (an event writes one:
#: the bench scene's steps take about 0.1 a circle, at area fraction 0.6 about 0.5), twice as
#: many each time a step fills it while the memory allows, up to SUM_LOG_MOST_PER_CIRCLE; and
#: the most entries a part takes from it at a time.
SUM_LOG_PER_CIRCLE = 1
SUM_LOG_MOST_PER_CIRCLE = 4
SUM_LOG_CHUNK = 256
#: Windows of a step split into parts at most (`Simulation._queue_parts_step`), and the steps
#: after which a step tries half as many.
MOST_WINDOWS = 8
WINDOW_RETRY_STEPS = 16
#: Rounds of one event step after which (and after twice as many, and so on) the events it
#: executed are counted: more than `event.most_events` stop it with an
#: error (jammed circles), as on the queue. A step takes about ten rounds.
JAM_CHECK_ROUNDS = 64
#: Sweeps of the causal bound per round before giving up (it settles in a few).
MAX_BOUND_SWEEPS = 10_000
#: Overlapping neighbours a circle remembers within a discrete step (more: it searches its
#: cells); at most discrete.MOST_CONTACTS.
DISCRETE_CONTACTS = 4
#: The discrete scheme on circles that all share one radius and one mass reads the first
#: circle's (`discrete.per_circle`), not each circle's: the same numbers, fewer loads. False:
#: every scene reads them per circle (for tests that compare the two).
DISCRETE_UNIFORM = True
#: The discrete scheme's first round of a step on a CPU's threads: in one part of the circles
#: per thread, each listing its marked circles before picking for them
#: (`discrete._first_round_in_parts`). False: a loop over every circle, as on a GPU (for tests
#: that compare the two).
DISCRETE_FIRST_IN_PARTS = True
#: On a CPU with several threads, a discrete step's move, grid, rounds and walls run as one
#: team (`discrete.team_step`, `circles.team`): one start of the thread pool a step instead of
#: one per loop. False: `discrete.begin_step`'s loops.
DISCRETE_TEAM = True
#: Runs the team's members one after another on one thread (for tests: the same state).
DISCRETE_TEAM_SERIAL = False
#: Steps between reorderings of the arrays by grid cell (neighbours close in memory).
REORDER_EVERY = 16
#: In a box wider than tall, a one-level grid numbers its cells along the box's y axis
#: (`grid.Grid`, transposed): the event queue's parts are strips of whole rows of cells, and
#: their borders, searched at every split, are then as long as the box's shorter side. The
#: same state bit for bit either way; the event scheme at 1e6 in a 16:9 box makes about 5%
#: more circle-steps (see bench/PERFORMANCE.md). A two-level grid keeps the box's axes (the
#: blocks its large circles search are sized along them: `event._runs`, `discrete.wide_reach`).
TRANSPOSE_WIDE_GRIDS = True
#: Steps in a row that `advance` lets end at their start (cut by a collision that would make
#: a circle faster than the grid allows) before it stops as stuck: each makes the largest
#: speed at least SPEED_MARGIN times larger, 1.1^1000 = 2.5e41 times in all.
MOST_STALLED_STEPS = 1000
#: The most by which the simulated clock (float64) may count a step or an advance wrong, as a
#: fraction of its length (`Simulation._check_clock_counts`): at a time whose float64 unit is
#: coarser, steps of that length are refused rather than counted as another length.
CLOCK_TOLERANCE = 2.0 ** -20
#: Two-level grid in a walled box (the discrete scheme, and the event scheme's queue): circles
#: larger than this many times the median radius are "large" when they are at most
#: TWO_LEVEL_MAX_FRACTION of all; the cells are then sized for the others, and each large circle
#: searches the block its reach spans (see circles.discrete and circles.event).
LARGE_RADIUS_RATIO = 4.0
TWO_LEVEL_MAX_FRACTION = 0.05
#: Overlap (relative to contact distance) above which from_arrays refuses a configuration.
INPUT_OVERLAP_TOLERANCE = 1e-9

_REAL = {"f32": ti.f32, "f64": ti.f64}
_NP_REAL = {"f32": np.float32, "f64": np.float64}


@dataclass
class State:
    """A copy of the state in creation order.

    pos (n, 2) and vel (n, 2): world units and units per second, float64.
    radius (n,), mass (n,): float64. color (n, 3): uint8 RGB.
    """

    pos: np.ndarray
    vel: np.ndarray
    radius: np.ndarray
    mass: np.ndarray
    color: np.ndarray


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


def default_dt(scheme, radius, vel):
    vmax = float(np.hypot(vel[:, 0], vel[:, 1]).max()) if len(vel) else 0.0
    if vmax <= 0:
        return 1.0
    if scheme == "event":
        dt = EVENT_STEP_RADII * float(radius.mean()) / vmax
    else:
        dt = DISCRETE_STEP_FRACTION * float(radius.min()) / vmax
    if not (0 < dt <= MAX_DT):
        raise ValueError(f"the largest speed {vmax:g} and the radii (mean {float(radius.mean()):g}) give a step "
                         f"dt = {dt:g}, beyond the steps from 0 to {MAX_DT:g} that a run takes: give dt, or measure "
                         "lengths and times in other units")
    return dt


#: Bytes per circle of the arrays a simulation holds on a CPU, by scheme and precision: the
#: least memory a scene needs, before the temporary arrays of its placement (counted by
#: tests/test_memory.py). An event queue split into parts (`_setup_parts`) holds PART_BYTES a
#: circle more.
ARRAY_BYTES = {("event", "f32"): 129, ("event", "f64"): 165, ("discrete", "f32"): 132, ("discrete", "f64"): 156}
PART_BYTES = {"f32": 41, "f64": 57}


def bytes_per_circle(n, scheme, precision):
    """ARRAY_BYTES of a CPU simulation of n circles, with PART_BYTES when its event queue will
    be split into parts (several threads, above the one-thread sizes; counted also where a
    spread of radii will give a two-level grid and one queue, which is known only after the
    radii are drawn)."""
    per = ARRAY_BYTES[(scheme, precision)]
    if scheme == "event" and EVENT_QUEUE_ON_CPU and not serial_loops(n, scheme) and count_parts() > 1:
        per += PART_BYTES[precision]
    return per


#: Bytes of the event log per collision it can keep (a float64 time and two int32 ids), and the
#: most collisions it can keep (Taichi's arrays count their items in 32 bits).
LOG_BYTES = 16
MOST_RECORDED = 2 ** 31 - 1


class NotEnoughMemory(MemoryError, ValueError):
    """A scene whose arrays would not fit in the memory available (`check_memory`)."""


#: Where Linux says how much memory this process may still take: the system's MemAvailable,
#: and the limit and use of a control group (version 2 and version 1), relative to the root.
_MEMINFO = "proc/meminfo"
_CGROUP_LIMITS = (("sys/fs/cgroup/memory.max", "sys/fs/cgroup/memory.current"),
                  ("sys/fs/cgroup/memory/memory.limit_in_bytes", "sys/fs/cgroup/memory/memory.usage_in_bytes"))


def available_memory(root="/") -> int | None:
    """Bytes of memory this process can take now, or None where the system does not say: the
    system's MemAvailable, or less when the process runs in a control group (a container)
    whose limit leaves less (the least of what each says)."""
    root = Path(root)
    available = None
    try:
        for line in (root / _MEMINFO).read_text().splitlines():
            if line.startswith("MemAvailable:"):
                available = int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    for limit_path, usage_path in _CGROUP_LIMITS:
        try:
            limit = int((root / limit_path).read_text().split()[0])  # "max" (no limit) is not a number
            usage = int((root / usage_path).read_text().split()[0])
        except (OSError, ValueError, IndexError):
            continue
        if limit < 1 << 60:  # version 1 writes a number near 2^63 for no limit
            left = max(limit - usage, 0)
            available = left if available is None else min(available, left)
    return available


def check_memory(n: int, scheme: str, precision: str, available=None, record_events=0):
    """Refuse, before anything is made, a CPU simulation of n circles whose arrays alone
    (`bytes_per_circle`, and LOG_BYTES for each collision its event log can keep) need more than the
    memory available (`available_memory`, or `available` bytes when given): it would otherwise
    be killed part way, or swap for hours. A GPU holds the arrays in its own memory, which
    Taichi reserves at start; it is not checked here."""
    if current_arch() != "cpu" or (scheme, precision) not in ARRAY_BYTES:
        return  # (an unknown scheme is refused where it is read)
    per = bytes_per_circle(n, scheme, precision)
    available = available_memory() if available is None else available
    if available is None:
        return
    need = n * per
    log = record_events * LOG_BYTES
    if need + log > available and log > 0:
        raise NotEnoughMemory(
            f"record_events = {record_events} keeps a log of {log / 1e9:.3g} GB ({LOG_BYTES} bytes a collision), "
            f"which with the {need / 1e9:.3g} GB of the circles' arrays is more than the {available / 1e9:.3g} "
            f"GB of memory available: keep at most {max(available - need, 0) // LOG_BYTES} collisions")
    if need > available:
        fix = f"at most {available // per} circles"
        if precision == "f64":
            fix += f" (in f32, {available // bytes_per_circle(n, scheme, 'f32')})"
        who = "circle needs" if n == 1 else "circles need"
        raise NotEnoughMemory(
            f"n = {n} {who} at least {need / 1e9:.3g} GB for their arrays ({per} bytes a circle with the "
            f"{scheme} scheme in {precision}), more than the {available / 1e9:.3g} GB of memory available: "
            f"simulate {fix}, or use a machine with more memory")


#: The most collisions a circle's counters hold (32-bit integers).
COUNT_MAX = 2 ** 31 - 1
#: The arrays of a file that `Simulation.save` writes.
SAVED_FIELDS = ("pos", "vel", "radius", "mass", "color", "box", "boundary", "scheme", "precision", "dt", "time",
                "steps", "pair_count", "wall_count", "virial", "wall_impulse")


def _read_saved(path):
    """The arrays of a file that `Simulation.save` wrote, by name; ValueError for any other file."""
    def refuse(why):
        return ValueError(f"{path} is not a simulation written by Simulation.save ({why}): load the file that "
                          "save wrote")

    try:
        f = np.load(path)
    except (FileNotFoundError, IsADirectoryError, PermissionError):
        raise
    except (ValueError, zipfile.BadZipFile):  # numpy takes what is neither .npy nor .npz for a pickle
        raise refuse("it is not an .npz archive") from None
    except (OSError, EOFError) as error:
        raise refuse(f"numpy cannot read it: {error}") from None
    if not isinstance(f, np.lib.npyio.NpzFile):
        raise refuse("it holds one array, not an .npz archive")
    with f:
        missing = [k for k in SAVED_FIELDS if k not in f.files]
        if missing:
            raise refuse(f"it lacks {', '.join(missing)}")
        try:
            d = {k: f[k] for k in SAVED_FIELDS}
        except (ValueError, OSError, EOFError, zipfile.BadZipFile) as error:  # a damaged member
            raise refuse(f"numpy cannot read its arrays: {error}") from None
    # Numbers of the right kind first: numpy casts complex numbers to reals with a warning (the
    # imaginary part dropped), and strings fail its arithmetic with messages of its own.
    kinds = {name: "iuf" for name in ("pos", "vel", "radius", "mass", "box", "dt", "time", "virial",
                                      "wall_impulse")}
    kinds.update(steps="iu", pair_count="iu", wall_count="iu")
    for name, kind in kinds.items():
        if d[name].dtype.kind not in kind:
            raise refuse(f"its {name} has type {d[name].dtype}, not {'integer' if kind == 'iu' else 'real number'}")
    if d["radius"].ndim != 1 or d["radius"].shape[0] == 0:
        raise refuse(f"its radius has shape {d['radius'].shape}, not (n,) for n >= 1 circles")
    n = d["radius"].shape[0]
    shapes = {"radius": (n,), "box": (2,), "boundary": (), "scheme": (), "precision": (), "dt": (), "time": (),
              "steps": (), "pair_count": (n,), "wall_count": (n,), "virial": (n,), "wall_impulse": (n,)}
    for name, shape in shapes.items():
        if d[name].shape != shape:
            raise refuse(f"its {name} has shape {d[name].shape}, not {shape}")
    for name in ("pair_count", "wall_count", "virial", "wall_impulse"):
        if not np.all(np.isfinite(d[name]) & (d[name] >= 0)):
            raise refuse(f"its {name} holds {d[name][~(np.isfinite(d[name]) & (d[name] >= 0))][0]}, not a "
                         "finite number >= 0")
    for name in ("pair_count", "wall_count"):  # a circle's counts are 32-bit integers in a run
        if np.any(d[name] > COUNT_MAX):
            raise refuse(f"its {name} holds {d[name].max()}, more than the {COUNT_MAX} a run counts for a circle")
    try:
        for name, allowed in (("boundary", BOUNDARIES), ("scheme", SCHEMES), ("precision", PRECISIONS)):
            _choice(name, str(d[name]), allowed)
        precision = str(d["precision"])
        box = check_box(tuple(float(x) for x in d["box"]))
        check_dt(float(d["dt"]))
        check_count("steps", int(d["steps"]))
        check_circles(d["pos"], d["vel"], d["radius"], box, precision)
        d["color"] = check_colors(d["color"], n)
        masses_for(d["mass"], d["radius"], precision)
        # A saved state lies inside the walls up to the rounding of its places.
        check_placed(d["pos"], d["radius"], box, str(d["boundary"]), place_slack(precision, box))
    except (ValueError, TypeError) as error:
        raise refuse(str(error)) from None
    if not (math.isfinite(float(d["time"])) and float(d["time"]) >= 0):
        raise refuse(f"its time {d['time']} is not a finite number >= 0")
    return d


def check_record_events(record_events, scheme):
    """record_events: a whole number >= 0 (the log's capacity) up to MOST_RECORDED, above 0 only
    with the event scheme, the one whose collisions are events at known times."""
    check_count("record_events", record_events, "the most collisions the log keeps; 0 keeps none")
    if record_events > MOST_RECORDED:
        raise ValueError(f"record_events = {record_events} is more than the {MOST_RECORDED} collisions a log "
                         "holds (its arrays count their items in 32 bits): keep fewer")
    if record_events > 0 and scheme != "event":
        raise ValueError(f"record_events = {record_events} with scheme {scheme!r}: only the event scheme logs its "
                         "collisions (the discrete scheme resolves overlaps at the end of each step, with no "
                         "time of contact); use scheme='event', or record_events=0")


class _WholeSteps:
    """Ctrl-C (SIGINT) during `advance` or `step` takes effect between two steps, never inside
    one: a step stopped between its kernels would leave circles moved to different times and
    the simulation's clock behind them.

    Used in the main thread only, where Python runs signal handlers (`_whole_steps`). Its first
    use puts this object in place of the SIGINT handler it finds, when that is a Python
    callable (Python's own, which raises KeyboardInterrupt, or a program's): outside steps it
    passes each press straight on; during a step it counts them, and passes them on when the
    step ends. Installed once, as a call of signal.signal costs microseconds (a tenth of a step
    of a few hundred circles): a program that puts in a handler of its own later takes its
    presses itself."""

    def __init__(self):
        self.previous = None  # the handler this one passes presses on to
        self.tried = False
        self.depth = 0  # calls of advance or step under way
        self.presses = 0

    def __call__(self, signum, frame):
        if self.depth > 0:
            self.presses += 1
        else:
            self.previous(signum, frame)

    def __enter__(self):
        if not self.tried:
            self.tried = True
            previous = signal.getsignal(signal.SIGINT)
            if callable(previous):
                self.previous = previous
                signal.signal(signal.SIGINT, self)
        self.depth += 1
        return self

    def between_steps(self):
        """Pass on the presses held during the step that just ended; once one raises (Python's
        handler does), the others go with it."""
        while self.presses > 0:
            self.presses -= 1
            try:
                self.previous(signal.SIGINT, None)
            except BaseException:
                self.presses = 0
                raise

    def __exit__(self, exc_type, exc, tb):
        self.depth -= 1
        if self.depth == 0:
            if exc_type is None:
                self.between_steps()
            else:
                self.presses = 0  # the call is ending with an exception already
        return False


class _AnyThread:
    """In place of `_WholeSteps` outside the main thread, whose steps a press never interrupts
    (Python raises KeyboardInterrupt in the main thread only)."""

    def __enter__(self):
        return self

    def between_steps(self):
        pass

    def __exit__(self, *exc_info):
        return False


_WHOLE_STEPS = _WholeSteps()
_ANY_THREAD = _AnyThread()


def _whole_steps():
    """The guard of a call of `advance` or `step` (`_WholeSteps`) in this thread."""
    return _WHOLE_STEPS if threading.current_thread() is threading.main_thread() else _ANY_THREAD


#: Counters of a simulation's work that its copies carry (see `Simulation.copy`).
WORK_COUNTERS = ("rounds", "sweeps", "cut_steps", "parts_run")


def _unpickle(cls, fields, scene, extras):
    """A pickled Simulation (`Simulation.__reduce__`) made again."""
    return cls._from_fields(fields, scene, extras)


#: Every Simulation that holds arrays of the running runtime (see `_release_all`).
_LIVE = weakref.WeakSet()


@on_restart
def _release_all():
    """Before `circles.init` restarts the runtime: every live simulation lets go of its arrays
    (see `backend.on_restart`); using one afterwards raises (`Simulation._live`)."""
    gc.collect()  # simulations no longer reachable go with their arrays
    for sim in list(_LIVE):
        sim._release()


class Simulation:
    """Circles in a box, advanced in fixed steps of simulated time.

    Made from a `Scene` (circles drawn and placed at random from its seed), from given circles
    (`from_arrays`), or from a file that `save` wrote (`load`). `advance(duration)` and
    `step(k)` move it; `state()`, `stats()`, `events()` and `render(width, height)` read it.
    """

    def __init__(self, scene: Scene, *, record_events: int = 0):
        """The circles of `scene`: radii, speeds, directions and colours drawn from its seed,
        places at random without overlap. With the event scheme, `record_events=CAPACITY` > 0
        keeps a log of up to CAPACITY collisions (`events`)."""
        if not isinstance(scene, Scene):
            raise TypeError(f"Simulation takes a circles.Scene, not {type(scene).__name__}")
        ensure_init()
        check_record_events(record_events, scene.scheme)
        check_memory(scene.n, scene.scheme, scene.precision, record_events=record_events)
        rng = np.random.default_rng(scene.seed)
        n = scene.n
        (rlo, rhi), (vlo, vhi) = scene.radius, scene.speed
        radius = rng.uniform(rlo, rhi, n) if rhi > rlo else np.full(n, rlo)
        speed = rng.uniform(vlo, vhi, n) if vhi > vlo else np.full(n, vlo)
        angle = rng.uniform(0.0, 2.0 * np.pi, n)
        vel = np.stack([speed * np.cos(angle), speed * np.sin(angle)], axis=1)
        color = random_colors(n, rng)
        mass = masses_for(scene.mass, radius, scene.precision)
        fraction = area_fraction(radius, scene.box)
        check_area_fraction(fraction, n, scene.box)
        periodic = scene.boundary == "periodic"
        pos = placement.place(radius, scene.box, periodic, scene.seed, rng, single=scene.precision == "f32")
        self.scene = scene
        self._setup(pos, vel, radius, mass, color, scene.box, scene.boundary, scene.scheme, scene.precision,
                    scene.dt, record_events)

    @classmethod
    def from_arrays(cls, pos, vel, radius, mass=None, box=(1.0, 1.0), boundary="walls", scheme="event",
                    precision="f64", dt=None, *, color=None, record_events: int = 0) -> "Simulation":
        """A simulation of given circles: pos and vel (n, 2), radius (n,) or one radius for all. mass:
        None (proportional to radius), a model name or (n,) masses."""
        ensure_init()
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
        sim = cls.__new__(cls)
        sim.scene = None
        sim._setup(pos, vel, radius, mass, color, box, boundary, scheme, precision, dt, record_events)
        sim._check_overlap()
        return sim

    # ----------------------------------------------------------------- set-up
    def _check_overlap(self):
        """Refuse circles that overlap by more than `overlap_tolerance`: given circles must be
        apart or in contact."""
        overlap = self._max_overlap()
        tolerance = overlap_tolerance(self.precision, self.box, self._radius)
        if overlap > tolerance:
            raise ValueError(f"circles overlap by {overlap:.3g} of their contact distance (tolerance {tolerance:.3g} "
                             f"in {self.precision}): place them apart or in contact")

    def _setup(self, pos, vel, radius, mass, color, box, boundary, scheme, precision, dt, record_events):
        self._runtime = runtime()
        _LIVE.add(self)
        n = radius.shape[0]
        self.n = n
        self.box = (float(box[0]), float(box[1]))
        self.boundary, self.scheme, self.precision = boundary, scheme, precision
        self.periodic = boundary == "periodic"
        self._real = _REAL[precision]
        self._np_real = _NP_REAL[precision]
        self.dt = float(dt) if dt is not None else default_dt(scheme, radius, vel)
        self.time = 0.0
        self.steps = 0
        # Callables f(sim) run after each step (or batch of steps), e.g. `trajectory.ImageTracker`.
        self.after_step = []
        self.rounds = 0
        self.sweeps = 0
        # Event steps cut short because a collision would outrun the grid (see circles.event).
        self.cut_steps = 0
        # Windows of event steps run with the queue split into parts (see `_queue_parts_step`).
        self.parts_run = 0
        self._mass = np.asarray(mass, dtype=np.float64).copy()
        self._mass_unit = mass_unit(self._mass)  # the kernels' masses and impulses are in it
        self._radius = np.asarray(radius, dtype=np.float64).copy()
        self._color = np.asarray(color, dtype=np.uint8).copy()
        self._rmax = float(self._radius.max())
        self._rmin = float(self._radius.min())
        self._same = self._same_circles()
        real = self._real
        self.pos = ti.Vector.ndarray(2, real, shape=n)
        self.vel = ti.Vector.ndarray(2, real, shape=n)
        self.radius = ti.ndarray(real, shape=n)
        self.inv_mass = ti.ndarray(real, shape=n)
        # Internally circles are kept in grid-cell order; `_ids[slot]` is the creation id.
        self.ids = ti.ndarray(ti.i32, shape=n)
        self._ids_cache = None
        self._color_cache = None  # colours in storage order, for render
        self._scratch = None  # spare arrays of each element type, for _reorder
        # Per-circle sums (a pair counts on its lower id): summed in a fixed order by stats(),
        # so they are the same whatever the thread count.
        self.pair_count = ti.ndarray(ti.i32, shape=n)
        self.wall_count = ti.ndarray(ti.i32, shape=n)
        self.virial = ti.ndarray(ti.f64, shape=n)
        self.wall_impulse = ti.ndarray(ti.f64, shape=n)
        # Small scenes on a CPU: every per-step loop on one thread (backend.serial_loops).
        self._serial = serial_loops(n, scheme)
        # The event queue (CPU) and the discrete scheme may use a two-level grid; the rounds do not.
        self._event_queue = scheme == "event" and EVENT_QUEUE_ON_CPU and current_arch() == "cpu"
        self._choose_levels(self._event_queue or scheme == "discrete")
        transposed = TRANSPOSE_WIDE_GRIDS and self.box[0] > self.box[1] and not self._two_level
        self.grid = Grid(n, self.box, self.periodic, serial=self._serial, transposed=transposed)
        self._upload(np.asarray(pos, dtype=np.float64), np.asarray(vel, dtype=np.float64), np.zeros(n, np.int32),
                     np.zeros(n, np.int32), np.zeros(n), np.zeros(n))
        self._speed_out = ti.ndarray(ti.f64, shape=2)
        # The largest speed of the state as it is (as `_max_speed` returns it), when an event
        # step's finish measured it (`event.finish`, CPU only); None: unknown, measure it.
        self._speed_view = launch.host_view(self._speed_out)
        self._known_speed = None
        self._overlap_out = ti.ndarray(ti.f64, shape=1)
        self._counters = ti.ndarray(ti.i32, shape=2)
        self._scalars = ti.ndarray(real, shape=2)
        reductions.fill_i32(self._counters, 0)
        # Work counters of the discrete rounds; slot discrete.NLARGE counts the large circles of a
        # two-level grid (both schemes).
        self._work = ti.ndarray(ti.i32, shape=discrete.PART_PICKS + max(count_parts(), 1))
        reductions.fill_i32(self._work, 0)
        self._record_cap = int(record_events)
        cap = max(1, self._record_cap)
        self._log_t = ti.ndarray(ti.f64, shape=cap)
        self._log_i = ti.ndarray(ti.i32, shape=cap)
        self._log_j = ti.ndarray(ti.i32, shape=cap)
        self._setup_two_level()
        if scheme == "event":
            self._alloc_event_arrays()
            self._setup_parts()
        self._steps_at_once = 1
        if scheme == "discrete":
            if current_arch() == "gpu":
                self._parallel_rounds = DISCRETE_MAX_ROUNDS
            elif self._serial:
                self._parallel_rounds = 0  # no parallel round: the whole step on one thread
            else:
                self._parallel_rounds = DISCRETE_PARALLEL_ROUNDS
            self._partner = ti.ndarray(ti.i32, shape=n)
            self._picked = ti.ndarray(ti.i32, shape=n)
            self._marked = ti.ndarray(ti.i32, shape=n)
            if not 0 < DISCRETE_CONTACTS <= discrete.MOST_CONTACTS:
                raise ValueError(f"DISCRETE_CONTACTS = {DISCRETE_CONTACTS} must be within 1 to "
                                 f"{discrete.MOST_CONTACTS} (discrete.MOST_CONTACTS)")
            # Contact m of every circle in one row: most circles overlap at most one other, so the
            # rounds read row 0 only.
            self._contacts = ti.ndarray(ti.i32, shape=(DISCRETE_CONTACTS, n))
            self._n_contacts = ti.ndarray(ti.i32, shape=n)
            self._work_lists = ti.ndarray(ti.i32, shape=(2, n))
            self._walled = ti.ndarray(ti.i32, shape=n)
            for arr in (self._picked, self._marked):
                reductions.fill_i32(arr, 0)
            # Equal radii and inverse masses as the kernels see them (`_same_circles`).
            self._uniform = DISCRETE_UNIFORM and self._same is not None
            # The first round of a step in one part per thread (`discrete._first_round_in_parts`).
            self._first_parts = DISCRETE_FIRST_IN_PARTS and count_parts() > 1
            # A step's stages on the CPU's threads as one team (`discrete.team_step`).
            self._team = DISCRETE_TEAM and current_arch() == "cpu" and not self._serial and count_parts() > 1
            if self._team:
                self._sync = ti.ndarray(ti.i32, shape=team.sync_slots())
            # Several steps a launch where a step runs on one thread (`discrete.serial_steps`).
            self._steps_at_once = DISCRETE_STEPS_AT_ONCE if self._parallel_rounds == 0 and not self._team else 1

    def _setup_parts(self):
        """The event queue's calendar heads, and the arrays of a queue split into parts
        (`event.split_parts`): on a CPU, with one grid level, when the step's loops run on
        several threads."""
        self._parts = self._event_queue and not self._serial and not self._two_level and count_parts() > 1
        self._split_wait = 0  # steps left before a split is tried again after one failed
        self._windows = 1  # of a step split into parts (see `_queue_parts_step`)
        n = self.n
        # The calendar's bucket heads (`event.queue_step`); each part's calendar takes one bucket
        # more than its share (see event.queue_parts). The queue's kernels take the width these
        # heads are made for as an argument.
        self._per_bucket = event.QUEUE_BUCKET_CIRCLES
        buckets = max(n // self._per_bucket, 1) if self._event_queue else 1
        if self._parts:
            buckets = n // self._per_bucket + event.MOST_PARTS + 1
        self._head = ti.ndarray(ti.i32, shape=buckets)
        if not self._parts:
            return
        self._label = ti.ndarray(ti.i32, shape=n)
        self._claimed = ti.ndarray(ti.i32, shape=max(n // PART_CLAIMS, 1))
        self._part_info = ti.ndarray(ti.i32, shape=event.part_info_size(event.MOST_PARTS))
        self._part_result = ti.ndarray(ti.f64, shape=event.MOST_PARTS)
        # The state at the step's start, put back when a collision would outrun the grid
        # (`_queue_parts_step`; every clock is 0 then), and the flags of its windows.
        self._backup = {name: self._like(getattr(self, name)) for name in PARTS_BACKUP_ORDER}
        self._sum_at = ti.ndarray(ti.i32, shape=1)
        self._make_sum_log(max(int(SUM_LOG_PER_CIRCLE * n), 1))
        self.sum_log_full = 0  # steps whose parts filled the sum log (then run from one queue)
        self._touched = ti.ndarray(ti.i32, shape=n)
        self._dirty_w = ti.ndarray(ti.i32, shape=n)
        # The split's absolute allowance on links, against round-off in the window's positions.
        self._link_allowance = LINK_ALLOWANCE_ULPS * float(np.finfo(self._np_real).eps) * max(self.box)

    def _same_circles(self):
        """(radius, inverse mass) as the kernels store them when every circle has the same ones,
        else None: the event queues then read them from an argument (`event.Same`), and the
        discrete kernels the first circle's (`discrete.per_circle`)."""
        radii = self._radius.astype(self._np_real)
        inv_mass = (self._mass_unit / self._mass).astype(self._np_real)
        if len(radii) and np.all(radii == radii[0]) and np.all(inv_mass == inv_mass[0]):
            return float(radii[0]), float(inv_mass[0])
        return None

    def _same_args(self):
        """(radius, inverse mass) of `_same_circles`, or zeros (unread) for circles of several,
        as the event kernels take them."""
        return self._same or (0.0, 0.0)

    def _make_sum_log(self, size):
        """The parts' sum log (`event.queue_parts`) of `size` entries: a circle's index (or a
        wall hit's entry) and an amount each."""
        self._sum_log = (ti.ndarray(ti.i32, shape=size), ti.ndarray(ti.f64, shape=size))

    def _sum_chunk(self, parts):
        """The entries a part takes from the sum log at a time: SUM_LOG_CHUNK, or fewer for a
        log too short for every part of several windows to hold a few chunks."""
        size = self._sum_log[0].shape[0]
        return max(1, min(SUM_LOG_CHUNK, size // (4 * parts * MOST_WINDOWS)))

    def _apply_sums(self):
        """The counts and sums of the windows run in parts so far this step, from the sum log."""
        event.apply_sums(*self._sum_log, self._sum_at, self.pair_count, self.virial, self.wall_count,
                         self.wall_impulse)

    def _part_shape(self):
        """(parts, rows of cells per part) of this step's split (`event.split_parts`); parts < 2: none
        (a periodic grid under 3 cells wide has no forward half of its cells to predict from)."""
        ncy = self.grid.ncy
        if self.grid.ncx < 3:
            return 0, 0
        threads = count_parts()
        # A multiple of the threads, so that they finish their share of the parts together.
        want = -(-max(self.n // event.PART_CIRCLES, threads) // threads) * threads
        parts = min(want, ncy // event.PART_MIN_ROWS, event.MOST_PARTS)
        if parts < 2:
            return 0, 0
        rows = -(-ncy // parts)
        return -(-ncy // rows), rows

    def _choose_levels(self, allowed):
        """Choose the grid: one level (cells as wide as the largest diameter), or, when `allowed`,
        two (see LARGE_RADIUS_RATIO, discrete.wide_row and event.build_coarse)."""
        stored = self._radius.astype(self._np_real).astype(np.float64)  # radii as the kernels see them
        r_cut = float(stored.max())
        small = stored[stored <= LARGE_RADIUS_RATIO * float(np.median(stored))]
        self._n_large = self.n - small.size
        self._two_level = bool(allowed and (not self.periodic) and
                               0 < self._n_large <= TWO_LEVEL_MAX_FRACTION * self.n)
        if self._two_level:
            r_cut = float(small.max())
        self._r_cut = r_cut

    def _setup_two_level(self):
        """The arrays of the grid's levels (`_choose_levels`)."""
        n_large = self._n_large
        self._large = ti.ndarray(ti.i32, shape=n_large if self._two_level else 1)
        self._spread = ti.ndarray(self._real, shape=2)
        self._spread.from_numpy(np.array([self._r_cut, self._radius.max()], dtype=self._np_real))
        # The coarse cells of the event queue's two-level grid (`event.build_coarse`), grown on demand.
        self._coarse_start = ti.ndarray(ti.i32, shape=1)
        self._coarse_ids = ti.ndarray(ti.i32, shape=n_large if self._two_level and self.scheme == "event" else 1)
        self._list_large()

    def _list_large(self):
        if self._two_level:
            discrete.list_large(self.radius, self._r_cut, self._large, self._work)

    def _alloc_event_arrays(self):
        n, real = self.n, self._real
        self.tau = ti.ndarray(real, shape=n)
        reductions.fill_real(self.tau, 0.0)
        # Each circle's event (time, partner). One queue on one thread starts a step with none
        # held (its finish clears them, `event.queue_step`), as here.
        self._ev_t = ti.ndarray(real, shape=n)
        self._ev_p = ti.ndarray(ti.i32, shape=n)
        # NEVER as the kernels write it (`ti.cast(NEVER, real)` of a literal, which is float32).
        reductions.fill_real(self._ev_t, float(np.float32(NEVER)))
        reductions.fill_i32(self._ev_p, NO_EVENT)
        self._dirty = ti.ndarray(ti.i32, shape=n)
        self._moved = ti.ndarray(ti.i32, shape=n)
        self._d1 = ti.ndarray(real, shape=n)
        # The key each round's bound carries (`event._bound_sweep`); the queue has no bounds.
        self._d_key = ti.ndarray(ti.i32, shape=(1 if self._event_queue else n, 2))
        self._active = (ti.ndarray(ti.i32, shape=n), ti.ndarray(ti.i32, shape=n))
        reductions.fill_i32(self._active[1], 0)
        # The queue's calendar (`event.queue_step`): each circle's back link (the bucket heads:
        # `_setup_parts`, which knows whether the queue is split).
        self._prv = ti.ndarray(ti.i32, shape=n if self._event_queue else 1)
        # The queue's list of neighbours that search again after an event (`event.queue_step`).
        self._pending = ti.ndarray(ti.i32, shape=n if self._event_queue else 1)
        # What a step changes, kept for the rounds to redo a step cut short; the queue needs no copy.
        self._backup = None if self._event_queue else {
            name: self._like(getattr(self, name))
            for name in ("pos", "vel", "pair_count", "wall_count", "virial", "wall_impulse")}

    @staticmethod
    def _like(arr):
        """A new ndarray of the same kind, element type and shape."""
        if isinstance(arr, ti.VectorNdarray):
            return ti.Vector.ndarray(arr.n, arr.dtype, shape=arr.shape)
        return ti.ndarray(arr.dtype, shape=arr.shape)

    def _cell_order(self, pos):
        """Creation ids sorted by grid cell (cells two largest radii wide, numbered as the grid numbers
        its cells), ties by id."""
        w, h = self.grid.extent
        side = max(2.0 * self._rmax, math.sqrt(w * h / max(self.n, 1)))
        ncx, ncy = max(1, int(w / side)), max(1, int(h / side))
        u, v = (pos[:, 1], pos[:, 0]) if self.grid.transposed else (pos[:, 0], pos[:, 1])
        cx = np.clip((u * (ncx / w)).astype(np.int64), 0, ncx - 1)
        cy = np.clip((v * (ncy / h)).astype(np.int64), 0, ncy - 1)
        return np.lexsort((np.arange(self.n), cy * ncx + cx))

    def _upload(self, pos, vel, pair_count, wall_count, virial, wall_impulse):
        """Store circles given in creation order, in cell order."""
        self._known_speed = None
        order = self._cell_order(pos)
        self._ids_cache = order
        self._color_cache = None
        self.grid.complete = False
        self.ids.from_numpy(order.astype(np.int32))
        self.pos.from_numpy(pos[order].astype(self._np_real))
        self.vel.from_numpy(vel[order].astype(self._np_real))
        self.radius.from_numpy(self._radius[order].astype(self._np_real))
        self.inv_mass.from_numpy((self._mass_unit / self._mass[order]).astype(self._np_real))
        self.pair_count.from_numpy(pair_count[order].astype(np.int32))
        self.wall_count.from_numpy(wall_count[order].astype(np.int32))
        # The impulses' sums in the kernels' unit of mass (exact: a power of two).
        self.virial.from_numpy(virial[order].astype(np.float64) / self._mass_unit)
        self.wall_impulse.from_numpy(wall_impulse[order].astype(np.float64) / self._mass_unit)

    @property
    def _ids(self):
        """Creation id of the circle in each slot (numpy), fetched after a reorder on the device."""
        if self._ids_cache is None:
            self._ids_cache = self.ids.to_numpy().astype(np.int64)
        return self._ids_cache

    def _creation_order(self, arr):
        """An internal per-circle array (numpy) put back in creation order."""
        arr = np.ascontiguousarray(arr)
        # Each row as one opaque item: numpy scatters 1-D items ten times faster than rows.
        row = arr.view(np.dtype((np.void, arr.strides[0]))).reshape(len(arr))
        out = np.empty_like(row)
        out[self._ids] = row
        return out.view(arr.dtype).reshape(arr.shape)

    def _download(self):
        """(pos, vel, pair_count, wall_count, virial, wall_impulse) in creation order, exactly as stored
        (the impulses' sums back in the masses' own unit, `mass_unit`)."""
        pos, vel, pair_count, wall_count, virial, wall_impulse = (
            self._creation_order(a.to_numpy()) for a in
            (self.pos, self.vel, self.pair_count, self.wall_count, self.virial, self.wall_impulse))
        return pos, vel, pair_count, wall_count, virial * self._mass_unit, wall_impulse * self._mass_unit

    def _reorder(self):
        """Sort the arrays by grid cell again, on the device, so that neighbours stay close in memory.

        Results do not depend on the memory order: event keys and the owners of per-circle
        sums are creation ids, and pair arithmetic is symmetric in the two circles. So the
        order inside a cell may follow thread timing (a GPU grid's atomic slots) without
        changing the state, and the order of the last step's grid serves: its positions are
        at most a step old (a third of the reorder's time was a grid build of its own).
        """
        if not self.grid.complete:
            self.grid.build(self.pos, 2.0 * self._rmax)
        if self._scratch is None:
            self._scratch = (self._like(self.pos), self._like(self.radius), self._like(self.ids),
                             self._like(self.virial))
        vec, real, i32, f64 = self._scratch
        reductions.permute_state(self.grid.sorted_ids, self.pos, self.vel, self.radius, self.inv_mass, self.ids,
                                 self.pair_count, self.wall_count, self.virial, self.wall_impulse, vec, real, i32, f64,
                                 self._serial)
        # Each array's permuted values are in the array before it in its kind's chain.
        (self.pos, self.vel, vec) = (vec, self.pos, self.vel)
        (self.radius, self.inv_mass, real) = (real, self.radius, self.inv_mass)
        (self.ids, self.pair_count, self.wall_count, i32) = (i32, self.ids, self.pair_count, self.wall_count)
        (self.virial, self.wall_impulse, f64) = (f64, self.virial, self.wall_impulse)
        self._scratch = (vec, real, i32, f64)
        self.grid.complete = False  # its slots name the circles of the old order
        self._ids_cache = self._color_cache = None
        self._list_large()

    # ---------------------------------------------------------------- stepping
    def _live(self):
        """Raise unless this simulation's arrays still exist: `circles.init` called again
        restarts Taichi's runtime, which frees every array made before it."""
        if self._runtime != runtime():
            raise RuntimeError("this Simulation was made before circles.init was called again, which restarted "
                               "the runtime and freed its arrays: make it again after circles.init (to carry a "
                               "state across, save it before the call and load it after)")

    def _release(self):
        """Let go of every Taichi array (and the grid and views that hold them); what describes
        the simulation (n, box, scheme, time, ...) stays, so it still prints."""
        keep = {"scene", "n", "box", "boundary", "scheme", "precision", "periodic", "_dt", "_time", "steps",
                "_runtime"}
        for name in list(vars(self)):
            if name not in keep:
                delattr(self, name)
        _LIVE.discard(self)

    @property
    def dt(self) -> float:
        """The step length in simulated seconds. It may be set between steps: to a number > 0,
        or to None for the one the scene would choose from the circles' speeds now."""
        return self._dt

    @dt.setter
    def dt(self, value):
        dt = check_dt(value)
        if dt is None:
            state = self.state()
            dt = default_dt(self.scheme, state.radius, state.vel)
        self._dt = dt

    @property
    def time(self) -> float:
        """The simulated clock in seconds. It may be set to any finite time >= 0, for example
        to start it again from 0 once its resolution has grown too coarse for the steps."""
        return self._time

    @time.setter
    def time(self, value):
        value = _scalar(value)
        if isinstance(value, bool) or not isinstance(value, Real) or not (0 <= value < math.inf):
            raise ValueError(f"time {value!r} must be a finite number of simulated seconds >= 0")
        self._time = float(value)

    def advance(self, duration: float):
        """Advance by `duration` of simulated time, ending exactly at the old time + duration."""
        self._live()
        duration = _scalar(duration)
        if isinstance(duration, bool) or not isinstance(duration, Real) or not math.isfinite(duration) \
                or duration < 0:
            raise ValueError(f"duration {duration!r} must be a finite number of simulated seconds >= 0")
        duration = float(duration)
        self._check_clock_counts(duration, "duration")
        end = self._time + duration
        stalled = 0  # steps in a row cut at their start (see below)
        with _whole_steps() as steps:
            while self._time < end:
                count = self._batch(self._dt, self._steps_at_once, end)
                if count > 1:
                    self._run_batch(self._dt, count)
                    if self.steps % REORDER_EVERY == 0:
                        self._reorder()
                    for hook in self.after_step:
                        hook(self)
                    steps.between_steps()
                    stalled = 0
                    continue
                left = end - self._time
                h = min(self._dt, left)
                if h < left:
                    self._check_clock_counts(h, "dt")
                done = self._step(h)
                # The last piece ends at `end` itself: time + (end - time) can round a unit
                # below it, which would cost a step of a unit's length more.
                before = self._time
                self._time = end if done == left else self._time + done
                self.steps += 1
                if self.steps % REORDER_EVERY == 0:
                    self._reorder()
                for hook in self.after_step:
                    hook(self)
                steps.between_steps()
                # A step cut at its start (done == 0) executed the events there up to one that
                # would outrun the grid (a pair touching and approaching at the start, say); the
                # next step is made for the speeds after it. Each such cut makes the largest
                # speed SPEED_MARGIN times larger, which the energy bounds: it cannot go on.
                stalled = stalled + 1 if done == 0 else 0
                if stalled > MOST_STALLED_STEPS:
                    raise RuntimeError(f"{stalled} steps in a row from time {self._time:g} were cut at their start by "
                                       "collisions that would outrun the grid, though each makes the largest speed "
                                       f"{SPEED_MARGIN} times larger (internal error)")
                if self._time == before and done > 0:
                    # A step cut short (a periodic box's limit, or a collision that would outrun
                    # the grid) below the clock's resolution: the next would be cut the same way.
                    raise ValueError(f"a step was cut to {done:g} s, below the resolution of the simulated clock "
                                     f"at time {self.time:g} ({np.spacing(self.time):g}): the clock cannot follow "
                                     f"the steps (the circles are at time {self.time:g} to within it); start the "
                                     "clock again with sim.time = 0, or, in a periodic box, lower the speeds or "
                                     "enlarge the box")
            self._time = end
        self._check_finite()
        return self

    def step(self, k: int = 1):
        """Take k steps of length dt."""
        self._live()
        k = _scalar(k)
        if isinstance(k, bool) or not isinstance(k, Real) or not math.isfinite(k) or int(k) != k or k < 0:
            raise ValueError(f"k = {k!r} must be a whole number of steps >= 0")
        dt = self._dt
        with _whole_steps() as steps:
            left = int(k)
            while left > 0:
                count = self._batch(dt, left)
                if count > 1:
                    self._run_batch(dt, count)
                else:
                    count = 1
                    self._check_clock_counts(dt, "dt")
                    done = 0.0
                    while done < dt:
                        done += self._step(dt - done)
                    self._time += dt
                    self.steps += 1
                left -= count
                if self.steps % REORDER_EVERY == 0:
                    self._reorder()
                for hook in self.after_step:
                    hook(self)
                steps.between_steps()
        self._check_finite()
        return self

    def _batch(self, h, most, end=None):
        """How many of the next steps, each of length h, run in one launch (`_steps_at_once`, on
        one thread; otherwise 1): at most `most`, none past the next reorder, and each one that
        the clock counts as h (`_check_clock_counts`) and, with `end` (`advance`), that ends
        before it."""
        if self._steps_at_once == 1:
            return 1
        most = min(most, self._steps_at_once, REORDER_EVERY - self.steps % REORDER_EVERY)
        time, count = self._time, 0
        while count < most and (end is None or h < end - time) and \
                abs(((time + h) - time) - h) <= CLOCK_TOLERANCE * h:
            time += h
            count += 1
        return count

    def _run_batch(self, h, count):
        """`count` steps of length h in as few launches as they allow (see `_batch`), the clock
        and the step count kept as a step at a time keeps them."""
        self._discrete_steps(h, count)
        for _ in range(count):
            self._time += h
        self.steps += count

    def _check_clock_counts(self, h, what):
        """Refuse a step (or an advance) of length h > 0 that the simulated clock, at its time
        now, would count off by more than CLOCK_TOLERANCE of h: the circles would move by h
        and the clock by another length (at time 1e14 float64 counts in units of 1/64, so a
        step of 0.01 counted as 0.015625)."""
        time = self._time
        moved = (time + h) - time
        if h > 0 and abs(moved - h) > CLOCK_TOLERANCE * h:
            unit = float(np.spacing(self.time + h))
            raise ValueError(f"{what} = {h:g} is too short for the simulated clock at time {self.time:g}, which "
                             f"counts in units of {unit:.3g} (it would count {h:g} as {moved:.6g}): give a {what} "
                             f"of at least {unit / CLOCK_TOLERANCE:.3g}, or start the clock again with sim.time = 0")

    def _step(self, h):
        if self.scheme == "event":
            return self._event_step(h)
        return self._discrete_step(h)

    def _max_speed(self):
        """The largest speed; raises when a circle is not finite. Measured by a pass over the
        circles unless the last event step's finish measured it (`_known_speed`)."""
        vmax = self._known_speed
        if vmax is None:
            vmax = reductions.max_speed(self.pos, self.vel, self._speed_out, self._serial)
        bad = -vmax if vmax < 0 else 0
        if bad:
            raise FloatingPointError(f"{int(bad)} circles have a non-finite position or velocity at time "
                                     f"{self.time}: the state is broken, the run stops here")
        return float(vmax)

    def _check_finite(self):
        self._max_speed()

    def _box_args(self):
        return self.box[0], self.box[1]

    def _event_step(self, h):
        """One step of the event scheme over [0, h]; returns the simulated time covered (h, or less when cut)."""
        vmax = self._max_speed()
        self._known_speed = None  # until the step's finish measures it again
        w, hgt = self.box
        if vmax == 0.0:
            return h
        vlim = vmax * SPEED_MARGIN
        reach = 2.0 * self._rmax + 2.0 * vlim * h
        if self.periodic:
            # The nearest image must be the only one within reach during the step.
            limit = 0.5 * min(w, hgt)
            if reach > limit:
                h = (limit - 2.0 * self._rmax) / (2.0 * vlim)
                reach = limit
        if self._two_level:
            self._build_two_levels(2.0 * vlim * h)
        else:
            self.grid.build(self.pos, reach)
        if self._event_queue:
            return self._queue_step(h, vlim)
        g = self.grid.args()
        real, periodic, record = self._real, self.periodic, self._record_cap > 0
        b = self._backup
        event.begin_step(self.pos, self.vel, self.pair_count, self.wall_count, self.virial, self.wall_impulse,
                         b["pos"], b["vel"], b["pair_count"], b["wall_count"], b["virial"], b["wall_impulse"],
                         self._dirty, self._moved, self._scalars, real, self._serial)
        log_count = int(self._counters.to_numpy()[1]) if record else 0
        t_end = h
        # A step that can end takes a few rounds; from JAM_CHECK_ROUNDS rounds on (and at every
        # doubling) its events so far are counted, and a jam stops it as on the queue.
        rounds, check = 0, JAM_CHECK_ROUNDS
        sweep_args = (self.pos, self.vel, self.radius, self.tau, self._ev_t, self._ev_p, self.ids, self._d1,
                      self._d_key, *self._active, *g, w, hgt)
        while True:
            tmin = event.begin_round(self.pos, self.vel, self.radius, self.tau, self.ids, self._ev_t, self._ev_p,
                                     self._dirty, self._moved, self._d1, self._d_key, *self._active, *g, w, hgt, t_end,
                                     vlim, self._scalars, real, periodic)
            if tmin > t_end:
                break
            # The bounds have settled when tmin >= 0; -1 asks for more sweeps.
            sweeps = event.SWEEPS_PER_LAUNCH
            while tmin < 0:
                if event.more_sweeps(*sweep_args, t_end, vlim, real, periodic) == 0:
                    break  # nothing decreased, so nothing was marked: both flag arrays are clear
                sweeps += event.SWEEPS_PER_LAUNCH
                if sweeps > MAX_BOUND_SWEEPS:
                    raise RuntimeError(f"causal bounds did not settle in {MAX_BOUND_SWEEPS} sweeps (internal error)")
            self.sweeps += sweeps
            executed = event.execute(self.pos, self.vel, self.radius, self.inv_mass, self.tau, self.ids, self._ev_t,
                                     self._ev_p, self._d1, self._d_key, self._dirty, self._moved, self.pair_count,
                                     self.wall_count, self.virial, self.wall_impulse, *g, w, hgt, t_end, vlim, self._time,
                                     self._scalars, self._counters, self._log_t, self._log_i, self._log_j, real,
                                     periodic, record)
            self.rounds += 1
            rounds += 1
            if rounds == check:
                check *= 2
                events = reductions.events_since(self.pair_count, self.wall_count, b["pair_count"], b["wall_count"])
                if events > event.most_events(self.n):
                    raise self._jammed()
            if executed < 0:
                # A collision would outrun the grid: redo the step up to it (see circles.event).
                # The redo may meet an earlier such collision and be redone again: one cut step.
                if t_end == h:
                    self.cut_steps += 1
                t_end = self._redo(log_count)
                continue
            if executed == 0:
                raise RuntimeError(f"event rounds made no progress at step time {self._scalars.to_numpy()[0]} "
                                   "(internal error)")
        event.finish(self.pos, self.vel, self.tau, t_end, w, hgt, self._speed_out, real, periodic, self._serial, False)
        return t_end

    def _build_two_levels(self, margin):
        """The event queue's two-level grid for a step in which two circles close in by at most
        `margin`: fine cells for the small circles, and coarse cells of whole blocks of fine
        cells, as wide as the reach of two large circles, that list the large ones."""
        w, hgt = self.box
        self.grid.build(self.pos, 2.0 * self._r_cut + margin)
        ncx, ncy = self.grid.ncx, self.grid.ncy
        reach = 2.0 * self._rmax + margin
        # A whole fine cell more than the reach, against round-off.
        mx = int(reach * ncx / w) + 1
        my = int(reach * ncy / hgt) + 1
        ncx_c, ncy_c = -(-ncx // mx), -(-ncy // my)
        if self._coarse_start.shape[0] < ncx_c * ncy_c + 1:
            self._coarse_start = ti.ndarray(ti.i32, shape=int(1.5 * ncx_c * ncy_c) + 1)
        event.build_coarse(self._large, self._work, self.grid.cell_of, self._coarse_start, self._coarse_ids, ncx, mx,
                           my, ncx_c, ncy_c)
        self._levels = (self._coarse_start, self._coarse_ids, ncx_c, ncy_c, mx, my, self._r_cut, margin)

    def _queue_step(self, h, vlim):
        """The rest of an event step over [0, h] from one queue (see `EVENT_QUEUE_ON_CPU`), in one
        launch that also brings every circle to the step's end; returns as `_event_step`. One
        queue takes no backup: a step cut short ends where the queue stopped (see
        circles.event). Split into parts when it can be (`_queue_parts_step`)."""
        if self._parts:
            if self._split_wait > 0:
                self._split_wait -= 1
            else:
                return self._queue_parts_step(h, vlim)
        return self._queue_step_whole(h, vlim)

    def _queue_step_whole(self, h, vlim, at_start=True):
        """`_queue_step` from one queue for all circles (`event.queue_step`); `at_start`: at the
        step's start (every circle's clock 0), not after some of its windows."""
        w, hgt = self.box
        real, periodic, record = self._real, self.periodic, self._record_cap > 0
        g = self.grid.args()
        two = self._two_level
        levels = self._levels if two else (self._coarse_start, self._coarse_start, 1, 1, 1, 1, 0.0, 0.0)
        # The rounds' arrays (bounds, flags) hold the queue's heap (circles, places, times) and
        # its lists' forward links.
        reached = event.queue_step(self.pos, self.vel, self.radius, self.inv_mass, self.tau, self.ids, self._ev_t,
                                   self._ev_p, self._dirty, *self._active, self._d1, self._head, self._moved,
                                   self._prv, self._pending, self.pair_count, self.wall_count, self.virial,
                                   self.wall_impulse,
                                   *g, w, hgt, h, vlim, self._time, self._counters, self._log_t, self._log_i,
                                   self._log_j, self._speed_out, *levels, event.most_events(self.n),
                                   self._per_bucket, *self._same_args(), real, periodic, record, two,
                                   self._serial, at_start, self._same is not None)
        self.rounds += 1
        # queue_step's finish left the largest speed in _speed_out; its return synchronised.
        self._known_speed = reductions.speed_in(self._speed_view)
        if reached == -2:
            raise self._jammed()
        if reached < 0:
            raise RuntimeError(f"the earliest event of the queue was not its partner's at step time {h} "
                               "(internal error)")
        if reached != h:
            self.cut_steps += 1
        return reached

    def _queue_parts_step(self, h, vlim):
        """`_queue_step` from one queue per part (`event.queue_parts`) in windows of the step: the
        parts of a window hold whole clusters of the circles that can meet within it
        (`event.split_parts`), and the shorter the window, the smaller the clusters. Every circle
        predicts its first event of the step in its part in the first window; before each later
        window, the circles whose searches met a neighbour in another part, and those paired
        with them, predict again (`event.repredict`). A step starts with as many windows as the
        last one ended with; a split that fails doubles them, up to MOST_WINDOWS, beyond which
        the rest of the step runs from one queue; every WINDOW_RETRY_STEPS steps, half as many
        are tried. A collision that would outrun the grid ends the step at its time for
        every circle, but the other parts may have gone past it: the step runs again from its
        start (`_backup`, which each part fills in the first window; the counts and sums change
        only when the step is done, from the sum log, `_apply_sums`) up to that time. The
        events up to it are the same (by causality), and so are their times (a pair's time of
        impact is computed from the later of its two clocks, which only their own events move),
        so the state is that of one queue bit for bit."""
        w, hgt = self.box
        record = self._record_cap > 0
        g = self.grid
        b = self._backup
        parts, rows_per = self._part_shape()
        if parts < 2:
            return self._queue_step_whole(h, vlim)
        if self.steps % WINDOW_RETRY_STEPS == 0 and self._windows > 1:
            self._windows //= 2
        cell_args = (g.cell_of, g.cell_start, g.sorted_ids, g.ncx, g.ncy, *spans(g.ncx, g.ncy, self.periodic))
        periodic = self.periodic
        log_count = int(self._counters.to_numpy()[1]) if record else 0
        end = h  # the step's end: h, or the time of a collision that would outrun the grid
        while True:
            t0 = 0.0
            done = 0  # windows of the step done, in the finest cut so far
            cut = end
            while t0 < end:
                if done > 0:
                    event.repredict(self.pos, self.vel, self.radius, self.tau, self.ids, self._ev_t, self._ev_p,
                                    self._dirty_w, self._touched, *cell_args, w, hgt, end, self._scalars,
                                    self._same_args()[0], self._real, periodic, self._same is not None)
                while True:
                    t1 = h if done + 1 >= self._windows else h * (done + 1) / self._windows
                    # The circles' reaches are kept in _d1, the queues' scratch of heap times.
                    if event.split_parts(self.pos, self.vel, self.tau, self.radius, self._label, self._claimed,
                                         self._d1, self._touched, self._dirty_w, self._part_info, *cell_args,
                                         rows_per, parts, w, hgt, t0, min(t1, end) - t0, vlim,
                                         self._link_allowance, self._same_args()[0], self._real, periodic,
                                         self._same is not None):
                        break
                    if self._windows >= MOST_WINDOWS:
                        self._split_wait = SPLIT_RETRY_STEPS
                        # The rest of the step from one queue, from the circles' clocks as they are,
                        # and from the sums of the windows done.
                        if done > 0:
                            self._apply_sums()
                        return self._rest_from_one_queue(end, h, vlim, done == 0)
                    self._windows *= 2
                    done *= 2
                event.queue_parts(self.pos, self.vel, self.radius, self.inv_mass, self.tau, self.ids, self._ev_t,
                                  self._ev_p, self._dirty, *self._active, self._d1, self._head, self._moved,
                                  self._prv, self._pending, self.pair_count, self.wall_count, self.virial,
                                  self.wall_impulse, self._touched, self._dirty_w,
                                  *(b[name] for name in PARTS_BACKUP_ORDER), *self._sum_log, self._sum_at,
                                  self._sum_chunk(parts), self._label, self._claimed,
                                  self._part_info, self._part_result, self._speed_out, *cell_args, rows_per,
                                  parts, w, hgt, end,
                                  min(t1, end), vlim, self._time, int(done == 0), self._counters, self._log_t,
                                  self._log_i, self._log_j, self._per_bucket, event.MOST_EVENTS_PER_CIRCLE,
                                  *self._same_args(), self._real, record, periodic,
                                  self._same is not None)
                self.parts_run += 1
                reached = self._part_result.to_numpy()[:parts]
                if np.any(reached == -2):
                    raise self._jammed()
                if np.any(reached == -3):
                    return self._sum_log_full(end, h, vlim, log_count)
                if np.any(reached < 0):
                    raise RuntimeError(f"the earliest event of a part's queue was not its partner's at step time "
                                       f"{h} (internal error)")
                cut = float(reached.min())
                if cut < end:
                    break
                t0 = t1
                done += 1
            if cut >= end:
                break
            # A collision at `cut` would outrun the grid: the step ends there, and runs again
            # from its start up to it (a redo may meet an earlier such collision: one cut step).
            if end == h:
                self.cut_steps += 1
            self._restore(log_count)
            end = cut
        h = end
        self.rounds += 1
        self._apply_sums()
        # The last window's parts moved their circles to the end and measured the largest speed
        # (`event.queue_parts`); reading their results synchronised.
        self._known_speed = reductions.speed_in(self._speed_view)
        return h

    def _sum_log_full(self, end, h, vlim, log_count):
        """A step in parts whose events filled the sum log: it runs again from its start (the
        counts and sums unchanged, the log dropped) up to `end` from one queue (which needs no
        log), and later steps have a log twice as long, up to SUM_LOG_MOST_PER_CIRCLE entries a
        circle. Returns as `_queue_parts_step`."""
        self.sum_log_full += 1
        self._restore(log_count)
        size, most = self._sum_log[0].shape[0], int(SUM_LOG_MOST_PER_CIRCLE * self.n)
        grown = min(2 * size, most)
        available = available_memory()
        # 12 bytes an entry; grown only with twice the new log's bytes to spare.
        if grown > size and (available is None or available > 2 * 12 * grown):
            self._make_sum_log(grown)
        return self._rest_from_one_queue(end, h, vlim, True)

    def _rest_from_one_queue(self, end, h, vlim, at_start):
        """A step in parts over [0, h], cut to `end` so far, run on to `end` from one queue
        (`_queue_step_whole`; `at_start`: from the step's start). Returns as `_queue_parts_step`;
        a cut the parts met is counted once."""
        cuts = self.cut_steps
        reached = self._queue_step_whole(end, vlim, at_start)
        if end < h:
            self.cut_steps = cuts  # counted when the parts first met the cut
        return reached

    def _jammed(self):
        """The error of an event step that executed more than event.MOST_EVENTS_PER_CIRCLE events
        per circle."""
        return RuntimeError(
            f"the event step from time {self.time} executed more than {event.most_events(self.n)} events "
            f"({event.MOST_EVENTS_PER_CIRCLE} per circle, or {event.MOST_EVENTS_ANY_STEP} in any step) without "
            "reaching its end. Most often circles jammed in a chain that spans the box "
            "(touching each other and the walls) collide without end at one instant: give them room (a lower "
            "area fraction, or radii that leave gaps) or use scheme='discrete'. A step can also hold that many "
            "collisions of its own (a circle M times as heavy as a light one pressing it against a wall makes "
            "about pi sqrt(M) of them): then give a shorter dt. The state is not usable after this.")

    def _redo(self, log_count):
        """Restore the state at the step's start for a step cut short at the collision that would
        outrun the grid; returns the cut time (see circles.event)."""
        cut = float(self._scalars.to_numpy()[1])
        self._restore(log_count)
        reductions.fill_i32(self._dirty, 1)
        reductions.fill_i32(self._moved, 1)
        self._set_scalars(NEVER, NEVER)
        return cut

    def _restore(self, log_count):
        """The state of the `_backup`, taken at the step's start, with every clock at 0 and
        `log_count` events logged."""
        for name, arr in self._backup.items():
            reductions.copy_vec(arr, getattr(self, name))
        reductions.fill_real(self.tau, 0.0)
        if self._record_cap > 0:
            self._set_counter(1, log_count)

    def _discrete_args(self):
        """What a discrete step's kernels take: the box, precision and boundary, the grid's cells
        (`Grid.prepare`) and spans, the circles' arrays, and whether the grid has two levels."""
        w, hgt = self.box
        real, periodic = self._real, self.periodic
        _, *cells = self.grid.prepare(2.0 * self._r_cut)
        rows, segs = spans(self.grid.ncx, self.grid.ncy, periodic)
        arrays = (self.pos, self.vel, self.radius, self.inv_mass, self.ids, self._partner, self._picked,
                  self._marked, self._contacts, self._n_contacts, self._work_lists, self._work, self.pair_count,
                  self.virial, self.wall_count, self.wall_impulse, self._walled)
        return w, hgt, real, periodic, cells, rows, segs, arrays, self._two_level

    def _discrete_step(self, h):
        if self._steps_at_once > 1:
            # One step of `serial_steps`, the same kernel as the batches' (one kernel to compile).
            self._discrete_steps(h, 1)
            return h
        w, hgt, real, periodic, cells, rows, segs, arrays, two = self._discrete_args()
        parallel = self._parallel_rounds
        if self._team:
            busy = discrete.team_step(*arrays, *cells, rows, segs, h, w, hgt, self._spread, self._large,
                                      self.grid.parts, self._sync, real, periodic, two, self._uniform,
                                      DISCRETE_FUSED_ROUNDS, DISCRETE_TEAM_SERIAL)
        else:
            busy = discrete.begin_step(*arrays, *cells, rows, segs, h, w, hgt, self._spread, self._large,
                                       self.grid.parts, real, periodic, two, self._uniform,
                                       DISCRETE_FUSED_ROUNDS, min(parallel, DISCRETE_FUSED_ROUNDS),
                                       self._first_parts)
        self.grid.complete = True
        self._more_rounds(busy, w, hgt, real, periodic, two, arrays, parallel)
        return h

    def _discrete_steps(self, h, count):
        """`count` discrete steps of length h on one thread, as many in a launch as settle within
        their fused rounds (`discrete.serial_steps`): the state of `count` calls of
        `_discrete_step`, bit for bit."""
        w, hgt, real, periodic, cells, rows, segs, arrays, two = self._discrete_args()
        while count > 0:
            begun = discrete.serial_steps(*arrays, *cells, rows, segs, h, w, hgt, self._spread, self._large,
                                          self.grid.parts, count, real, periodic, two, self._uniform,
                                          DISCRETE_FUSED_ROUNDS)
            self.grid.complete = True
            busy = begun < 0
            begun = abs(begun)
            count -= begun
            self.rounds += (begun - 1) * DISCRETE_FUSED_ROUNDS
            self._more_rounds(busy, w, hgt, real, periodic, two, arrays, 0)

    def _more_rounds(self, busy, w, hgt, real, periodic, two, arrays, parallel):
        """The rest of a discrete step whose fused rounds left work (`busy`): more rounds up to
        DISCRETE_MAX_ROUNDS, and the walls if they did not settle; counts the step's rounds."""
        done = DISCRETE_FUSED_ROUNDS
        # Most steps settle within the fused rounds; `busy` says whether another round has work.
        while busy and done < DISCRETE_MAX_ROUNDS:
            more = min(DISCRETE_FUSED_ROUNDS, DISCRETE_MAX_ROUNDS - done)
            busy = discrete.more_rounds(*arrays, *self.grid.args(), w, hgt, self._spread, real, periodic, two,
                                        self._uniform, more,
                                        min(max(parallel - done, 0), more))
            done += more
        self.rounds += done
        if busy and not periodic:
            # The round limit was reached: the walls were left for rounds that did not come.
            discrete.walls(self.pos, self.vel, self.radius, self.inv_mass, self.wall_count, self.wall_impulse,
                           self._walled, self._work, w, hgt, real, self._uniform)

    def _set_scalars(self, a, b):
        self._scalars.from_numpy(np.array([a, b], dtype=self._np_real))

    def _set_counter(self, k, value):
        c = self._counters.to_numpy()
        c[k] = value
        self._counters.from_numpy(c)

    # --------------------------------------------------------------- read-out
    def _pair_collisions(self):
        return int(self.pair_count.to_numpy().sum(dtype=np.int64))

    def _max_overlap(self):
        self.grid.build(self.pos, 2.0 * self._rmax)
        return float(reductions.max_overlap(self.pos, self.radius, *self.grid.args(), self.box[0], self.box[1],
                                            self._overlap_out, self.periodic))

    def state(self) -> State:
        """The circles now, as numpy float64 arrays in creation order: pos and vel (n, 2), radius
        and mass (n,), and color (n, 3) uint8."""
        self._live()
        pos = self._creation_order(self.pos.to_numpy()).astype(np.float64)
        vel = self._creation_order(self.vel.to_numpy()).astype(np.float64)
        return State(pos=pos, vel=vel, radius=self._radius.copy(), mass=self._mass.copy(), color=self._color.copy())

    def stats(self) -> dict:
        """Totals since the start, sums in float64: time; kinetic_energy (sum of m v^2 / 2);
        momentum (px, py); pair_collisions and wall_collisions (executed hits that changed
        velocities); virial, the sum over pair collisions of (r_i + r_j) |J| (J the impulse), and
        wall_impulse, the sum over wall hits of 2 m |v_n|, from which pressures follow: over a
        time t, the walls' P = delta wall_impulse / (t perimeter), and in 2D P A = N kT +
        delta virial / (2 t) with N kT the kinetic energy (the centres' box, W - 2r by H - 2r,
        in a walled box); max_overlap, the largest overlap of two circles as a fraction of
        their contact distance; pressure, compressibility (Z = P A / (N kT)) and wall_pressure,
        averaged since time 0 (NaN at time 0, wall_pressure NaN in a periodic box: see
        `circles.observables`)."""
        self._live()
        pos, vel, pair_count, wall_count, virial, wall_impulse = self._download()
        vel = vel.astype(np.float64)
        m = self._mass
        stats = {
            "time": self.time,
            "kinetic_energy": float(0.5 * np.sum(m * (vel[:, 0] ** 2 + vel[:, 1] ** 2))),
            "momentum": (float(np.sum(m * vel[:, 0])), float(np.sum(m * vel[:, 1]))),
            "pair_collisions": int(pair_count.sum(dtype=np.int64)),
            "wall_collisions": int(wall_count.sum(dtype=np.int64)),
            "virial": float(np.sum(virial)),
            "wall_impulse": float(np.sum(wall_impulse)),
            "max_overlap": self._max_overlap(),
        }
        stats.update(observables.since_start(stats, self.n, self.box, self.boundary, float(np.mean(self._radius))))
        return stats

    def events(self) -> np.ndarray:
        """The collisions the event scheme executed so far, when made with record_events=CAPACITY
        > 0: a (k, 3) float64 array of rows (time, i, j) sorted by time, then i, then j. i < j
        are the creation ids of a pair whose velocities changed; a wall hit has i the circle and
        j its wall: -1 (x = 0), -2 (x = W), -3 (y = 0) or -4 (y = H). Raises when more than
        CAPACITY collisions happened."""
        self._live()
        if self._record_cap <= 0:
            raise RuntimeError("events are recorded only with record_events=CAPACITY > 0: give it to Simulation, "
                               "Simulation.from_arrays or Simulation.load (a loaded run's log starts at the load)")
        k = int(self._counters.to_numpy()[1])
        if k > self._record_cap:
            raise RuntimeError(f"{k} events happened but record_events={self._record_cap}: "
                               "make the capacity larger")
        t = self._log_t.to_numpy()[:k]
        i = self._log_i.to_numpy()[:k].astype(np.float64)
        j = self._log_j.to_numpy()[:k].astype(np.float64)
        order = np.lexsort((j, i, t))
        return np.stack([t[order], i[order], j[order]], axis=1)

    def render(self, width: int = 1280, height: int = 720, color: str = "random", *, speed_scale=None) -> np.ndarray:
        """The circles drawn into a (height, width, 3) uint8 image (see `circles.canvas.render`)."""
        self._live()
        from .canvas import render, speed_scale_of
        # Drawing does not depend on the order of the circles (coverage sums are exact
        # integers), so the arrays go as stored, without putting them in creation order.
        if self._color_cache is None:
            self._color_cache = self._color[self._ids]
        # As stored (the canvas takes float32 or float64 alike); velocities only colour by speed.
        pos = self.pos.to_numpy()
        radius = self.radius.to_numpy()
        vel = self.vel.to_numpy().astype(np.float64) if color == "speed" else np.zeros(pos.shape, pos.dtype)
        if color == "speed" and speed_scale is None:
            # A sum over circles: taken in creation order, so it does not follow the storage order.
            speed_scale = speed_scale_of(self._creation_order(vel))
        return render(pos, vel, radius, self._color_cache, self.box, width, height, color, periodic=self.periodic,
                      speed_scale=speed_scale, check=False)

    # ------------------------------------------------------------ save / load
    def _fields(self) -> dict:
        """What `save` writes (`SAVED_FIELDS`): the state in creation order, exactly as stored,
        and what describes the run."""
        pos, vel, pair_count, wall_count, virial, wall_impulse = self._download()
        return dict(pos=pos, vel=vel, radius=self._radius.copy(), mass=self._mass.copy(), color=self._color.copy(),
                    box=np.array(self.box), boundary=self.boundary, scheme=self.scheme, precision=self.precision,
                    dt=self.dt, time=self.time, steps=self.steps, pair_count=pair_count, wall_count=wall_count,
                    virial=virial, wall_impulse=wall_impulse)

    def _extras(self) -> dict:
        """What a copy carries besides `_fields`: the event log and the work counters."""
        extras = {name: getattr(self, name) for name in WORK_COUNTERS}
        if self._record_cap > 0:
            extras["log"] = (self._record_cap, self._counters.to_numpy(), self._log_t.to_numpy(),
                             self._log_i.to_numpy(), self._log_j.to_numpy())
        return extras

    @classmethod
    def _from_fields(cls, d, scene=None, extras=None, record_events=0) -> "Simulation":
        """A simulation in the state `_fields` (or a file, `_read_saved`) gives, with `extras`
        (`_extras`) when given, else with a new event log of `record_events` collisions."""
        ensure_init()
        extras = extras or {}
        log = extras.get("log")
        capacity = record_events if log is None else log[0]
        check_memory(d["radius"].shape[0], str(d["scheme"]), str(d["precision"]), record_events=capacity)
        sim = cls.__new__(cls)
        sim.scene = scene
        sim._setup(d["pos"], d["vel"], d["radius"], d["mass"], d["color"], tuple(d["box"]), str(d["boundary"]),
                   str(d["scheme"]), str(d["precision"]), float(d["dt"]), capacity)
        sim._upload(d["pos"], d["vel"], d["pair_count"], d["wall_count"], d["virial"], d["wall_impulse"])
        sim.time = float(d["time"])
        sim.steps = int(d["steps"])
        for name in WORK_COUNTERS:
            if name in extras:
                setattr(sim, name, extras[name])
        if log is not None:
            for arr, values in zip((sim._counters, sim._log_t, sim._log_i, sim._log_j), log[1:]):
                arr.from_numpy(values)
        return sim

    def copy(self) -> "Simulation":
        """An independent simulation in the same state, with arrays of its own (and its own copy
        of the event log): it goes on as this one would, bit for bit. `copy.copy` and
        `copy.deepcopy` make the same (a copy sharing the arrays would be two simulations
        stepping one state)."""
        self._live()
        return type(self)._from_fields(self._fields(), self.scene, self._extras())

    def __copy__(self):
        return self.copy()

    def __deepcopy__(self, memo):
        return self.copy()

    def __reduce__(self):
        """Pickling (for multiprocessing, say) carries what `copy` does; unpickling makes the
        arrays in the receiving process's runtime (started with arch="auto" unless
        `circles.init` was called there)."""
        self._live()
        return _unpickle, (type(self), self._fields(), self.scene, self._extras())

    def save(self, path) -> Path:
        """Write the state exactly (in the working precision, creation order) to the file `path`
        as an .npz archive, whatever its suffix (numpy's own savez would add .npz to a name
        without it); returns the path. The archive is written beside it under a temporary name
        and then renamed, so a failed save leaves no partial file and keeps an older one."""
        self._live()
        path = Path(path)
        if path.is_dir():
            raise IsADirectoryError(f"cannot save to {path}: it is a folder; give a file's path, such as "
                                    f"{path / 'run.npz'}")
        if not path.parent.is_dir():
            raise FileNotFoundError(f"cannot save to {path}: the folder {path.parent} does not exist; make it first")
        fields = self._fields()
        # The temporary name holds at most 100 bytes of the file's (a name may take 255).
        short = path.name.encode()[:100].decode(errors="ignore")
        part = path.with_name(f".{short}.{os.getpid()}.part")
        try:
            with open(part, "wb") as f:
                np.savez(f, **fields)
            os.replace(part, path)
        finally:
            part.unlink(missing_ok=True)
        return path

    @classmethod
    def load(cls, path, *, record_events: int = 0) -> "Simulation":
        """A simulation from a file that `save` wrote: the same state, time and step count, so
        that it goes on as the saved one would have, bit for bit. A file that is not such an
        archive raises ValueError (a missing one FileNotFoundError). The event log is not
        saved: `record_events=CAPACITY` starts a new one, as in `Simulation`."""
        d = _read_saved(path)
        try:
            check_record_events(record_events, str(d["scheme"]))
        except ValueError as error:
            raise ValueError(f"{error} (the file {path} holds a run of the {d['scheme']} scheme)") from None
        sim = cls._from_fields(d, record_events=record_events)
        if sim.scheme == "event":  # its circles never overlap (the discrete scheme's do, by its errors)
            try:
                sim._check_overlap()
            except ValueError as error:
                sim._release()
                raise ValueError(f"{path} is not a simulation written by Simulation.save ({error}): load the file "
                                 "that save wrote") from None
        return sim

    def __repr__(self):
        return (f"Simulation(n={self.n}, box={self.box}, boundary={self.boundary!r}, scheme={self.scheme!r}, "
                f"precision={self.precision!r}, dt={self.dt:.4g}, time={self.time:.4g})")
