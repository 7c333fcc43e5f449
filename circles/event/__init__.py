"""Scheme "event": exact collisions by time of impact, executed in parallel rounds.

Within a step [0, t_end] every circle carries a local clock tau (its position is stored at
tau). A round has three stages:

1. predict: each circle whose neighbourhood changed finds its earliest event in
   (tau, t_end], a pair time of impact (both circles brought to a common time) or a wall hit,
   chosen by the key (time, lo, hi) so that ties break by ids.
2. bound: a lower bound D_k on the time at which circle k's straight path can be disturbed
   by anything other than its own predicted event. A neighbour l can only touch k
   unexpectedly after l itself leaves its straight path (at min(t_l, D_l)), and then only
   once its deviation, growing at most at 2 vlim, has closed their straight-path gap:
       D_k = min over l in the 3x3 cells of k of F_kl(min(t_l, D_l))   (see rounds._bound_sweep).
   Delays add up along a chain of neighbours, so far events do not hold up near ones. The
   sweeps run from D = infinity down to the fixed point, which is unique, so D does not
   depend on the order in which threads update it.
3. execute: an event (i, j, t) is safe when i and j chose each other and t <= D_i, D_j.
   Safe events touch disjoint circles (no races, no atomics on velocities); the earliest
   event overall is always safe, so every round makes progress. Simultaneous safe events
   touch disjoint circles and commute, so executing them together equals any serial order.

On a CPU the step runs from one queue instead (`queue.queue_step`): the same events in the
same order with the same arithmetic, without the rounds. With several threads and one grid
level, the circles are split into parts whose events cannot touch each other within a window
of the step, and each part runs its own queue (`split.split_parts`, `split.queue_parts`).

Radius spread: cells as wide as the reach of the largest circles would hold hundreds of small
circles when a few circles are much larger. In a walled box with a few large circles (see
simulation.LARGE_RADIUS_RATIO) the queue's grid has two levels: fine cells sized for the small
circles, and coarse cells, blocks of fine cells as wide as the reach of two large circles,
that list the large circles only (`two_level.build_coarse`). A small circle meets the small
ones in its 3 x 3 fine cells and the large ones in its 3 x 3 coarse cells; a large circle
meets the small ones in the block of fine cells its reach spans and the large ones in its
coarse cells (`two_level._runs`). Every pair that can collide in the step is met from both of
its circles, as with one level, so the state is the same bit for bit.

The grid and the bounds assume every speed stays below vlim during the step. A collision
that would exceed it (a light circle hit by a heavy one) ends the step at its time: the
rounds, which execute independent events out of time order, redo the step up to that time
(the events before it are the same, by causality); the queue, which executes them in time
order, has executed exactly those when it meets the collision, and goes on with the step's
end moved to its time. Events at exactly that time, the collision among them, are executed
(a step's last instant belongs to it). The next step rebuilds the grid for the new speeds.

The package holds a module per stage: `time_of_impact` (a pair's time of impact, its cull, and
the key that orders events), `search` (a circle's earliest event among its neighbours and
walls, and the move to the step's end), `rounds` (predict, bound, execute), `calendar` and
`queue` (one queue of events), `split` (the queue split into parts, in windows of the step),
`two_level` (the coarse cells of large circles), and `stepper` (the host side of a step, which
chooses among them).
"""
# _bucket, _first_events_once and _reach_of: private, reached here by the tests.
from .calendar import _bucket  # noqa: F401
from .queue import apply_sums, queue_step
from .rounds import begin_round, begin_step, execute, more_sweeps
from .search import _first_events_once, finish  # noqa: F401
from .split import _reach_of, queue_parts, repredict, split_parts  # noqa: F401
from .stepper import EventStepper, most_events
from .time_of_impact import STEP_START, Same, event_key, own_values, pair_time, pair_time_of_impact
from .two_level import build_coarse

__all__ = ["EventStepper", "STEP_START", "Same", "apply_sums", "begin_round", "begin_step", "build_coarse",
           "event_key", "execute", "finish", "more_sweeps", "most_events", "own_values", "pair_time",
           "pair_time_of_impact", "queue_parts", "queue_step", "repredict", "split_parts"]
