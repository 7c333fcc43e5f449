"""Scheme "discrete": the fast approximate baseline (the original assignment's method).

A step moves every circle by v dt, then resolves overlapping approaching pairs with the exact
elastic impulse, then reflects circles that crossed a wall by mirroring their position.
Pairs are resolved race-free and deterministically: in each round every circle picks, among
its overlapping approaching neighbours, the pair that touched first (largest overlap over
approach speed, ties by ids), and mutual picks are resolved together. The pair with the
smallest key overall is always mutual, so each round resolves at least one pair. After the
first round only circles overlapping a resolved circle pick again; the others' picks still hold.

What a step touches: every circle once to move and once to sort into the grid and search the
forward half of its neighbour cells for overlaps (each pair is tested once); the first round
reads a mark of every circle and works on those with an approaching overlap (on a CPU each
thread first lists its part's marked circles, `_first_round_in_parts`), later rounds
visit only the circles listed as overlapping a resolved one, and the walls only the circles
the move left reaching past a wall.

On a CPU with several threads the step runs as one team (`team_step`, `circles.team`): the
same stages in one parallel loop, each cut into chunks that the threads take, with one start
of the thread pool a step instead of one per loop (a dozen or more, each as long as a step of
tens of thousands of circles on some hosts).

Radius spread: cells as wide as the largest diameter would hold hundreds of small circles
when a few circles are much larger. In a walled box with a few large circles (see
simulation.LARGE_RADIUS_RATIO) the grid has two levels: cells sized for the small circles,
which search their neighbour cells for each other, and the large circles, each of which
searches the block of cells its reach spans for all its pairs (`wide_row`). Both levels find
the same pairs, so the state is the same bit for bit as with one level.

Known errors of the method, which the benchmark measures: a circle faster than about a
diameter per step can pass through another (tunnelling), overlap is left behind, and
collisions can be missed or counted twi

The package holds the move and the search for overlapping pairs (`contacts`), the rounds of
pick and resolve, the walls and the kernels of a step (`rounds`), the step's stages as one team
of a CPU's threads (`team_step`), and the host side of a step (`stepper`).
"""
from ..geometry import wide_row
from .contacts import MOST_CONTACTS, NLARGE, PART_PICKS, per_circle
# _first_round_in_parts: private, reached here by the tests.
from .rounds import _first_round_in_parts, begin_step, list_large, more_rounds, serial_steps, walls  # noqa: F401
from .stepper import DiscreteStepper
from .team_step import team_step

__all__ = ["DiscreteStepper", "MOST_CONTACTS", "NLARGE", "PART_PICKS", "begin_step", "list_large", "more_rounds",
           "per_circle", "serial_steps", "team_step", "walls", "wide_row"]
