"""The discrete scheme's host side: a step's kernels chosen and launched in order.

`DiscreteStepper.step(h)` launches the move, the grid and the first rounds of pick and resolve
in one kernel (on a CPU with several threads, as one team of the threads), then more rounds
while a round left work, then the walls if the rounds did not settle. Where a step runs on one
thread, several steps run in one launch (`steps`). The stepper owns its scratch arrays and its
tuning constants; the circles' arrays and counts are the simulation's.
"""
import taichi as ti

from .. import reductions, team
from ..backend import current_arch
from ..geometry import spans
from ..grid import count_parts
from ..stepper import Stepper
from . import rounds, team_step
from .contacts import MOST_CONTACTS

#: Default discrete-scheme step: the fastest circle moves this fraction of the smallest radius.
DISCRETE_STEP_FRACTION = 0.2
#: Rounds of pair resolution per discrete step; what is left stays for the next step.
DISCRETE_MAX_ROUNDS = 16
#: Rounds run in the same launch as the move and the grid (more follow only when needed); even,
#: as the rounds alternate between two work lists. Rounds after the last busy one cost two
#: empty loops each: on a CPU serial ones (see DISCRETE_PARALLEL_ROUNDS), about a microsecond each.
DISCRETE_FUSED_ROUNDS = 8
#: Rounds of a discrete step whose loops run in parallel on a CPU; later ones run on one thread.
#: Starting a parallel loop on the CPU's thread pool costs tens of microseconds even when it has
#: nothing to do, while one thread takes a fraction of a microsecond per listed circle, and the
#: lists shrink fast: by round 3 about 1% of the circles, by round 8 none. A GPU runs every
#: round in parallel.
DISCRETE_PARALLEL_ROUNDS = 4
#: Discrete steps run in one launch, at most, where a step runs on one thread (see
#: backend.serial_loops): a launch and its call cost some 20 microseconds, more than the whole
#: step of a few hundred circles (`discrete.serial_steps`). A reorder (REORDER_EVERY) ends a
#: batch. 1: a launch a step.
DISCRETE_STEPS_AT_ONCE = 16

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


