"""Simulation: the state of a scene, its clock, and the public interface that advances and reads it.

A `Simulation` holds the circles' arrays (positions, velocities, radii, inverse masses, ids,
and per-circle counts and sums), the grid, the clock and the event log, and calls its scheme's
stepper (`circles.schemes`, `circles.stepper`) for each step: the event scheme's
(`circles.event.stepper`) or the discrete scheme's (`circles.discrete.stepper`). What it is
given is checked by `circles.inputs` and `circles.memory`; its file is `circles.storage`'s.
"""
from __future__ import annotations

import gc
import math
import weakref
from numbers import Real
from pathlib import Path

import numpy as np
import taichi as ti

from . import launch, observables, placement, reductions
from .backend import compile_for, ensure_init, on_restart, runtime, serial_loops
from .discrete.contacts import PART_PICKS
from .discrete.rounds import list_large
from .event.stepper import SPEED_MARGIN
from .grid import Grid, count_parts
from .inputs import check_record_events, given_circles, mass_unit, overlap_tolerance
from .interrupts import whole_steps
from .memory import check_memory
from .scene import Scene, check_dt
from .scene import scalar as _scalar
from .schemes import STEPPERS, default_dt
from .state import State
from .stepper import like
from .storage import read_saved, write_saved

#: Steps between reorderings of the arrays by grid cell (neighbours close in memory).
REORDER_EVERY = 16
#: In a box wider than tall, a one-level grid numbers its cells along the box's y axis
#: (`grid.Grid`, transposed): the event queue's parts are strips of whole rows of cells, and
#: their borders, searched at every split, are then as long as the box's shorter side. The
#: same state bit for bit either way, and fewer circles near borders. A two-level grid keeps the box's axes (the
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

