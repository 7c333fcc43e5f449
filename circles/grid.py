"""Uniform-grid broadphase rebuilt by counting sort.

Stages: cell index and slot of each circle (on a GPU one atomic add per circle, on a CPU
plain adds in one part of the circles per thread, see `enter_cells`), prefix sum of the
counts (in chunks and groups of chunks, see `prefix_sum`), scatter of ids into `sorted_ids`.
`cell_start[c]:cell_start[c+1]` then lists the circles of cell c, numbered as
`geometry.cell_index` says (in a walled box inside a frame of empty cells, so that
neighbouring cells are at fixed offsets with no edge tests). On a GPU the slot order inside
a cell depends on thread timing; nothing that feeds the state may depend on it, and nothing
does (see geometry.key_less).

The cell side is at least the requested reach, so the 3 x 3 block around a circle's cell
holds every circle within that reach. The number of cells is capped (`max_cells`): when the
box would need more, cells are made larger, never smaller than the reach.
"""

import taichi as ti

from . import launch
from .backend import cpu_threads
from .geometry import cell_index, cell_total, cells_in, spans
from .loops import each, unroll


#: Cells per chunk of the prefix sum (one thread sums a chunk), on a CPU and on a GPU: a GPU
#: runs many more threads, each slower, so its chunks are shorter.
PREFIX_CHUNK = {"cpu": 2048, "gpu": 256}
#: Chunks per group: the chunk totals are summed within groups in parallel, and only the group
#: totals one after another (a serial pass of cells / (chunk x group) items). 0: one serial
#: pass over the chunk totals and two tasks fewer. That suits a CPU: its serial pass covers
#: cells / 2048 items, and at small N a step costs mostly its task dispatches.
PREFIX_GROUP = {"cpu": 0, "gpu": 1024}


def _scan_shape():
    """(chunk, group) of the prefix sum for the arch Taichi runs on (read when a kernel compiles)."""
    arch = ti.lang.impl.current_cfg().arch
    key = "cpu" if arch in (ti.x64, ti.arm64) else "gpu"
    return PREFIX_CHUNK[key], PREFIX_GROUP[key]


def _warp_fill():
    """Whether the last pass of the prefix sum runs one warp per chunk (CUDA only)."""
    return ti.lang.impl.current_cfg().arch == ti.cuda


#: Lanes of a CUDA warp.
WARP = 32


@ti.func
def _position(i, a: ti.template()):
    """Circle i's stored position: a = (pos,)."""
    return a[0][i]


@ti.func
def _keep_nothing(i, p, a: ti.template()):
    """A grid build's pass stores nothing of its own."""


@ti.func
def build_cells(pos: ti.template(), include: ti.template(), cell_of: ti.template(), slot: ti.template(),
                cell_count: ti.template(), cell_start: ti.template(), sorted_ids: ti.template(), parts: ti.template(),
                ncx, ncy, inv_cw, inv_ch, transposed, masked: ti.template(), periodic: ti.template(),
                serial: ti.template()):
    """The grid's stages as top-level loops, so that a scheme can run them inside its own kernel;
    with `serial`, every loop on one thread (see backend.serial_loops). Masked (circles whose
    `include` is 0 left out, cell_of -1): an atomic add per circle, as on a GPU.

    `cell_count` must be all zero on entry; it is left all zero (each chunk clears its counts
    once it has turned them into starts), so no pass clears it.
    """
    if ti.static(masked):
        ti.loop_config(serialize=serial)
        for i in range(pos.shape[0]):
            if include[i] != 0:
                enter_cell(i, pos[i], cell_of, slot, cell_count, ncx, ncy, inv_cw, inv_ch, transposed, periodic)
            else:
                cell_of[i] = -1
    else:
        enter_cells(pos.shape[0], _position, _keep_nothing, (pos,), cell_of, slot, cell_count, sorted_ids, parts, ncx,
                    ncy, inv_cw, inv_ch, transposed, ti.f64, periodic, serial)
    finish_cells(cell_of, slot, cell_count, cell_start, sorted_ids, ncx, ncy, periodic, serial)


