"""The event scheme's host side: the stages of a step chosen and launched in order.

`EventStepper.step(h)` measures the largest speed, builds the grid (two levels when a few
circles are much larger), and then runs the step's events: from one queue on a CPU
(`queue.queue_step`), split into parts in windows of the step when the CPU has several threads,
or one thread and a scene larger than its cache (`split.split_parts`, `split.queue_parts`), or in parallel rounds of predict, bound and execute
on a GPU (`rounds`). Every path ends with each circle moved to the step's end. The stepper owns
its scratch arrays and its tuning constants; the circles' arrays and counts are the
simulation's (`Simulation`), read afresh at each step since a reorder replaces them.
"""
import numpy as np
import taichi as ti

from .. import reductions
from ..backend import available_memory, current_arch, EVENT_PARTS_ONE_THREAD_N, serial_loops
from ..geometry import NEVER, NO_EVENT, spans
from ..grid import count_parts
from ..stepper import Stepper, like
from . import queue, search, split, two_level
from . import rounds as parallel_rounds
from .search import LIST_SLOTS

#: Speeds may grow by this factor within an event step before the step is cut short. The grid's
#: cells, and the clusters a split into parts must keep whole, grow with it; a step cut short
#: runs in two pieces. A larger margin makes every step dearer, a smaller one cuts more steps
#: short; 1.1 balances the two (the Performance page of the docs).
SPEED_MARGIN = 1.1
#: Default step: the fastest circle moves this many mean radii per step (the mean, not the
#: largest: a few large circles must not make every step long and every grid cell wide).
EVENT_STEP_RADII = 0.3
#: ... and at most this many collisions a circle takes part in per step, by Enskog's collision
#: frequency at the scene's area fraction (`theory.enskog_rate`). Dense circles collide many
#: times while the fastest moves a radius: there a step's cells would hold many circles that
#: every collision searches, and a shorter step with smaller cells costs less (the
#: Performance page of the docs). A dilute scene's step is the radii's.
EVENT_STEP_COLLISIONS = 1.1
#: ... and this many from EVENT_PARTS_ONE_THREAD_N circles, where every thread count runs its
#: steps in parts: there a shorter step keeps each part's events within fewer cache lines, and
#: 0.33 made 1.13 times the collisions per second of 1.1 at 1e6 dense disks on two threads.
EVENT_STEP_COLLISIONS_LARGE = 0.33

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
#: The neighbour lists of one queue (`_list_r2`) reach this many units in the last place of
#: the largest coordinate further than the step's reach.
LIST_ALLOWANCE_ULPS = 64
#: The arrays of a circle's state that the parts of an event step back up at its start (the
#: clocks aside, 0 then), in the order event.queue_parts takes them; the counts and sums are not
#: changed until the step is done (its events write to a sum log, `event.apply_sums`).
PARTS_BACKUP_ORDER = ("pos", "vel")
#: The parts' sum log (`split.queue_parts`): entries per circle at first (an event writes one;
#: a step takes well under one a circle below the freezing density), twice as many each time a step fills it while the memory allows, up to SUM_LOG_MOST_PER_CIRCLE; and
#: the most entries a part takes from it at a time.
SUM_LOG_PER_CIRCLE = 1
SUM_LOG_MOST_PER_CIRCLE = 4
SUM_LOG_CHUNK = 256
#: Windows of a step split into parts at most (`EventStepper._queue_parts_step`), and the steps
#: after which a step tries half as many.
MOST_WINDOWS = 8
WINDOW_RETRY_STEPS = 16
#: Rounds of one event step after which (and after twice as many, and so on) the events it
#: executed are counted: more than `event.most_events` stop it with an
#: error (jammed circles), as on the queue. A step takes about ten rounds.
JAM_CHECK_ROUNDS = 64
#: Sweeps of the causal bound per round before giving up (it settles in a few).
MAX_BOUND_SWEEPS = 10_000

#: Circles per bucket of the queue's calendar (`calendar`).
QUEUE_BUCKET_CIRCLES = 4

