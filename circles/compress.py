"""Compression of hard disks by growing them: to an area fraction, or to jamming.

Lubachevsky and Stillinger's algorithm (J. Stat. Phys. 60, 561 (1990)), the one of Donev,
Torquato and Stillinger's PackLSD: the disks move and collide exactly, event by event, while
every radius grows in proportion, so the size ratios of a mixture stay as given
(`circles.growth` has the kernels and the collision rule).

- The rate: the mean diameter grows by `rate` thermal speeds sqrt(kT/m) per unit time (m the
  mean mass, kT the temperature at the start). Slow rates (1e-3 and below) let the fluid
  follow in equilibrium and crystallise equal disks; fast ones (0.1 and above) quench a glass.
- The temperature: growth pumps energy in; after every interval of 10 events a circle (0.1 /
  rate at rates above 0.01, at least 1, since fast growth heats faster) the speeds are scaled
  back to the starting kT. A periodic box starts with zero total momentum, which collisions
  keep.
- The pressure: over each interval, Z = PA / (NkT) = 1 + virial / (2 t N kT), the virial the
  sum of (r_i + r_j) |J| over pair collisions (`circles.observables`), kT the mean of the
  interval's first and last (in a walled box the walls' part is left out: it is of order the
  perimeter over the area).
- The end: `to` an area fraction, reached at the time the growth gives it; or "jammed", when
  Z passes `pressure_bound` (contacts then stand apart from gaps by about 1/Z of a diameter)
  or when an interval no longer moves the area fraction (the growth has stalled). A target
  beyond the packing's jamming point ends the same way, below the target.

The packing returned never overlaps: the radii at the end are trimmed to the closest pair's
distance if round-off brought any pair closer than contact (by a few units in the last place).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

#: The densest packing of equal disks, pi / sqrt(12): no target may pass it.
DENSEST = math.pi / math.sqrt(12.0)
#: Events per circle between two rescalings of the speeds (fewer at fast rates: `compress`).
INTERVAL_EVENTS = 10
#: The default bound on Z for a jammed packing, and the largest growth rate.
PRESSURE_BOUND = 1e6
MOST_RATE = 10.0
#: The fastest growth that ends in a jammed packing (faster growth arrests chains of disks
#: whose pressure diverges with few contacts behind it: see the docs' Compression page).
JAMMING_MOST_RATE = 0.01
#: The default rates: towards a target, and to jamming. A packing jammed at rate 0.01 falls
#: about 0.12 contacts a disk short of isostatic, one at 0.001 less than 0.02: the default jams
#: slowly enough to be isostatic (docs: Compression).
RATE = 0.01
JAMMING_RATE = 0.001
#: The cells are rebuilt when the radii have grown by this factor since they were laid out.
CELL_GROWTH = 1.05
#: The columns of the compression's stats table, a row per interval.
COLUMNS = ("time", "area_fraction", "temperature", "pair_collisions", "wall_collisions", "collision_rate",
           "compressibility", "reduced_pressure", "max_overlap")


@dataclass
class Compression:
    """What `compress` made: the packing (a `Simulation`), its area fraction and last
    compressibility Z, why it stopped ("target", "pressure" or "stalled"), the events and
    collisions it took, the simulated and wall time, and its stats rows (dicts of `COLUMNS`)."""

    simulation: object
    area_fraction: float
    compressibility: float
    stopped: str
    events: int
    pair_collisions: int
    time: float
    wall_s: float
    rows: list = field(default_factory=list)

    @property
    def jammed(self) -> bool:
        return self.stopped in ("pressure", "stalled")


def check_target(to, start_fraction):
    """`to` as "jammed" or an area fraction above the start's and at most DENSEST; else a
    ValueError naming the value, the limit and the fix."""
    if isinstance(to, str):
        if to != "jammed":
            raise ValueError(f"--to {to!r}: give an area fraction, or jammed")
        return to
    if isinstance(to, bool) or not isinstance(to, (int, float)) or not math.isfinite(to):
        raise ValueError(f"--to {to!r}: give an area fraction, or jammed")
    if to <= start_fraction:
        raise ValueError(f"--to {to:g} is not above the scene's area fraction {start_fraction:.6g}: compression "
                         "only grows the disks; give a larger target, or a scene of a lower area fraction")
    if to > DENSEST:
        raise ValueError(f"--to {to:g} is above the densest packing of disks, pi/sqrt(12) = {DENSEST:.6f}: give a "
                         "target at most that (a random packing jams near 0.82 to 0.84; use --to jammed)")
    return float(to)


def default_rate(to):
    """The rate a compression to `to` takes when none is given."""
    return JAMMING_RATE if to == "jammed" else RATE


def check_rate(rate):
    if isinstance(rate, bool) or not isinstance(rate, (int, float)) or not math.isfinite(rate) or rate <= 0:
        raise ValueError(f"--rate {rate!r} must be a growth rate > 0 (the mean diameter's growth in thermal speeds; "
                         f"1e-3 slow, 0.1 fast)")
    if rate > MOST_RATE:
        raise ValueError(f"--rate {rate:g} is above {MOST_RATE:g}: growth that fast outruns the disks' motion; give "
                         "a rate at most that")
    return float(rate)


def check_jamming_rate(rate):
    """Growth faster than JAMMING_MOST_RATE arrests the disks in chains that never jam: refused
    for --to jammed."""
    if rate > JAMMING_MOST_RATE:
        raise ValueError(f"--rate {rate:g} with --to jammed: growth faster than {JAMMING_MOST_RATE:g} arrests the disks "
                         "in chains whose pressure diverges with no packing behind it; give --rate "
                         f"{JAMMING_MOST_RATE:g} or less")
    return rate


def check_bound(bound):
    if isinstance(bound, bool) or not isinstance(bound, (int, float)) or not math.isfinite(bound) or bound < 100:
        raise ValueError(f"pressure bound {bound!r} must be a number >= 100 (a compressibility Z; 1e6 by default)")
    return float(bound)


class _Engine:
    """The state of a compression in numpy arrays and the kernels that move it."""

    def __init__(self, pos, vel, radius, mass, box, periodic):
        from . import growth

        self.growth = growth
        n = len(radius)
        self.n = n
        self.x = np.ascontiguousarray(pos, dtype=np.float64).copy()
        self.v = np.ascontiguousarray(vel, dtype=np.float64).copy()
        self.r0 = np.ascontiguousarray(radius, dtype=np.float64).copy()
        self.inv_m = 1.0 / np.asarray(mass, dtype=np.float64)
        self.box = (float(box[0]), float(box[1]))
        self.periodic = bool(periodic)
        self.tau = np.zeros(n)
        self.count = np.zeros(n, np.int32)
        self.ev_t = np.zeros(n)
        self.ev_p = np.zeros(n, np.int32)
        self.ev_c = np.zeros(n, np.int32)
        self.nxt = np.zeros(n, np.int32)
        self.prv = np.zeros(n, np.int32)
        self.cell = np.zeros(n, np.int32)
        self.heap = np.zeros(n, np.int32)
        self.where = np.zeros(n, np.int32)
        self.totals = np.zeros(7)
        self.log = np.zeros((1, 3))  # the event log (`growth.run`): its first event, unless a caller gives more rows
        self.params = np.zeros(8)
        self.head = np.zeros(1, np.int32)

    def layout(self, now, g, largest_scale):
        """Cells at least the largest contact distance at `largest_scale` wide, the clocks all
        `now`, every event predicted."""
        w, h = self.box
        reach = 2.0 * float(self.r0.max()) * largest_scale * (1.0 + 1e-9)
        ncx, ncy = max(1, int(w / reach)), max(1, int(h / reach))
        if self.head.size != ncx * ncy:
            self.head = np.zeros(ncx * ncy, np.int32)
        self.params[:] = (w, h, g, ncx, ncy, w / ncx, h / ncy, now)
        self.growth.start(self.x, self.v, self.tau, self.r0, self.count, self.ev_t, self.ev_p, self.ev_c, self.head,
                          self.nxt, self.prv, self.cell, self.heap, self.where, self.params, self.periodic)

    def run(self, end, most):
        self.growth.run(self.x, self.v, self.tau, self.r0, self.inv_m, self.count, self.ev_t, self.ev_p, self.ev_c,
                        self.head, self.nxt, self.prv, self.cell, self.heap, self.where, self.params, self.totals,
                        self.log, end, most, self.periodic)
        return float(self.totals[self.growth.TIME])

    def synchronise(self, now):
        """Every circle to time `now` (inside the box, when periodic)."""
        self.x += self.v * (now - self.tau)[:, None]
        self.tau[:] = now
        if self.periodic:
            self.x %= self.box
            self.x[self.x >= self.box] = 0.0


def _kinetic(v, mass):
    return 0.5 * float(np.sum(mass * (v[:, 0] ** 2 + v[:, 1] ** 2)))


def largest_scale(pos, r0, box, periodic):
    """The largest factor every radius may be multiplied by with no pair overlapping (and, in a
    walled box, no circle through a wall), as floats compute it: the packing's radii are r0
    times this at most."""
    from scipy.spatial import cKDTree

    pos = np.asarray(pos, np.float64)
    w, h = box
    reach = 2.0 * float(r0.max())
    scale = math.inf
    if periodic:
        tree = cKDTree(np.mod(pos, box) % np.asarray(box), boxsize=box)
    else:
        tree = cKDTree(pos)
        scale = float(np.min(np.minimum.reduce([pos[:, 0], w - pos[:, 0], pos[:, 1], h - pos[:, 1]]) / r0))
    # The nearest pairs: within the largest diameter at the scale the nearest pair allows.
    _, first = tree.query(pos, k=2)
    d0 = pos[first[:, 1]] - pos
    if periodic:
        d0 -= np.asarray(box) * np.round(d0 / np.asarray(box))
    bound = float(np.min(np.hypot(d0[:, 0], d0[:, 1]) / (r0 + r0[first[:, 1]])))
    pairs = tree.query_pairs(reach * bound * 1.000001, output_type="ndarray")
    if len(pairs):
        i, j = pairs[:, 0], pairs[:, 1]
        d = pos[j] - pos[i]
        if periodic:
            d -= np.asarray(box) * np.round(d / np.asarray(box))
        scale = min(scale, float(np.min(np.hypot(d[:, 0], d[:, 1]) / (r0[i] + r0[j]))))
    # Down a few units in the last place, until every pair and wall holds in floating point.
    for _ in range(64):
        r = r0 * scale
        ok = True
        if len(pairs):
            ok = bool(np.all(np.hypot(d[:, 0], d[:, 1]) >= r[i] + r[j]))
        if not periodic:
            ok = ok and bool(np.all((pos[:, 0] >= r) & (pos[:, 0] <= w - r) & (pos[:, 1] >= r) & (pos[:, 1] <= h - r)))
        if ok:
            return scale
        scale = math.nextafter(scale, 0.0)
    return scale


def contact_number(simulation, tolerance=1e-4):
    """(mean contacts a disk, disks kept) of a packing once its rattlers are taken away: pairs
    whose gap is below `tolerance` of their contact distance are contacts, and disks with fewer
    than 3 (which a jammed packing does not hold in place) go, one round after another, until
    none is left. A jammed packing of frictionless disks in a periodic box is isostatic:
    2 (N' - 1) + 1 contacts among its N' disks, a mean of 4 - 2/N'."""
    from scipy.spatial import cKDTree

    state = simulation.state()
    pos, r, box = state.pos, state.radius, np.asarray(simulation.box, np.float64)
    periodic = simulation.boundary == "periodic"
    tree = cKDTree(pos % box, boxsize=box) if periodic else cKDTree(pos)
    pairs = tree.query_pairs(2 * r.max() * (1 + tolerance), output_type="ndarray")
    if not len(pairs):
        return 0.0, 0
    d = pos[pairs[:, 1]] - pos[pairs[:, 0]]
    if periodic:
        d -= box * np.round(d / box)
    touching = pairs[np.hypot(d[:, 0], d[:, 1]) / (r[pairs[:, 0]] + r[pairs[:, 1]]) - 1 < tolerance]
    alive = np.ones(len(r), bool)
    while True:
        kept = touching[alive[touching[:, 0]] & alive[touching[:, 1]]]
        count = np.bincount(kept.ravel(), minlength=len(r))
        rattlers = alive & (count < 3)
        if not rattlers.any():
            return (2 * len(kept) / alive.sum() if alive.any() else 0.0), int(alive.sum())
        alive &= ~rattlers


def compress(source, to, rate=None, *, pressure_bound=PRESSURE_BOUND, on_row=None):
    """Grow the disks of `source` (a `Scene` of the event scheme, or a `Simulation`) until the
    area fraction `to`, or until they jam (`to="jammed"`), at growth rate `rate` (by default
    RATE, or JAMMING_RATE to jamming); returns a `Compression`. `on_row(row)` is called with
    each interval's stats row as it comes."""
    from . import placement
    from .backend import ensure_init
    from .scene import Scene
    from .simulation import Simulation

    ensure_init()
    rate = check_rate(default_rate(to) if rate is None else rate)
    check_bound(pressure_bound)
    if isinstance(source, Scene):
        if source.scheme != "event":
            raise ValueError("compression needs the event scheme (scheme = \"event\"): growing disks meet at times "
                             "a quadratic gives, which fixed steps would miss")
        pos, vel, radius, mass, color = placement.scene_circles(source)
        box, boundary = source.box, source.boundary
    elif isinstance(source, Simulation):
        if source.scheme != "event":
            raise ValueError("compression needs the event scheme: this simulation runs the discrete one")
        state = source.state()
        pos, vel, radius, mass, color = state.pos, state.vel, state.radius, state.mass, state.color
        box, boundary = tuple(float(b) for b in source.box), source.boundary
    else:
        raise TypeError(f"compress takes a circles.Scene or a Simulation, not {type(source).__name__}")
    pos, vel, radii, done = grow(pos, vel, radius, mass, box, boundary, to, rate, pressure_bound=pressure_bound,
                                 on_row=on_row)
    done.simulation = Simulation.from_arrays(pos, vel, radii, mass, box=box, boundary=boundary, scheme="event",
                                             precision="f64", color=color)
    return done


def grow(pos, vel, radius, mass, box, boundary, to, rate, *, pressure_bound=PRESSURE_BOUND, on_row=None):
    """The arrays of `compress`, grown: (positions, velocities, radii) reached, float64, and the
    `Compression` with no simulation yet. The rate is checked here; the event engine's kernels
    need Taichi started."""
    from .observables import temperature
    from .scene import area_fraction

    rate = check_rate(rate)
    pressure_bound = check_bound(pressure_bound)
    n = len(radius)
    radius = np.asarray(radius, np.float64)
    mass = np.asarray(mass, np.float64)
    periodic = boundary == "periodic"
    start_fraction = area_fraction(radius, box)
    to = check_target(to, start_fraction)
    if to == "jammed":
        check_jamming_rate(rate)
    vel = np.array(vel, np.float64)
    if periodic:
        vel -= np.sum(mass[:, None] * vel, axis=0) / np.sum(mass)
    total_mass = float(np.sum(mass))

    def kt(v):
        return float(temperature(_kinetic(v, mass), tuple(np.sum(mass[:, None] * v, axis=0)), total_mass, n, boundary))

    kt0 = kt(vel)
    if not kt0 > 0:
        raise ValueError("compression needs moving circles (a temperature above 0): give the scene speeds above 0")
    g = rate * math.sqrt(kt0 / float(np.mean(mass))) / float(np.mean(2.0 * radius))
    final_scale = math.sqrt(to / start_fraction) if to != "jammed" else math.sqrt(DENSEST / start_fraction)
    equal = bool(np.all(radius == radius[0]))

    engine = _Engine(pos, vel, radius, mass, box, periodic)
    started = time.perf_counter()
    elapsed = 0.0  # simulated time
    grown = 1.0  # the radii now over the radii at the start
    rows = []
    stopped = None
    z = math.nan
    pairs_before = 0
    per_interval = int(n * min(INTERVAL_EVENTS, max(1.0, 0.1 / rate)))
    while stopped is None:
        # Each interval starts afresh from the radii reached, on a clock of its own: the speeds
        # were rescaled, so every event is predicted again.
        left = final_scale / grown  # the growth left to the target
        cell_scale = min(left, CELL_GROWTH)
        engine.layout(0.0, g, cell_scale)
        end = min((left - 1.0) / g, (cell_scale - 1.0) / g)
        virial_before = float(engine.totals[engine.growth.VIRIAL])
        reached = engine.run(end, per_interval)
        engine.synchronise(reached)
        kt_end = kt(engine.v)
        step = 1.0 + g * reached
        engine.r0 *= step
        engine.tau[:] = 0.0
        grown *= step
        elapsed += reached
        virial = float(engine.totals[engine.growth.VIRIAL]) - virial_before
        pairs = int(engine.totals[engine.growth.PAIRS])
        fraction = start_fraction * grown ** 2
        if reached > 0:
            z = float(1.0 + virial / (2.0 * reached * n * 0.5 * (kt0 + kt_end)))
            row = {"time": elapsed, "area_fraction": fraction, "temperature": float(kt_end), "pair_collisions": pairs,
                   "wall_collisions": int(engine.totals[engine.growth.WALLS]),
                   "collision_rate": 2.0 * (pairs - pairs_before) / (n * reached), "compressibility": z,
                   "reduced_pressure": z * 4.0 * fraction / math.pi if equal else math.nan,
                   "max_overlap": max(0.0, 1.0 - largest_scale(engine.x, engine.r0, box, periodic))}
            rows.append(row)
            if on_row is not None:
                on_row(row)
        pairs_before = pairs
        engine.v *= math.sqrt(kt0 / kt_end)
        if reached >= end and end == (left - 1.0) / g:
            stopped = "target" if to != "jammed" else "stalled"
        elif z > pressure_bound:  # jammed, or (with a target) jammed before it
            stopped = "pressure"
        elif step == 1.0:
            stopped = "stalled"
    scale = final_scale if stopped == "target" else grown
    while stopped == "target" and area_fraction(radius * scale, box) > to:
        scale = math.nextafter(scale, 0.0)  # the target, not a unit in the last place above it
    radii = radius * scale
    radii *= min(1.0, largest_scale(engine.x, radii, box, periodic))
    return engine.x, engine.v, radii, Compression(
        simulation=None, area_fraction=area_fraction(radii, box), compressibility=z, stopped=stopped,
        events=int(engine.totals[engine.growth.EVENTS]), pair_collisions=int(engine.totals[engine.growth.PAIRS]),
        time=elapsed, wall_s=time.perf_counter() - started, rows=rows)


# ---- the command line ---------------------------------------------------------------------

DESCRIPTION = ("Grow the disks of a scene (the showcase, or SCENE.toml, with the scene flags over it) while they "
               "collide, Lubachevsky-Stillinger style, to an area fraction or to jamming; write the packing as a GSD "
               "frame that circles run --from and HOOMD-blue read, and a stats row per interval.")


def add_compress_command(commands):
    """The `circles compress` subcommand, on the command line's subparsers (its help)."""
    _arguments(commands.add_parser("compress", help="grow the disks to an area fraction or to jamming",
                                   description=DESCRIPTION))


def _target(text):
    if text == "jammed":
        return text
    try:
        return float(text)
    except ValueError:
        raise ValueError(f"--to {text}: give an area fraction such as 0.8, or jammed") from None


def _arguments(parser):
    from .sceneflags import add_scene_flags

    parser.add_argument("scene", nargs="?", metavar="SCENE.toml", help="scene file: Scene fields at top level")
    add_scene_flags(parser)
    parser.add_argument("--from", dest="from_", metavar="FILE.gsd[:FRAME]",
                        help="compress the circles of a frame of a GSD file (circles.frames) in place of a scene")
    grow = parser.add_argument_group("compression")
    grow.add_argument("--to", required=True, metavar="PHI|jammed",
                      help="the area fraction to stop at, or jammed: until Z passes --pressure-bound")
    grow.add_argument("--out", required=True, metavar="PACKED.gsd", help="the packing, one GSD frame")
    grow.add_argument("--rate", type=float, metavar="R",
                      help=f"growth of the mean diameter per unit time, in thermal speeds sqrt(kT/m) (default {RATE:g}; "
                           f"{JAMMING_RATE:g} and at most {JAMMING_MOST_RATE:g} with --to jammed)")
    grow.add_argument("--pressure-bound", type=float, default=PRESSURE_BOUND, metavar="Z",
                      help=f"--to jammed stops when Z = PA/NkT passes this (default {PRESSURE_BOUND:g})")
    grow.add_argument("--stats", metavar="RUN.csv", help="a CSV row per interval of the compression")
    grow.add_argument("--force", action="store_true", help="overwrite existing --out and --stats files")


def _check(args, made):
    """(scene, target, out, stats) from the arguments, or a UsageError: everything checked
    before any disk moves."""
    from .command import UsageError
    from .sceneflags import SHOWCASE_SCENE, frame_source, random_scene, read_scene_file, scene_from_frame
    from .scenefile import lists_circles
    from .trajectory import check_path

    fields = read_scene_file(args.scene)[0] if args.scene else dict(SHOWCASE_SCENE)
    source = frame_source(args, fields)
    if source is not None:
        scene = scene_from_frame(source, fields if args.scene else {}, args)
    elif args.scene and lists_circles(fields):
        raise UsageError(f"{args.scene} lists its circles ([[circle]] entries): circles compress grows a random "
                         "scene or a GSD frame (--from); give n, radius and the other Scene fields")
    else:
        scene = random_scene(fields, args)
    if scene.scheme != "event":
        raise UsageError("--scheme discrete: compression needs the event scheme, whose times of impact account for "
                         "the growth; drop --scheme or give --scheme event")
    try:
        to = _target(args.to)
        if args.rate is None:
            args.rate = default_rate(to)
        check_rate(args.rate)
        check_bound(args.pressure_bound)
        if to == "jammed":
            check_jamming_rate(args.rate)
        else:
            check_target(to, starting_fraction(scene))
        out = check_path(args.out, args.force, ".gsd", "--out", made, resumable=False)
        stats = None if args.stats is None else check_path(args.stats, args.force, ".csv", "--stats", made,
                                                           resumable=False)
    except ValueError as error:
        raise UsageError(str(error)) from None
    return scene, to, out, stats


def starting_fraction(scene):
    """The area fraction a scene (a `Scene`, on average) or a `CircleList` starts at."""
    if hasattr(scene, "pos"):
        from .scene import area_fraction

        return area_fraction(scene.radius, scene.box)
    return scene.area_fraction


def write_packing(compression, out, run=None):
    """The packing of `compression` as one GSD frame at `out` (replaced whole), with `run` (a
    dict) as its ``log/circles/run``."""
    from .storage import replaced_whole
    from .trajectory import GSDWriter

    with replaced_whole(out) as part:
        writer = GSDWriter(part, "w", tracker=False, run=run)
        try:
            writer.write(compression.simulation)
        finally:
            writer.close()


def write_stats(rows, path):
    """The compression's rows as a CSV table at `path` (replaced whole)."""
    import csv

    from .storage import replaced_whole

    with replaced_whole(path) as part:
        with open(part, "w", newline="", encoding="utf-8") as file:
            writer = csv.DictWriter(file, COLUMNS, lineterminator="\n")
            writer.writeheader()
            for row in rows:
                writer.writerow({k: repr(v) if isinstance(v, float) else v for k, v in row.items()})


def main(argv):
    """`circles compress ...` (argv from "compress" on): the exit status (0 done, 2 bad input,
    1 failed, 130 Ctrl-C)."""
    import sys

    from . import backend
    from .command import EXIT_BAD_INPUT, EXIT_FAILED, EXIT_INTERRUPTED, Parser, UsageError, remove_made

    parser = Parser(prog="circles compress", description=DESCRIPTION)
    _arguments(parser)
    made = []
    try:
        args = parser.parse_args(argv[1:])
        scene, to, out, stats = _check(args, made)
    except UsageError as error:
        remove_made(made)
        print(f"circles: error: {error}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except SystemExit as exit_:  # --help
        return exit_.code if isinstance(exit_.code, int) else 0
    try:
        if not backend._state["initialized"]:
            backend.init("cpu")  # one thread carries the events; the CPU holds the state between intervals
        target = "jamming" if to == "jammed" else f"area fraction {to:g}"
        from .sceneflags import frame_source
        print(f"compress    {scene.n} circles in a {scene.boundary} box of {scene.box[0]:g} x {scene.box[1]:g}, to "
              f"{target} at rate {args.rate:g}", flush=True)
        source = scene
        if hasattr(scene, "pos"):  # a GSD frame's circles
            from .simulation import Simulation
            source = Simulation.from_arrays(scene.pos, scene.vel, scene.radius, scene.mass, box=scene.box,
                                            boundary=scene.boundary, scheme="event", precision="f64",
                                            color=scene.color)
        done = compress(source, to, args.rate, pressure_bound=args.pressure_bound)
        why = {"target": "the target reached", "pressure": f"Z passed {args.pressure_bound:g}",
               "stalled": "the growth stalled"}[done.stopped]
        if to != "jammed" and done.stopped != "target":
            why = f"jammed below the target {to:g}: {why}"
        print(f"done        area fraction {done.area_fraction:.6f}, Z {done.compressibility:.4g} ({why}); "
              f"{done.events} events, {done.pair_collisions} pair collisions in {done.wall_s:.1f} s", flush=True)
        made_of = {"from": frame_source(args, {})} if hasattr(scene, "pos") else {"scene": scene.to_dict()}
        run = {"compress": {**made_of, "to": to, "rate": args.rate,
                            "pressure_bound": args.pressure_bound, "stopped": done.stopped,
                            "area_fraction": done.area_fraction, "compressibility": done.compressibility}}
        write_packing(done, out, run)
        written = [str(out)]
        if stats is not None:
            write_stats(done.rows, stats)
            written.append(str(stats))
        print(f"wrote       {', '.join(written)}")
        made.clear()
        return 0
    except KeyboardInterrupt:
        print("circles: stopped by Ctrl-C; nothing written", file=sys.stderr)
        return EXIT_INTERRUPTED
    except (FloatingPointError, RuntimeError, OSError, ValueError) as error:
        print(f"circles: the compression failed: {error}", file=sys.stderr)
        return EXIT_FAILED
    finally:
        remove_made(made)