@ti.func
def cell_at(p, ncx, ncy, inv_cw, inv_ch, transposed, periodic: ti.template()):
    """The cell of a circle at p. The grid's x axis is the box's x, or its y when `transposed`
    is not 0 (see `Grid`); inv_cw and inv_ch are the cells per unit length along the grid's x
    and y."""
    u = ti.select(transposed != 0, p[1], p[0])
    v = ti.select(transposed != 0, p[0], p[1])
    # Positions may sit a round-off outside the box (or outside [0, W) in a
    # periodic box before wrapping): clamp and wrap the cell coordinates.
    cx = ti.cast(ti.floor(ti.cast(u, ti.f64) * inv_cw), ti.i32)
    cy = ti.cast(ti.floor(ti.cast(v, ti.f64) * inv_ch), ti.i32)
    cx = ti.min(ti.max(cx, 0), ncx - 1)
    cy = ti.min(ti.max(cy, 0), ncy - 1)
    return cell_index(cx, cy, ncx, periodic)


@ti.func
def enter_cell(i, p, cell_of: ti.template(), slot: ti.template(), cell_count: ti.template(), ncx, ncy, inv_cw,
               inv_ch, transposed, periodic: ti.template()):
    """Count circle i, at p, into its cell with an atomic add."""
    c = cell_at(p, ncx, ncy, inv_cw, inv_ch, transposed, periodic)
    cell_of[i] = c
    slot[i] = ti.atomic_add(cell_count[c], 1)


#: Iterations of the loop over a CPU's parts in `enter_cells` per part: Taichi (1.7) cuts a
#: parallel loop of m iterations on T threads into T tasks of max(m / T, 512) iterations each,
#: so a loop of 512 T iterations gives each thread one task, whose first iteration counts one
#: part. Another cut would only run the parts on fewer threads.
PART_ITERATIONS = 512
#: Circles that `enter_cells` takes at a time on a CPU: their loads first, then their stores.
CPU_GROUP = 8


def count_parts() -> int:
    """Parts of the circles' range that `enter_cells` counts without atomics: one per CPU
    thread (`backend.cpu_threads`); 0 on a GPU, which counts with an atomic add per circle
    (read when a kernel compiles)."""
    return cpu_threads() if ti.lang.impl.current_cfg().arch in (ti.x64, ti.arm64) else 0