#: A step that executes more events than this per circle (the queue: at most 2**30 in all) stops
#: with an error, on the queue and in the rounds: circles jammed in a chain across the box
#: collide without end at one instant. Every step may execute MOST_EVENTS_ANY_STEP, so that a few
#: circles can make many collisions of their own in a step (a circle 1e10 times as heavy as a light
#: one pressing it against a wall makes 314159).
MOST_EVENTS_PER_CIRCLE = 10_000
MOST_EVENTS_ANY_STEP = 1_000_000


def most_events(n):
    """The events a step of n circles may execute before it stops as jammed (see above)."""
    return min(max(n * MOST_EVENTS_PER_CIRCLE, MOST_EVENTS_ANY_STEP), 1 << 30)


#: Circles per part (`split_parts`): enough for the borders' clusters to be a small share, few
#: enough that a part's arrays mostly stay in the cache.
PART_CIRCLES = 65536
#: Rows of cells per part at least (a cluster that crosses a border reaches a row or two in).
PART_MIN_ROWS = 4
#: Parts at most.
MOST_PARTS = 1024


def part_info_size(parts: int) -> int:
    """Entries of `split_parts`' info array for `parts` parts: part k's first slot in the
    queues' arrays (info[k], k <= parts, info[parts] = n), the start and end of its claimed
    circles in `claimed` (at parts + 1 + k and 2 parts + 1 + k), the threads' counter of borders
    or parts taken (at 3 parts + 1) and whether the split holds (at 3 parts + 2)."""
    return 3 * parts + 3