_REAL = {"f32": ti.f32, "f64": ti.f64}
_NP_REAL = {"f32": np.float32, "f64": np.float64}


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
        compile_for(scene.n)
        pos, vel, radius, mass, color = placement.scene_circles(scene)
        self.scene = scene
        self._setup(pos, vel, radius, mass, color, scene.box, scene.boundary, scene.scheme, scene.precision,
                    scene.dt, record_events)

    @classmethod
    def from_arrays(cls, pos, vel, radius, mass=None, box=(1.0, 1.0), boundary="walls", scheme="event",
                    precision="f64", dt=None, *, color=None, record_events: int = 0) -> "Simulation":
        """A simulation of given circles: pos and vel (n, 2), radius (n,) or one radius for all. mass:
        None (proportional to radius), a model name or (n,) masses."""
        ensure_init()
        pos, vel, radius, mass, color, box, dt = given_circles(pos, vel, radius, mass, box, boundary, scheme,
                                                               precision, dt, color, record_events)
        sim = cls.__new__(cls)
        sim.scene = None
        sim._setup(pos, vel, radius, mass, color, box, boundary, scheme, precision, dt, record_events)
        sim._check_overlap()
        return sim

    def __getattr__(self, name):
        """What the simulation does not hold, its stepper's (its counters of work, and its arrays
        and settings for inspection): called only for names not found on the simulation."""
        stepper = self.__dict__.get("stepper")
        if stepper is None:
            raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")
        return getattr(stepper, name)

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
        compile_for(n)
        self.n = n
        self.box = (float(box[0]), float(box[1]))
        self.boundary, self.scheme, self.precision = boundary, scheme, precision
        self.periodic = boundary == "periodic"
        self._real = _REAL[precision]
        self._np_real = _NP_REAL[precision]
        self.dt = float(dt) if dt is not None else default_dt(scheme, radius, vel, box)
        self.time = 0.0
        self.steps = 0
        # Callables f(sim) run after each step (or batch of steps), e.g. `trajectory.ImageTracker`.
        self.after_step = []
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
        stepper = STEPPERS[scheme]
        self._choose_levels(stepper.two_levels_allowed())
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
        reductions.fill_i32(self._counters, 0)
        # Work counters of the discrete rounds; slot NLARGE counts the large circles of a
        # two-level grid (both schemes).
        self._work = ti.ndarray(ti.i32, shape=PART_PICKS + max(count_parts(), 1))
        reductions.fill_i32(self._work, 0)
        self._record_cap = int(record_events)
        cap = max(1, self._record_cap)
        self._log_t = ti.ndarray(ti.f64, shape=cap)
        self._log_i = ti.ndarray(ti.i32, shape=cap)
        self._log_j = ti.ndarray(ti.i32, shape=cap)
        self._setup_two_level()
        # The scheme: its stepper makes its own arrays, and from then on steps the state.
        self.stepper = stepper(self)

    def _same_circles(self):
        """(radius, inverse mass) as the kernels store them when every circle has the same ones,
        else None: the event queues then read them from an argument (`event.Same`), and the
        discrete kernels the first circle's (`discrete.per_circle`)."""
        radii = self._radius.astype(self._np_real)
        inv_mass = (self._mass_unit / self._mass).astype(self._np_real)
        if len(radii) and np.all(radii == radii[0]) and np.all(inv_mass == inv_mass[0]):
            return float(radii[0]), float(inv_mass[0])
        return None

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
        self._list_large()

    def _list_large(self):
        if self._two_level:
            list_large(self.radius, self._r_cut, self._large, self._work)

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
        at most a step old, and a grid build of its own would cost a third of the reorder.
        """
        if not self.grid.complete:
            self.grid.build(self.pos, 2.0 * self._rmax)
        if self._scratch is None:
            self._scratch = (like(self.pos), like(self.radius), like(self.ids), like(self.virial))
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
            dt = default_dt(self.scheme, state.radius, state.vel, self.box)
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
        with whole_steps() as steps:
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
        with whole_steps() as steps:
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
        self.stepper.steps(h, count)
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
        """One step of length h by the scheme; returns the simulated time covered."""
        return self.stepper.step(h)

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
        delta virial / (2 t) (the centres' box, W - 2r by H - 2r, in a walled box); temperature,
        kT: the kinetic energy over N in a walled box, and in a periodic box, which conserves
        its momentum, the kinetic energy in the centre-of-mass frame over N - 1
        (`observables.temperature`); max_overlap, the largest overlap of two circles as a fraction of
        their contact distance; pressure, compressibility (Z = P A / (N kT)), reduced_pressure
        (beta P d^2 of equal disks of diameter d, NaN for several radii) and wall_pressure,
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
        stats["temperature"] = observables.temperature(stats["kinetic_energy"], stats["momentum"], float(np.sum(m)),
                                                       self.n, self.boundary)
        stats.update(observables.since_start(stats, self.n, self.box, self.boundary, float(np.mean(self._radius)),
                                             observables.equal_diameter(self._radius)))
        stats.update(self.stepper.stats())
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
        extras = self.stepper.work()
        if self._record_cap > 0:
            extras["log"] = (self._record_cap, self._counters.to_numpy(), self._log_t.to_numpy(),
                             self._log_i.to_numpy(), self._log_j.to_numpy())
        return extras

    @classmethod
    def _from_fields(cls, d, scene=None, extras=None, record_events=0) -> "Simulation":
        """A simulation in the state `_fields` (or a file, `storage.read_saved`) gives, with `extras`
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
        for name in sim.stepper.WORK_COUNTERS:
            if name in extras:
                setattr(sim.stepper, name, extras[name])
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
        as an .npz archive, whatever its suffix; returns the path. A failed save leaves no partial
        file and keeps an older one (`storage.write_saved`)."""
        self._live()
        return write_saved(path, self._fields)

    @classmethod
    def load(cls, path, *, record_events: int = 0) -> "Simulation":
        """A simulation from a file that `save` wrote: the same state, time and step count, so
        that it goes on as the saved one would have, bit for bit. A file that is not such an
        archive raises ValueError (a missing one FileNotFoundError). The event log is not
        saved: `record_events=CAPACITY` starts a new one, as in `Simulation`."""
        d = read_saved(path)
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
