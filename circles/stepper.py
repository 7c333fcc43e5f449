"""What a scheme is to a `Simulation`: a stepper with one small interface.

A stepper is made for one simulation, once its state's arrays exist (`Stepper(sim)`), and
makes the scratch arrays of its own. `step(h)` advances every circle by a step of length h (or
less, when the scheme cuts the step short) and returns the simulated time it covered;
`steps(h, count)` runs several whole steps in one launch where the scheme can
(`steps_at_once` > 1). The class says what the scheme needs before any array is made: its
bytes per circle (`bytes_per_circle`), its default step (`default_dt`), whether its grid may
have two levels (`two_levels_allowed`) and whether it logs its collisions (`LOGS_EVENTS`).
`work()` gives its counters of work, which copies carry; `stats()`, what it adds to
`Simulation.stats`.

The simulation keeps the state (positions, velocities, radii, inverse masses, ids and the
per-circle counts and sums), the grid, the clock and the public interface; a stepper reads
the state's arrays from it at each step, as a reorder replaces them.
"""
import weakref

import taichi as ti


def like(arr):
    """A new ndarray of the same kind, element type and shape."""
    if isinstance(arr, ti.VectorNdarray):
        return ti.Vector.ndarray(arr.n, arr.dtype, shape=arr.shape)
    return ti.ndarray(arr.dtype, shape=arr.shape)


class Stepper:
    """The interface of a scheme's stepper (see the module's docstring)."""

    #: Bytes per circle of a simulation's arrays and the stepper's on a CPU, by precision.
    ARRAY_BYTES: dict = {}
    #: Bytes per circle more when the scheme splits its steps into parts (several threads).
    PART_BYTES = {"f32": 0, "f64": 0}
    #: Bytes per circle more for lists of neighbours (`lists_neighbours`).
    LIST_BYTES = 0
    #: Whether the scheme's collisions are events at known times that it can log.
    LOGS_EVENTS = False
    #: The counters of work that copies of a simulation carry.
    WORK_COUNTERS = ("rounds", "sweeps", "cut_steps", "parts_run")

    def __init__(self, sim):
        # A weak reference: the simulation owns its stepper, and its arrays go with it when it
        # is no longer used, without waiting for the collector of reference cycles.
        self.sim = weakref.proxy(sim)
        self.rounds = 0
        self.sweeps = 0
        self.cut_steps = 0
        self.parts_run = 0
        self._steps_at_once = 1

    @classmethod
    def splits_into_parts(cls, n):
        """Whether a CPU simulation of n circles may split its steps into parts."""
        return False

    @classmethod
    def bytes_per_circle(cls, n, precision):
        """ARRAY_BYTES of a CPU simulation of n circles, with PART_BYTES when it may split its
        steps into parts (`splits_into_parts`) and LIST_BYTES when it lists neighbours
        (`lists_neighbours`)."""
        per = cls.ARRAY_BYTES[precision]
        if cls.splits_into_parts(n):
            per += cls.PART_BYTES[precision]
        if cls.lists_neighbours(n):
            per += cls.LIST_BYTES
        return per

    @classmethod
    def lists_neighbours(cls, n):
        """Whether a CPU simulation of n circles keeps lists of each circle's neighbours."""
        return False

    @classmethod
    def two_levels_allowed(cls):
        """Whether the grid may have two levels (`Simulation._choose_levels`)."""
        return False

    @staticmethod
    def default_dt(radius, vmax, collision_rate=0.0):
        """The step length for circles of these radii whose fastest moves at vmax > 0, colliding
        `collision_rate` times a circle per unit time (0: not known)."""
        raise NotImplementedError

    @property
    def steps_at_once(self):
        """Whole steps that `steps` may run in one launch (1: a launch a step)."""
        return self._steps_at_once

    def step(self, h):
        """Advance every circle by h; returns the simulated time covered (h, or less when cut)."""
        raise NotImplementedError

    def steps(self, h, count):
        """`count` whole steps of length h, as `count` calls of `step` would make them."""
        for _ in range(count):
            self.step(h)

    def work(self) -> dict:
        """The counters of work so far, by name (`WORK_COUNTERS`)."""
        return {name: getattr(self, name) for name in self.WORK_COUNTERS}

    def stats(self) -> dict:
        """What the scheme adds to `Simulation.stats` (nothing by default)."""
        return {}

