"""A step's stages on a CPU's threads inside one parallel loop: a team.

Each top-level loop of a Taichi kernel is a task of its own, and on a CPU a parallel task
starts the thread pool: its threads sleep between tasks, and waking them costs tens of
microseconds (`bench/diagnostics/launch_cost.py` measures it), even for a loop with nothing
to do. A discrete step runs more than a dozen such loops, which on a scene
of 1e5 circles is a fifth of the step or more.

A team kernel starts the pool once: one parallel loop with one iteration per thread (a
member; `members`), and inside it the step's stages in turn. Each stage's work is cut into
chunks, which the members take one at a time with an atomic counter of the stage; a member
that finds no chunk left waits, spinning on the stage's count of finished chunks, until every
chunk of the stage is done, and then goes on to the next stage (`stage`). A stage of one
chunk is run by one member, as a serial statement between loops would be.

A member waits only for chunks that another member took and is running, and a chunk waits for
nothing, so a team cannot deadlock, whatever the pool does: a member that starts late (as
when the pool runs the iterations one after another on one thread) finds the chunks of the
stages before taken and done, and passes through them. What a chunk does must not depend on which member
runs it, and each stage's count of chunks must be the same whenever a member reads it: a
constant, or a value that an earlier stage wrote and no later stage of the kernel changes
(a late member reads it after the stages that might). The counters live in a `sync` array of
`sync_slots()` entries, zeroed before the team starts (`clear`).

The atomics are sequentially consistent (Taichi's), so the stores of a finished chunk are seen
by every member that has seen its count.
"""
import taichi as ti

from .grid import PART_ITERATIONS, count_parts

#: Stages of a team kernel at most, and values that stages keep for later stages' counts.
STAGES = 64
VALUES = 64


def sync_slots() -> int:
    """Entries of a team's `sync` array: for each stage, one counter of chunks taken per member
    and one of chunks done (`stage`); then the VALUES values (`value_slot`)."""
    return (members() + 1) * STAGES + VALUES


def members() -> int:
    """Members of a team: one per thread of the CPU's pool (`grid.count_parts`), read when a
    kernel compiles."""
    return max(count_parts(), 1)


def loop_iterations() -> int:
    """Iterations of a team's parallel loop: PART_ITERATIONS per member, of which the first of
    each is the member (Taichi cuts the loop into one task per thread, see grid.PART_ITERATIONS)."""
    return members() * PART_ITERATIONS


@ti.func
def member_of(it):
    """The member that iteration `it` of the team's loop is, or -1 (the other iterations do
    nothing)."""
    return ti.select(it % PART_ITERATIONS == 0, it // PART_ITERATIONS, -1)


@ti.func
def clear(sync: ti.template()):
    """Every counter zeroed (a statement of the kernel before its team loop: one thread)."""
    for s in range(sync.shape[0]):
        sync[s] = 0


@ti.func
def value_slot(k):
    """The entry of `sync` that holds value k."""
    return (ti.static(members()) + 1) * STAGES + k


@ti.func
def stage(sync: ti.template(), s, chunks, body: ti.template(), args: ti.template(), me):
    """Stage s of a team, run by member `me`: body(c, args) for each chunk c < chunks, each run
    once by the member that takes it; returns once every chunk is done.

    Member m's own chunks are the m-th of `members()` equal runs of them: it takes those first,
    in order, and then helps the others with theirs. So each member mostly works on the same
    share of the circles in every stage (the first of the circles' parts, `grid.count_parts`,
    is member 0's, and so on), whose cache lines its core last wrote: chunks handed out in turn
    made the two threads of a 1e6 scene pass their lines back and forth between stages."""
    t = ti.static(members())
    base = (t + 1) * s
    for k in range(t):
        o = (me + k) % t
        first = ti.cast(ti.cast(chunks, ti.i64) * o // t, ti.i32)
        end = ti.cast(ti.cast(chunks, ti.i64) * (o + 1) // t, ti.i32)
        while True:
            c = first + ti.atomic_add(sync[base + o], 1)
            if c >= end:
                break
            body(c, args)
            ti.atomic_add(sync[base + t], 1)
    while ti.atomic_or(sync[base + t], 0) < chunks:
        pass


@ti.func
def span(c, n, size):
    """Items [lo, hi) of chunk c of n items cut into chunks of `size`."""
    lo = c * size
    return lo, ti.min(lo + size, n)


@ti.func
def chunks_of(n, size):
    """Chunks of `size` items that cover n items."""
    return (n + size - 1) // size