@ti.func
def _part_range(n, k, parts):
    """The circles [lo, hi) of part k of `parts`."""
    lo = ti.cast(ti.cast(n, ti.i64) * k // parts, ti.i32)
    hi = ti.cast(ti.cast(n, ti.i64) * (k + 1) // parts, ti.i32)
    return lo, hi


@ti.func
def _count_plain(i, c, cell_count: ti.template(), slot: ti.template()):
    """Circle i counted into cell c with a plain add (by the one thread that counts c)."""
    s = cell_count[c]
    cell_count[c] = s + 1
    slot[i] = s


@ti.func
def _count_owned(i, c, own_lo, own_hi, lo, strays, cell_count: ti.template(), slot: ti.template(),
                 stray: ti.template()):
    """Circle i of a part (from lo) counted into cell c with a plain add when the part owns c,
    else set aside as the part's next stray; returns the part's strays."""
    if own_lo <= c and c < own_hi:
        _count_plain(i, c, cell_count, slot)
    else:
        stray[lo + strays] = i
        strays += 1
    return strays


@ti.func
def enter_cells(n, place: ti.template(), keep: ti.template(), args: ti.template(), cell_of: ti.template(),
                slot: ti.template(), cell_count: ti.template(), stray: ti.template(), parts: ti.template(), ncx, ncy,
                inv_cw, inv_ch, transposed, real: ti.template(), periodic: ti.template(),
                serial: ti.template()):
    """The first stage for every circle i < n, fused into a scheme's own pass (such as a move):
    p = place(i, args) says where circle i is (it must store nothing but rarely), keep(i, p,
    args) stores what the pass stores for it, and the grid gets its cell in cell_of[i] and its
    slot in the cell.

    On a GPU: one atomic add per circle. On a CPU two things made such a pass slow: an atomic
    add drains the core's pending stores, and Taichi reloads an array's address after every
    store (see circles/loops.py), so a load that follows a store waits. There the circles'
    range is cut into one part per thread (`count_parts`), and each thread counts its part
    with plain adds into the cells it owns, CPU_GROUP circles at a time: their loads and
    arithmetic first, then their stores, then their counts. Part k owns the cells from the
    cell its first circle had at the last count up to part k + 1's: about the cells of its
    circles, which are kept in cell order. A circle in a cell that another part owns (near the
    parts' border, or far from where the last reorder left it) is set aside as a stray (in
    `stray`, which the scatter overwrites later, at lo_k + its rank) and counted after all
    parts, on one thread. The slots then do not depend on thread timing. `parts` holds the
    owned ranges' starts (count_parts() + 1 entries) and each part's number of strays
    (count_parts() more); any cell_of on entry is valid, a poor one only makes more strays.
    """
    np_ = ti.static(count_parts())
    if ti.static(np_ == 0):
        ti.loop_config(serialize=serial)
        for i in range(n):
            p = place(i, args)
            keep(i, p, args)
            enter_cell(i, p, cell_of, slot, cell_count, ncx, ncy, inv_cw, inv_ch, transposed, periodic)
    else:
        ti.loop_config(serialize=True)
        for _ in range(1):
            owned_starts(n, cell_of, parts, ncx, ncy, periodic)
        ti.loop_config(serialize=serial)
        for it in range(np_ * PART_ITERATIONS):
            if it % PART_ITERATIONS == 0:
                count_part(it // PART_ITERATIONS, n, place, keep, args, cell_of, slot, cell_count, stray, parts, ncx,
                           ncy, inv_cw, inv_ch, transposed, real, periodic)
        ti.loop_config(serialize=True)
        for _ in range(1):
            count_strays(n, cell_of, slot, cell_count, stray, parts)


@ti.func
def owned_starts(n, cell_of: ti.template(), parts: ti.template(), ncx, ncy, periodic: ti.template()):
    """The first stage of `enter_cells` on a CPU, on one thread: the cells each part owns, from
    the cells its first circle had at the last count."""
    np_ = ti.static(count_parts())
    ncells = cells_in(ncx, ncy, periodic)
    parts[0] = 0
    for k in range(1, np_):
        lo, _hi = _part_range(n, k, np_)
        parts[k] = ti.max(parts[k - 1], ti.min(ti.max(cell_of[lo], 0), ncells))
    parts[np_] = ncells


@ti.func
def count_part(k, n, place: ti.template(), keep: ti.template(), args: ti.template(), cell_of: ti.template(),
               slot: ti.template(), cell_count: ti.template(), stray: ti.template(), parts: ti.template(), ncx, ncy,
               inv_cw, inv_ch, transposed, real: ti.template(), periodic: ti.template()):
    """Part k of `enter_cells` on a CPU (one thread): its circles placed and kept, and counted
    into the cells the part owns, the others set aside as strays."""
    np_ = ti.static(count_parts())
    g = ti.static(CPU_GROUP)
    lo, hi = _part_range(n, k, np_)
    own_lo = parts[k]
    own_hi = parts[k + 1]
    strays = 0
    for q in range((hi - lo) // g):
        first = lo + q * g
        ps = ti.Matrix.zero(real, g, 2)
        cs = ti.Vector.zero(ti.i32, g)
        for u in ti.static(range(g)):
            p = place(first + u, args)
            ps[u, 0] = p[0]
            ps[u, 1] = p[1]
            cs[u] = cell_at(p, ncx, ncy, inv_cw, inv_ch, transposed, periodic)
        for u in ti.static(range(g)):
            keep(first + u, ti.Vector([ps[u, 0], ps[u, 1]], dt=real), args)
        for u in ti.static(range(g)):
            cell_of[first + u] = cs[u]
        for u in ti.static(range(g)):
            strays = _count_owned(first + u, cs[u], own_lo, own_hi, lo, strays, cell_count, slot, stray)
    for i in range(lo + (hi - lo) // g * g, hi):
        p = place(i, args)
        keep(i, p, args)
        c = cell_at(p, ncx, ncy, inv_cw, inv_ch, transposed, periodic)
        cell_of[i] = c
        strays = _count_owned(i, c, own_lo, own_hi, lo, strays, cell_count, slot, stray)
    parts[np_ + 1 + k] = strays


@ti.func
def count_strays(n, cell_of: ti.template(), slot: ti.template(), cell_count: ti.template(), stray: ti.template(),
                 parts: ti.template()):
    """The last stage of `enter_cells` on a CPU, on one thread: every part's strays counted, in
    the parts' order."""
    np_ = ti.static(count_parts())
    for k in range(np_):
        lo, _hi = _part_range(n, k, np_)
        for m in range(parts[np_ + 1 + k]):
            i = stray[lo + m]
            _count_plain(i, cell_of[i], cell_count, slot)


@ti.func
def finish_cells(cell_of: ti.template(), slot: ti.template(), cell_count: ti.template(), cell_start: ti.template(),
                 sorted_ids: ti.template(), ncx, ncy, periodic: ti.template(), serial: ti.template()):
    """The stages after counting: cell starts, then ids scattered into their slots; with
    `serial`, every loop on one thread (see backend.serial_loops)."""
    prefix_sum(cell_count, cell_start, cells_in(ncx, ncy, periodic), serial)
    if ti.static(count_parts() == 0):
        each(cell_of.shape[0], _scatter, (cell_of, slot, cell_start, sorted_ids), serial)
    else:
        # CPU_GROUP circles at a time, their loads before their stores (see `enter_cells`).
        g = ti.static(CPU_GROUP)
        ti.loop_config(serialize=serial)
        for q in range((cell_of.shape[0] + g - 1) // g):
            scatter_group(q, cell_of, slot, cell_start, sorted_ids)


@ti.func
def scatter_group(q, cell_of: ti.template(), slot: ti.template(), cell_start: ti.template(),
                  sorted_ids: ti.template()):
    """The ids of circles q CPU_GROUP to (q + 1) CPU_GROUP scattered into their slots, their
    loads before their stores (see `enter_cells`)."""
    g = ti.static(CPU_GROUP)
    n = cell_of.shape[0]
    at = ti.Vector.zero(ti.i32, g)
    for u in ti.static(range(g)):
        i = q * g + u
        at[u] = -1
        if i < n:
            c = cell_of[i]
            if c >= 0:
                at[u] = cell_start[c] + slot[i]
    for u in ti.static(range(g)):
        if at[u] >= 0:
            sorted_ids[at[u]] = q * g + u


@ti.func
def _scatter(i, a: ti.template()):
    """Circle i's id into its slot of `sorted_ids`: a = (cell_of, slot, cell_start, sorted_ids)."""
    c = a[0][i]
    if c >= 0:
        a[3][a[2][c] + a[1][i]] = i


@ti.func
def prefix_sum(count: ti.template(), start: ti.template(), ncells, serial: ti.template()):
    """start[c] = count[0] + ... + count[c - 1] for c <= ncells, and count[:ncells] set to 0.

    Integer sums, so the result is exact whatever the order. Passes (each loop one task):
    1. each chunk's total, kept in start[] at the chunk's end (on CUDA one warp per chunk,
       `_warp_chunk_totals`);
    2. within each group of chunks, the running total at each chunk end (on CUDA one warp per
       group, `_warp_group_totals`);
    3. serially, each group's end gets the total of all groups before it;
    4. the other chunk ends get the total of the groups before theirs
       (without groups, passes 2 to 4 are one serial running total over the chunk ends);
    5. each chunk's starts from its (now final) first start, and its counts cleared (on CUDA
       one warp per chunk, see `_warp_fill_starts`).
    With `serial` (a CPU only), the parallel passes run on one thread too.
    """
    chunk, group = ti.static(_scan_shape())
    nchunks = (ncells + chunk - 1) // chunk
    if ti.static(_warp_fill()):
        _warp_chunk_totals(count, start, ncells, nchunks, chunk)
    else:
        ti.loop_config(serialize=serial)
        for b in range(nchunks):
            chunk_total(b, count, start, ncells)
    if ti.static(group == 0):
        ti.loop_config(serialize=True)
        for _ in range(1):
            chunk_ends(start, ncells)
    else:
        ngroups = (nchunks + group - 1) // group
        if ti.static(_warp_fill()):
            _warp_group_totals(start, ncells, nchunks, ngroups, chunk, group)
        else:
            for g in range(ngroups):
                running = 0
                for b in range(g * group, ti.min((g + 1) * group, nchunks)):
                    hi = ti.min((b + 1) * chunk, ncells)
                    running += start[hi]
                    start[hi] = running
        ti.loop_config(serialize=True)
        for g in range(1, ngroups):
            start[ti.min((g + 1) * group * chunk, ncells)] += start[g * group * chunk]
        for b in range(nchunks):
            g = b // group
            if g > 0 and (b + 1) % group != 0 and b != nchunks - 1:
                start[(b + 1) * chunk] += start[g * group * chunk]
    start[0] = 0
    if ti.static(_warp_fill()):
        _warp_fill_starts(count, start, ncells, nchunks, chunk)
    else:
        ti.loop_config(serialize=serial)
        for b in range(nchunks):
            chunk_starts(b, count, start, ncells)


@ti.func
def chunk_total(b, count: ti.template(), start: ti.template(), ncells):
    """Pass 1 of `prefix_sum` for chunk b: its total, at its end in `start`."""
    chunk = ti.static(_scan_shape()[0])
    lo = b * chunk
    hi = ti.min(lo + chunk, ncells)
    total = 0
    for c in range(lo, hi):
        total += count[c]
    start[hi] = total


@ti.func
def chunk_ends(start: ti.template(), ncells):
    """Passes 2 to 4 of `prefix_sum` without groups, on one thread: the running total over the
    chunk ends."""
    chunk = ti.static(_scan_shape()[0])
    for b in range(1, (ncells + chunk - 1) // chunk):
        start[ti.min((b + 1) * chunk, ncells)] += start[b * chunk]


@ti.func
def chunk_starts(b, count: ti.template(), start: ti.template(), ncells):
    """Pass 5 of `prefix_sum` for chunk b (after start[0] = 0)."""
    chunk = ti.static(_scan_shape()[0])
    lo = b * chunk
    _run_starts(count, start, lo, ti.min(lo + chunk, ncells))


@ti.func
def _run_starts(count: ti.template(), start: ti.template(), lo, hi):
    """start[c + 1] = start[c] + count[c] for c in [lo, hi - 1) from start[lo], and
    count[lo:hi] set to 0, `unroll()` cells per iteration (see `loops`)."""
    u = ti.static(unroll())
    running = start[lo]
    c = lo
    while c + u <= hi - 1:
        for k in ti.static(range(u)):
            running += count[c + k]
            start[c + k + 1] = running
            count[c + k] = 0
        c += u
    while c < hi - 1:
        running += count[c]
        start[c + 1] = running
        count[c] = 0
        c += 1
    count[hi - 1] = 0


@ti.func
def _warp_inclusive(x, lane):
    """The sum of x over lanes 0..lane of the warp (a scan by register shuffles; every lane
    of the warp must take part)."""
    for d in ti.static((1, 2, 4, 8, 16)):
        y = ti.simt.warp.shfl_up_i32(ti.u32(0xFFFFFFFF), x, d)
        if lane >= d:
            x += y
    return x


@ti.func
def _warp_chunk_totals(count: ti.template(), start: ti.template(), ncells, nchunks, chunk: ti.template()):
    """Pass 1 of `prefix_sum` on CUDA: one warp per chunk, reading 32 neighbouring cells at a
    time (one thread per chunk would read 32 cells a chunk apart at each load)."""
    ti.loop_config(block_dim=128)
    for t in range(nchunks * WARP):
        b = t // WARP
        lane = t % WARP
        lo = b * chunk
        hi = ti.min(lo + chunk, ncells)
        x = 0
        for s in range((chunk + WARP - 1) // WARP):
            c = lo + s * WARP + lane
            if c < hi:
                x += count[c]
        x = _warp_inclusive(x, lane)
        if lane == WARP - 1:
            start[hi] = x


@ti.func
def _warp_group_totals(start: ti.template(), ncells, nchunks, ngroups, chunk: ti.template(), group: ti.template()):
    """Pass 2 of `prefix_sum` on CUDA: one warp per group of chunks, 32 chunk ends at a time,
    so that a group's running totals take group / 32 dependent steps, not group."""
    ti.loop_config(block_dim=128)
    for t in range(ngroups * WARP):
        g = t // WARP
        lane = t % WARP
        b_hi = ti.min((g + 1) * group, nchunks)
        carry = 0
        for s in range((group + WARP - 1) // WARP):
            b = g * group + s * WARP + lane
            end = ti.min((b + 1) * chunk, ncells)
            x = 0
            if b < b_hi:
                x = start[end]
            x = _warp_inclusive(x, lane)
            if b < b_hi:
                start[end] = carry + x
            carry += ti.simt.warp.shfl_sync_i32(ti.u32(0xFFFFFFFF), x, WARP - 1)


@ti.func
def _warp_fill_starts(count: ti.template(), start: ti.template(), ncells, nchunks, chunk: ti.template()):
    """Pass 5 of `prefix_sum` on CUDA: one warp per chunk, 32 cells at a time, so that the
    loads and stores of a warp are one contiguous run (one thread per chunk writes 32 runs).

    Each lane takes one cell; a scan by register shuffles gives the sums within the 32, and
    the running total of the chunk is carried from lane 31. The loop covers whole warps
    (nchunks * 32 items, thread blocks a multiple of 32), so every lane takes part in every
    shuffle; lanes past the chunk's end add 0 and write nothing.
    """
    full = ti.u32(0xFFFFFFFF)
    ti.loop_config(block_dim=128)
    for t in range(nchunks * WARP):
        b = t // WARP
        lane = t % WARP
        lo = b * chunk
        hi = ti.min(lo + chunk, ncells)
        carry = start[lo]
        for s in range((chunk + WARP - 1) // WARP):
            c = lo + s * WARP + lane
            x = 0
            if c < hi:
                x = count[c]
            x = _warp_inclusive(x, lane)
            if c < hi - 1:
                start[c + 1] = carry + x
            if c < hi:
                count[c] = 0
            carry += ti.simt.warp.shfl_sync_i32(full, x, WARP - 1)


@launch.kernel
def _build(pos: ti.types.ndarray(ndim=1), include: ti.types.ndarray(ndim=1), cell_of: ti.types.ndarray(ndim=1),
           slot: ti.types.ndarray(ndim=1), cell_count: ti.types.ndarray(ndim=1),
           cell_start: ti.types.ndarray(ndim=1), sorted_ids: ti.types.ndarray(ndim=1),
           parts: ti.types.ndarray(ndim=1), ncx: ti.i32, ncy: ti.i32, inv_cw: ti.f64, inv_ch: ti.f64,
           transposed: ti.i32, masked: ti.template(), periodic: ti.template(), serial: ti.template()):
    build_cells(pos, include, cell_of, slot, cell_count, cell_start, sorted_ids, parts, ncx, ncy, inv_cw, inv_ch,
                transposed, masked, periodic, serial)


class Grid:
    """Cell lists over a fixed number of circles, with a fixed cell capacity.

    The cells are numbered row by row along the grid's x axis (`geometry.cell_index`), which is
    the box's x, or with `transposed` the box's y: then the grid's rows are the box's columns
    of cells. Only the numbering changes: the cells are the same, and a search visits the same
    neighbours (a search of 3 x 3 cells reads three rows, in another order). A scheme that
    splits the circles into strips of whole rows (`event.split_parts`) has borders as long as
    a row, so a box wider than tall is better numbered along its y axis (see
    `simulation.TRANSPOSE_WIDE_GRIDS`).
    """

    def __init__(self, n: int, box, periodic: bool, max_cells=None, serial=False, transposed=False):
        """`serial`: build on one thread (see backend.serial_loops); `transposed`: the grid's x
        axis is the box's y (see above)."""
        self.n = n
        self.serial = bool(serial)
        self.transposed = bool(transposed)
        self.box = (float(box[0]), float(box[1]))
        # The box's extent along the grid's x and y axes.
        self.extent = self.box[::-1] if self.transposed else self.box
        self.periodic = periodic
        self.max_cells = max_cells or max(64, 3 * n)
        self.cell_of = ti.ndarray(ti.i32, shape=n)
        self.slot = ti.ndarray(ti.i32, shape=n)
        self.sorted_ids = ti.ndarray(ti.i32, shape=n)
        self.cell_count = ti.ndarray(ti.i32, shape=self.max_cells)
        self.cell_count.fill(0)
        self.cell_start = ti.ndarray(ti.i32, shape=self.max_cells + 1)
        self._dummy_mask = ti.ndarray(ti.i32, shape=1)
        # The owned cell ranges and stray counts of a CPU's count (see `enter_cells`).
        self.parts = ti.ndarray(ti.i32, shape=2 * count_parts() + 1)
        self.ncx = self.ncy = 1
        self.reach = 0.0
        # Whether sorted_ids lists every circle, in the cell order of the last build (a build
        # without a mask, or a scheme's own; see Simulation._reorder).
        self.complete = False
        self._shapes = {}  # reach -> (ncx, ncy): most steps ask for the reach of the step before

    def shape_for(self, reach: float):
        """Cells per axis for cells at least `reach` wide, within the cell capacity."""
        shape = self._shapes.get(reach)
        if shape is None:
            if len(self._shapes) >= 64:
                self._shapes = {}
            shape = self._shapes[reach] = self._shape_for(reach)
        return shape

    def _shape_for(self, reach: float):
        w, h = self.extent
        reach = max(reach, 1e-300)
        ncx = max(1, min(int(w / reach), 1 << 20))
        ncy = max(1, min(int(h / reach), 1 << 20))
        while cell_total(ncx, ncy, self.periodic) > self.max_cells:
            ncx = max(1, int(ncx / 1.5))
            ncy = max(1, int(ncy / 1.5))
        return ncx, ncy

    def prepare(self, reach):
        """Set the cells for `reach`; returns the arguments of `build_cells` after pos (no mask)."""
        self.ncx, self.ncy = self.shape_for(reach)
        self.reach = reach
        w, h = self.extent
        return (self._dummy_mask, self.cell_of, self.slot, self.cell_count, self.cell_start, self.sorted_ids,
                self.ncx, self.ncy, self.ncx / w, self.ncy / h, int(self.transposed))

    def build(self, pos, reach, include=None):
        """Sort the circles into cells at least `reach` wide; `include` (int ndarray) masks circles out."""
        mask, cell_of, slot, cell_count, cell_start, sorted_ids, *shape = self.prepare(reach)
        masked = include is not None
        _build(pos, include if masked else mask, cell_of, slot, cell_count, cell_start, sorted_ids, self.parts, *shape,
               masked, self.periodic, self.serial)
        self.complete = not masked

    def args(self):
        """The grid's arrays and sizes, in the order the scheme kernels take them."""
        rows, segs = spans(self.ncx, self.ncy, self.periodic)
        return (self.cell_of, self.cell_start, self.sorted_ids, self.ncx, self.ncy, rows, segs)

    def cells_numpy(self):
        """(cell_of, cell_start, sorted_ids) as numpy arrays, for tests."""
        ncells = cell_total(self.ncx, self.ncy, self.periodic)
        return (self.cell_of.to_numpy(), self.cell_start.to_numpy()[: ncells + 1], self.sorted_ids.to_numpy())