class DiscreteStepper(Stepper):
    """The discrete scheme of a simulation `sim`: move, then resolve overlapping approaching
    pairs (see `circles.discrete`)."""

    #: Bytes per circle of the simulation's and this stepper's arrays, by precision.
    ARRAY_BYTES = {"f32": 132, "f64": 156}

    @classmethod
    def two_levels_allowed(cls):
        """Whether the grid may have two levels: always (the large circles search their blocks)."""
        return True

    @staticmethod
    def default_dt(radius, vmax, collision_rate=0.0):
        """The step in which the fastest circle moves DISCRETE_STEP_FRACTION of the least radius."""
        return DISCRETE_STEP_FRACTION * float(radius.min()) / vmax

    def __init__(self, sim):
        super().__init__(sim)
        sim = self.sim
        if current_arch() == "gpu":
            self._parallel_rounds = DISCRETE_MAX_ROUNDS
        elif sim._serial:
            self._parallel_rounds = 0  # no parallel round: the whole step on one thread
        else:
            self._parallel_rounds = DISCRETE_PARALLEL_ROUNDS
        self._partner = ti.ndarray(ti.i32, shape=sim.n)
        self._picked = ti.ndarray(ti.i32, shape=sim.n)
        self._marked = ti.ndarray(ti.i32, shape=sim.n)
        if not 0 < DISCRETE_CONTACTS <= MOST_CONTACTS:
            raise ValueError(f"DISCRETE_CONTACTS = {DISCRETE_CONTACTS} must be within 1 to "
                             f"{MOST_CONTACTS} (discrete.MOST_CONTACTS)")
        # Contact m of every circle in one row: most circles overlap at most one other, so the
        # rounds read row 0 only.
        self._contacts = ti.ndarray(ti.i32, shape=(DISCRETE_CONTACTS, sim.n))
        self._n_contacts = ti.ndarray(ti.i32, shape=sim.n)
        self._work_lists = ti.ndarray(ti.i32, shape=(2, sim.n))
        self._walled = ti.ndarray(ti.i32, shape=sim.n)
        for arr in (self._picked, self._marked):
            reductions.fill_i32(arr, 0)
        # Equal radii and inverse masses as the kernels see them (`_same_circles`).
        self._uniform = DISCRETE_UNIFORM and sim._same is not None
        # The first round of a step in one part per thread (`discrete._first_round_in_parts`).
        self._first_parts = DISCRETE_FIRST_IN_PARTS and count_parts() > 1
        # A step's stages on the CPU's threads as one team (`discrete.team_step`).
        self._team = DISCRETE_TEAM and current_arch() == "cpu" and not sim._serial and count_parts() > 1
        if self._team:
            self._sync = ti.ndarray(ti.i32, shape=team.sync_slots())
        # Several steps a launch where a step runs on one thread (`discrete.serial_steps`).
        self._steps_at_once = DISCRETE_STEPS_AT_ONCE if self._parallel_rounds == 0 and not self._team else 1

    def _discrete_args(self):
        """What a discrete step's kernels take: the box, precision and boundary, the grid's cells
        (`Grid.prepare`) and spans, the circles' arrays, and whether the grid has two levels."""
        sim = self.sim
        w, hgt = sim.box
        real, periodic = sim._real, sim.periodic
        _, *cells = sim.grid.prepare(2.0 * sim._r_cut)
        rows, segs = spans(sim.grid.ncx, sim.grid.ncy, periodic)
        arrays = (sim.pos, sim.vel, sim.radius, sim.inv_mass, sim.ids, self._partner, self._picked,
                  self._marked, self._contacts, self._n_contacts, self._work_lists, sim._work, sim.pair_count,
                  sim.virial, sim.wall_count, sim.wall_impulse, self._walled)
        return w, hgt, real, periodic, cells, rows, segs, arrays, sim._two_level

    def step(self, h):
        """One step of length h; returns h (a discrete step is never cut short)."""
        sim = self.sim
        if self._steps_at_once > 1:
            # One step of `serial_steps`, the same kernel as the batches' (one kernel to compile).
            self.steps(h, 1)
            return h
        w, hgt, real, periodic, cells, rows, segs, arrays, two = self._discrete_args()
        parallel = self._parallel_rounds
        if self._team:
            busy = team_step.team_step(*arrays, *cells, rows, segs, h, w, hgt, sim._spread, sim._large,
                                       sim.grid.parts, self._sync, real, periodic, two, self._uniform,
                                       DISCRETE_FUSED_ROUNDS, DISCRETE_TEAM_SERIAL)
        else:
            busy = rounds.begin_step(*arrays, *cells, rows, segs, h, w, hgt, sim._spread, sim._large,
                                     sim.grid.parts, real, periodic, two, self._uniform,
                                     DISCRETE_FUSED_ROUNDS, min(parallel, DISCRETE_FUSED_ROUNDS),
                                     self._first_parts)
        sim.grid.complete = True
        self._more_rounds(busy, w, hgt, real, periodic, two, arrays, parallel)
        return h

    def steps(self, h, count):
        """`count` discrete steps of length h on one thread, as many in a launch as settle within
        their fused rounds (`discrete.serial_steps`): the state of `count` calls of
        `step`, bit for bit."""
        sim = self.sim
        w, hgt, real, periodic, cells, rows, segs, arrays, two = self._discrete_args()
        while count > 0:
            begun = rounds.serial_steps(*arrays, *cells, rows, segs, h, w, hgt, sim._spread, sim._large,
                                        sim.grid.parts, count, real, periodic, two, self._uniform,
                                        DISCRETE_FUSED_ROUNDS)
            sim.grid.complete = True
            busy = begun < 0
            begun = abs(begun)
            count -= begun
            self.rounds += (begun - 1) * DISCRETE_FUSED_ROUNDS
            self._more_rounds(busy, w, hgt, real, periodic, two, arrays, 0)

    def _more_rounds(self, busy, w, hgt, real, periodic, two, arrays, parallel):
        """The rest of a discrete step whose fused rounds left work (`busy`): more rounds up to
        DISCRETE_MAX_ROUNDS, and the walls if they did not settle; counts the step's rounds."""
        sim = self.sim
        done = DISCRETE_FUSED_ROUNDS
        # Most steps settle within the fused rounds; `busy` says whether another round has work.
        while busy and done < DISCRETE_MAX_ROUNDS:
            more = min(DISCRETE_FUSED_ROUNDS, DISCRETE_MAX_ROUNDS - done)
            busy = rounds.more_rounds(*arrays, *sim.grid.args(), w, hgt, sim._spread, real, periodic, two,
                                      self._uniform, more, min(max(parallel - done, 0), more))
            done += more
        self.rounds += done
        if busy and not periodic:
            # The round limit was reached: the walls were left for rounds that did not come.
            rounds.walls(sim.pos, sim.vel, sim.radius, sim.inv_mass, sim.wall_count, sim.wall_impulse,
                         self._walled, sim._work, w, hgt, real, self._uniform)