class EventStepper(Stepper):
    """The event scheme of a simulation `sim`: exact collisions by time of impact (see
    `circles.event`)."""

    #: Bytes per circle of the simulation's and this stepper's arrays, by precision.
    ARRAY_BYTES = {"f32": 129, "f64": 165}
    #: Bytes per circle more when a step is split into parts.
    PART_BYTES = {"f32": 41, "f64": 57}
    #: Bytes per circle more for the lists of neighbours of one queue on one thread: a count and
    #: LIST_SLOTS entries.
    LIST_BYTES = 4 * (1 + LIST_SLOTS)
    #: Collisions are events at known times: this scheme can log them.
    LOGS_EVENTS = True
    #: The counters of work that copies carry: the rounds (one queue counts one a step), bound
    #: sweeps, steps cut short, windows run in parts, and steps whose parts filled the sum log.
    WORK_COUNTERS = Stepper.WORK_COUNTERS + ("sum_log_full",)

    @staticmethod
    def default_dt(radius, vmax, collision_rate=0.0):
        """The step in which the fastest circle moves EVENT_STEP_RADII mean radii, and a circle
        takes part in at most EVENT_STEP_COLLISIONS collisions (EVENT_STEP_COLLISIONS_LARGE
        from EVENT_PARTS_ONE_THREAD_N circles) at `collision_rate` (collisions a circle takes
        part in per unit time; 0: not known). It depends on the circles alone, not on the
        threads, so that the steps, and the bits, are the same at any thread count."""
        dt = EVENT_STEP_RADII * float(radius.mean()) / vmax
        if collision_rate > 0:
            most = EVENT_STEP_COLLISIONS_LARGE if len(radius) >= EVENT_PARTS_ONE_THREAD_N else EVENT_STEP_COLLISIONS
            dt = min(dt, most / collision_rate)
        return dt

    @classmethod
    def splits_into_parts(cls, n):
        """Whether a CPU simulation of n circles may split its steps into parts: where its loops
        do not run as one serial loop (several threads, or at least EVENT_PARTS_ONE_THREAD_N
        circles on one; counted also where a spread of radii will give a two-level grid and one
        queue, which is known only after the radii are drawn)."""
        return cls.uses_queue() and not serial_loops(n, "event")

    @classmethod
    def lists_neighbours(cls, n):
        """Whether a CPU simulation of n circles lists each circle's neighbours at a step's start:
        one queue whose loops run on one thread (counted also where a spread of radii will give
        a two-level grid, which searches cells, known only after the radii are drawn)."""
        return cls.uses_queue() and serial_loops(n, "event")

    @staticmethod
    def uses_queue():
        """Whether steps run from one queue of events (on a CPU) rather than in rounds."""
        return EVENT_QUEUE_ON_CPU and current_arch() == "cpu"

    @classmethod
    def two_levels_allowed(cls):
        """Whether the grid may have two levels: the queue's searches take them, the rounds not."""
        return cls.uses_queue()

    def __init__(self, sim):
        super().__init__(sim)
        self.sweeps = 0
        # Steps cut short because a collision would outrun the grid (see circles.event).
        self.cut_steps = 0
        # Windows of steps run with the queue split into parts (see `_queue_parts_step`).
        self.parts_run = 0
        # Steps whose parts filled the sum log, and ran from one queue (`_sum_log_full`).
        self.sum_log_full = 0
        self._event_queue = self.uses_queue()
        self._reach = 0.0  # the grid's reach of the step under way (`step`)
        # A step's two scalars on the device: the earliest event time of a round, and the time
        # of a collision that would outrun the grid (NEVER when none).
        self._scalars = ti.ndarray(sim._real, shape=2)
        n_coarse = sim._n_large if sim._two_level else 1
        # The coarse cells of the queue's two-level grid (`two_level.build_coarse`), grown on demand.
        self._coarse_start = ti.ndarray(ti.i32, shape=1)
        self._coarse_ids = ti.ndarray(ti.i32, shape=n_coarse)
        self._alloc_event_arrays()
        self._setup_parts()

    def _setup_parts(self):
        """The event queue's calendar heads, and the arrays of a queue split into parts
        (`split.split_parts`): on a CPU, with one grid level, when the step's loops do not run
        as one serial loop (`backend.serial_loops`: several threads, or a large scene on one)."""
        sim = self.sim
        self._parts = self._event_queue and not sim._serial and not sim._two_level
        self._split_wait = 0  # steps left before a split is tried again after one failed
        self._windows = 1  # of a step split into parts (see `_queue_parts_step`)
        n = sim.n
        # The calendar's bucket heads (`queue.queue_step`); each part's calendar takes one bucket
        # more than its share (see split.queue_parts). The queue's kernels take the width these
        # heads are made for as an argument.
        self._per_bucket = QUEUE_BUCKET_CIRCLES
        buckets = max(n // self._per_bucket, 1) if self._event_queue else 1
        if self._parts:
            buckets = n // self._per_bucket + MOST_PARTS + 1
        self._head = ti.ndarray(ti.i32, shape=buckets)
        # One queue on one thread with one grid level lists each circle's neighbours within the
        # step's reach as it first predicts, and searches those lists after each event
        # (`search._first_events_once`); the other paths search cells.
        self._listed = self.lists_neighbours(n) and not sim._two_level
        self._lists = (ti.ndarray(ti.i32, shape=n if self._listed else 1),
                       ti.ndarray(ti.i32, shape=n * LIST_SLOTS if self._listed else 1))
        # The lists' absolute allowance beyond the reach, against round-off in the positions.
        self._list_allowance = LIST_ALLOWANCE_ULPS * float(np.finfo(sim._np_real).eps) * max(sim.box)
        if not self._parts:
            return
        self._label = ti.ndarray(ti.i32, shape=n)
        self._claimed = ti.ndarray(ti.i32, shape=max(n // PART_CLAIMS, 1))
        self._part_info = ti.ndarray(ti.i32, shape=part_info_size(MOST_PARTS))
        self._part_result = ti.ndarray(ti.f64, shape=MOST_PARTS)
        # The state at the step's start, put back when a collision would outrun the grid
        # (`_queue_parts_step`; every clock is 0 then), and the flags of its windows.
        self._backup = {name: like(getattr(sim, name)) for name in PARTS_BACKUP_ORDER}
        self._sum_at = ti.ndarray(ti.i32, shape=1)
        self._make_sum_log(max(int(SUM_LOG_PER_CIRCLE * n), 1))
        self._touched = ti.ndarray(ti.i32, shape=n)
        self._dirty_w = ti.ndarray(ti.i32, shape=n)
        # The split's absolute allowance on links, against round-off in the window's positions.
        self._link_allowance = LINK_ALLOWANCE_ULPS * float(np.finfo(sim._np_real).eps) * max(sim.box)

    def _list_r2(self):
        """The squared distance within which the first predictions list a circle's neighbours:
        the step's reach, with a margin over the round-off of the positions (a longer list
        costs a little; a shorter one would miss a pair)."""
        return (self._reach * (1.0 + 1e-9) + self._list_allowance) ** 2

    def _same_args(self):
        """(radius, inverse mass) of `_same_circles`, or zeros (unread) for circles of several,
        as the event kernels take them."""
        sim = self.sim
        return sim._same or (0.0, 0.0)

    def _make_sum_log(self, size):
        """The parts' sum log (`split.queue_parts`) of `size` entries: a circle's index (or a
        wall hit's entry) and an amount each."""
        self._sum_log = (ti.ndarray(ti.i32, shape=size), ti.ndarray(ti.f64, shape=size))

    def _sum_chunk(self, parts):
        """The entries a part takes from the sum log at a time: SUM_LOG_CHUNK, or fewer for a
        log too short for every part of several windows to hold a few chunks."""
        size = self._sum_log[0].shape[0]
        return max(1, min(SUM_LOG_CHUNK, size // (4 * parts * MOST_WINDOWS)))

    def _apply_sums(self):
        """The counts and sums of the windows run in parts so far this step, from the sum log."""
        sim = self.sim
        queue.apply_sums(*self._sum_log, self._sum_at, sim.pair_count, sim.virial, sim.wall_count,
                         sim.wall_impulse)

    def _part_shape(self):
        """(parts, rows of cells per part) of this step's split (`split.split_parts`); parts < 2: none
        (a periodic grid under 3 cells wide has no forward half of its cells to predict from)."""
        sim = self.sim
        ncy = sim.grid.ncy
        if sim.grid.ncx < 3:
            return 0, 0
        threads = count_parts()
        # A multiple of the threads, so that they finish their share of the parts together.
        want = -(-max(sim.n // PART_CIRCLES, threads) // threads) * threads
        parts = min(want, ncy // PART_MIN_ROWS, MOST_PARTS)
        if parts < 2:
            return 0, 0
        rows = -(-ncy // parts)
        return -(-ncy // rows), rows

    def _alloc_event_arrays(self):
        sim = self.sim
        n, real = sim.n, sim._real
        self.tau = ti.ndarray(real, shape=n)
        reductions.fill_real(self.tau, 0.0)
        # Each circle's event (time, partner). One queue on one thread starts a step with none
        # held (its finish clears them, `queue.queue_step`), as here.
        self._ev_t = ti.ndarray(real, shape=n)
        self._ev_p = ti.ndarray(ti.i32, shape=n)
        # NEVER as the kernels write it (`ti.cast(NEVER, real)` of a literal, which is float32).
        reductions.fill_real(self._ev_t, float(np.float32(NEVER)))
        reductions.fill_i32(self._ev_p, NO_EVENT)
        self._dirty = ti.ndarray(ti.i32, shape=n)
        self._moved = ti.ndarray(ti.i32, shape=n)
        self._d1 = ti.ndarray(real, shape=n)
        # The key each round's bound carries (`_bound_sweep`); the queue has no bounds.
        self._d_key = ti.ndarray(ti.i32, shape=(1 if self._event_queue else n, 2))
        self._active = (ti.ndarray(ti.i32, shape=n), ti.ndarray(ti.i32, shape=n))
        reductions.fill_i32(self._active[1], 0)
        # The queue's calendar (`queue.queue_step`): each circle's back link (the bucket heads:
        # `_setup_parts`, which knows whether the queue is split).
        self._prv = ti.ndarray(ti.i32, shape=n if self._event_queue else 1)
        # The queue's list of neighbours that search again after an event (`queue.queue_step`).
        self._pending = ti.ndarray(ti.i32, shape=n if self._event_queue else 1)
        # What a step changes, kept for the rounds to redo a step cut short; the queue needs no copy.
        self._backup = None if self._event_queue else {
            name: like(getattr(sim, name))
            for name in ("pos", "vel", "pair_count", "wall_count", "virial", "wall_impulse")}

    def step(self, h):
        """One step over [0, h]; returns the simulated time covered (h, or less when cut short)."""
        sim = self.sim
        vmax = sim._max_speed()
        sim._known_speed = None  # until the step's finish measures it again
        w, hgt = sim.box
        if vmax == 0.0:
            return h
        vlim = vmax * SPEED_MARGIN
        reach = 2.0 * sim._rmax + 2.0 * vlim * h
        if sim.periodic:
            # The nearest image must be the only one within reach during the step.
            limit = 0.5 * min(w, hgt)
            if reach > limit:
                h = (limit - 2.0 * sim._rmax) / (2.0 * vlim)
                reach = limit
        self._reach = reach
        if sim._two_level:
            self._build_two_levels(2.0 * vlim * h)
        else:
            sim.grid.build(sim.pos, reach)
        if self._event_queue:
            return self._queue_step(h, vlim)
        g = sim.grid.args()
        real, periodic, record = sim._real, sim.periodic, sim._record_cap > 0
        b = self._backup
        parallel_rounds.begin_step(sim.pos, sim.vel, sim.pair_count, sim.wall_count, sim.virial, sim.wall_impulse,
                                   b["pos"], b["vel"], b["pair_count"], b["wall_count"], b["virial"],
                                   b["wall_impulse"], self._dirty, self._moved, self._scalars, real, sim._serial)
        log_count = int(sim._counters.to_numpy()[1]) if record else 0
        t_end = h
        # A step that can end takes a few rounds; from JAM_CHECK_ROUNDS rounds on (and at every
        # doubling) its events so far are counted, and a jam stops it as on the queue.
        rounds, check = 0, JAM_CHECK_ROUNDS
        sweep_args = (sim.pos, sim.vel, sim.radius, self.tau, self._ev_t, self._ev_p, sim.ids, self._d1,
                      self._d_key, *self._active, *g, w, hgt)
        while True:
            tmin = parallel_rounds.begin_round(sim.pos, sim.vel, sim.radius, self.tau, sim.ids, self._ev_t,
                                               self._ev_p, self._dirty, self._moved, self._d1, self._d_key,
                                               *self._active, *g, w, hgt, t_end, vlim, self._scalars, real, periodic)
            if tmin > t_end:
                break
            # The bounds have settled when tmin >= 0; -1 asks for more sweeps.
            sweeps = parallel_rounds.SWEEPS_PER_LAUNCH
            while tmin < 0:
                if parallel_rounds.more_sweeps(*sweep_args, t_end, vlim, real, periodic) == 0:
                    break  # nothing decreased, so nothing was marked: both flag arrays are clear
                sweeps += parallel_rounds.SWEEPS_PER_LAUNCH
                if sweeps > MAX_BOUND_SWEEPS:
                    raise RuntimeError(f"causal bounds did not settle in {MAX_BOUND_SWEEPS} sweeps (internal error)")
            self.sweeps += sweeps
            executed = parallel_rounds.execute(sim.pos, sim.vel, sim.radius, sim.inv_mass, self.tau, sim.ids,
                                               self._ev_t, self._ev_p, self._d1, self._d_key, self._dirty,
                                               self._moved, sim.pair_count, sim.wall_count, sim.virial,
                                               sim.wall_impulse, *g, w, hgt, t_end, vlim, sim._time, self._scalars,
                                               sim._counters, sim._log_t, sim._log_i, sim._log_j, real, periodic,
                                               record)
            self.rounds += 1
            rounds += 1
            if rounds == check:
                check *= 2
                events = reductions.events_since(sim.pair_count, sim.wall_count, b["pair_count"], b["wall_count"])
                if events > most_events(sim.n):
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
        search.finish(sim.pos, sim.vel, self.tau, t_end, w, hgt, sim._speed_out, real, periodic, sim._serial, False)
        return t_end

    def _build_two_levels(self, margin):
        """The event queue's two-level grid for a step in which two circles close in by at most
        `margin`: fine cells for the small circles, and coarse cells of whole blocks of fine
        cells, as wide as the reach of two large circles, that list the large ones."""
        sim = self.sim
        w, hgt = sim.box
        sim.grid.build(sim.pos, 2.0 * sim._r_cut + margin)
        ncx, ncy = sim.grid.ncx, sim.grid.ncy
        reach = 2.0 * sim._rmax + margin
        # A whole fine cell more than the reach, against round-off.
        mx = int(reach * ncx / w) + 1
        my = int(reach * ncy / hgt) + 1
        ncx_c, ncy_c = -(-ncx // mx), -(-ncy // my)
        if self._coarse_start.shape[0] < ncx_c * ncy_c + 1:
            self._coarse_start = ti.ndarray(ti.i32, shape=int(1.5 * ncx_c * ncy_c) + 1)
        two_level.build_coarse(sim._large, sim._work, sim.grid.cell_of, self._coarse_start, self._coarse_ids, ncx,
                               mx, my, ncx_c, ncy_c)
        self._levels = (self._coarse_start, self._coarse_ids, ncx_c, ncy_c, mx, my, sim._r_cut, margin)

    def _queue_step(self, h, vlim):
        """The rest of an event step over [0, h] from one queue (see `EVENT_QUEUE_ON_CPU`), in one
        launch that also brings every circle to the step's end; returns as `step`. One
        queue takes no backup: a step cut short ends where the queue stopped (see
        circles.event). Split into parts when it can be (`_queue_parts_step`)."""
        if self._parts:
            if self._split_wait > 0:
                self._split_wait -= 1
            else:
                return self._queue_parts_step(h, vlim)
        return self._queue_step_whole(h, vlim)

    def _queue_step_whole(self, h, vlim, at_start=True):
        """`_queue_step` from one queue for all circles (`queue.queue_step`); `at_start`: at the
        step's start (every circle's clock 0), not after some of its windows."""
        sim = self.sim
        w, hgt = sim.box
        real, periodic, record = sim._real, sim.periodic, sim._record_cap > 0
        g = sim.grid.args()
        two = sim._two_level
        levels = self._levels if two else (self._coarse_start, self._coarse_start, 1, 1, 1, 1, 0.0, 0.0)
        # The rounds' arrays (bounds, flags) hold the queue's heap (circles, places, times) and
        # its lists' forward links.
        reached = queue.queue_step(sim.pos, sim.vel, sim.radius, sim.inv_mass, self.tau, sim.ids, self._ev_t,
                                   self._ev_p, self._dirty, *self._active, self._d1, self._head, self._moved,
                                   self._prv, self._pending, sim.pair_count, sim.wall_count, sim.virial,
                                   sim.wall_impulse,
                                   *g, w, hgt, h, vlim, sim._time, sim._counters, sim._log_t, sim._log_i,
                                   sim._log_j, sim._speed_out, *levels, most_events(sim.n),
                                   self._per_bucket, *self._same_args(), *self._lists, self._list_r2(),
                                   real, periodic, record, two, sim._serial, at_start, sim._same is not None,
                                   self._listed)
        self.rounds += 1
        # queue_step's finish left the largest speed in _speed_out; its return synchronised.
        sim._known_speed = reductions.speed_in(sim._speed_view)
        if reached == -2:
            raise self._jammed()
        if reached < 0:
            raise RuntimeError(f"the earliest event of the queue was not its partner's at step time {h} "
                               "(internal error)")
        if reached != h:
            self.cut_steps += 1
        return reached

    def _queue_parts_step(self, h, vlim):
        """`_queue_step` from one queue per part (`split.queue_parts`) in windows of the step: the
        parts of a window hold whole clusters of the circles that can meet within it
        (`split.split_parts`), and the shorter the window, the smaller the clusters. Every circle
        predicts its first event of the step in its part in the first window; before each later
        window, the circles whose searches met a neighbour in another part, and those paired
        with them, predict again (`split.repredict`). A step starts with as many windows as the
        last one ended with; a split that fails doubles them, up to MOST_WINDOWS, beyond which
        the rest of the step runs from one queue; every WINDOW_RETRY_STEPS steps, half as many
        are tried. A collision that would outrun the grid ends the step at its time for
        every circle, but the other parts may have gone past it: the step runs again from its
        start (`_backup`, which each part fills in the first window; the counts and sums change
        only when the step is done, from the sum log, `_apply_sums`) up to that time. The
        events up to it are the same (by causality), and so are their times (a pair's time of
        impact is computed from the later of its two clocks, which only their own events move),
        so the state is that of one queue bit for bit."""
        sim = self.sim
        w, hgt = sim.box
        record = sim._record_cap > 0
        g = sim.grid
        b = self._backup
        parts, rows_per = self._part_shape()
        if parts < 2:
            return self._queue_step_whole(h, vlim)
        if sim.steps % WINDOW_RETRY_STEPS == 0 and self._windows > 1:
            self._windows //= 2
        cell_args = (g.cell_of, g.cell_start, g.sorted_ids, g.ncx, g.ncy, *spans(g.ncx, g.ncy, sim.periodic))
        periodic = sim.periodic
        log_count = int(sim._counters.to_numpy()[1]) if record else 0
        end = h  # the step's end: h, or the time of a collision that would outrun the grid
        while True:
            t0 = 0.0
            done = 0  # windows of the step done, in the finest cut so far
            cut = end
            while t0 < end:
                if done > 0:
                    split.repredict(sim.pos, sim.vel, sim.radius, self.tau, sim.ids, self._ev_t, self._ev_p,
                                    self._dirty_w, self._touched, *cell_args, w, hgt, end, self._scalars,
                                    self._same_args()[0], sim._real, periodic, sim._same is not None)
                while True:
                    t1 = h if done + 1 >= self._windows else h * (done + 1) / self._windows
                    # The circles' reaches are kept in _d1, the queues' scratch of heap times.
                    if split.split_parts(sim.pos, sim.vel, self.tau, sim.radius, self._label, self._claimed,
                                         self._d1, self._touched, self._dirty_w, self._part_info, *cell_args,
                                         rows_per, parts, w, hgt, t0, min(t1, end) - t0, vlim,
                                         self._link_allowance, self._same_args()[0], sim._real, periodic,
                                         sim._same is not None):
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
                split.queue_parts(sim.pos, sim.vel, sim.radius, sim.inv_mass, self.tau, sim.ids, self._ev_t,
                                  self._ev_p, self._dirty, *self._active, self._d1, self._head, self._moved,
                                  self._prv, self._pending, sim.pair_count, sim.wall_count, sim.virial,
                                  sim.wall_impulse, self._touched, self._dirty_w,
                                  *(b[name] for name in PARTS_BACKUP_ORDER), *self._sum_log, self._sum_at,
                                  self._sum_chunk(parts), self._label, self._claimed,
                                  self._part_info, self._part_result, sim._speed_out, *cell_args, rows_per,
                                  parts, w, hgt, end,
                                  min(t1, end), vlim, sim._time, int(done == 0), sim._counters, sim._log_t,
                                  sim._log_i, sim._log_j, self._per_bucket, MOST_EVENTS_PER_CIRCLE,
                                  *self._same_args(), sim._real, record, periodic,
                                  sim._same is not None)
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
        # (`split.queue_parts`); reading their results synchronised.
        sim._known_speed = reductions.speed_in(sim._speed_view)
        return h

    def _sum_log_full(self, end, h, vlim, log_count):
        """A step in parts whose events filled the sum log: it runs again from its start (the
        counts and sums unchanged, the log dropped) up to `end` from one queue (which needs no
        log), and later steps have a log twice as long, up to SUM_LOG_MOST_PER_CIRCLE entries a
        circle. Returns as `_queue_parts_step`."""
        sim = self.sim
        self.sum_log_full += 1
        self._restore(log_count)
        size, most = self._sum_log[0].shape[0], int(SUM_LOG_MOST_PER_CIRCLE * sim.n)
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
        """The error of an event step that executed more than MOST_EVENTS_PER_CIRCLE events
        per circle."""
        sim = self.sim
        return RuntimeError(
            f"the event step from time {sim.time} executed more than {most_events(sim.n)} events "
            f"({MOST_EVENTS_PER_CIRCLE} per circle, or {MOST_EVENTS_ANY_STEP} in any step) without "
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
        sim = self.sim
        for name, arr in self._backup.items():
            reductions.copy_vec(arr, getattr(sim, name))
        reductions.fill_real(self.tau, 0.0)
        if sim._record_cap > 0:
            self._set_counter(1, log_count)

    def _set_scalars(self, a, b):
        self._scalars.from_numpy(np.array([a, b], dtype=self.sim._np_real))

    def _set_counter(self, k, value):
        sim = self.sim
        c = sim._counters.to_numpy()
        c[k] = value
        sim._counters.from_numpy(c)

