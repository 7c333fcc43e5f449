"""The grid's prefix sum and cell lists against numpy, on every path through the chunked scan.

The scan's chunk and group sizes are read when a kernel compiles, so each case compiles a
kernel of its own with the sizes patched in: tiny sizes reach several groups and partial
last chunks and groups with a few hundred cells.
"""

import numpy as np
import pytest
import taichi as ti

import circles
from circles import grid


def scan_with(chunk, group, serial=False):
    arch = circles.backend.current_arch()
    saved = grid.PREFIX_CHUNK[arch], grid.PREFIX_GROUP[arch]
    grid.PREFIX_CHUNK[arch], grid.PREFIX_GROUP[arch] = chunk, group

    @ti.kernel
    def scan(count: ti.types.ndarray(ndim=1), start: ti.types.ndarray(ndim=1), ncells: ti.i32):
        grid.prefix_sum(count, start, ncells, serial)

    def run(counts):
        count = ti.ndarray(ti.i32, shape=len(counts) + 3)
        count.from_numpy(np.concatenate([counts, [7, 7, 7]]).astype(np.int32))
        start = ti.ndarray(ti.i32, shape=len(counts) + 4)
        start.fill(-5)
        try:
            scan(count, start, len(counts))
        finally:
            grid.PREFIX_CHUNK[arch], grid.PREFIX_GROUP[arch] = saved
        return count.to_numpy(), start.to_numpy()
    return run


@pytest.mark.parametrize("chunk,group", [(3, 2), (5, 4), (1, 1), (2048, 64), (256, 1024), (3, 0), (2048, 0)])
@pytest.mark.parametrize("ncells", [1, 2, 7, 30, 31, 500, 20011, 300_007])
def test_prefix_sum_matches_numpy(circles_cpu, chunk, group, ncells):
    check_prefix_sum(chunk, group, ncells, False)


@pytest.mark.parametrize("chunk,group", [(3, 2), (2048, 0)])
@pytest.mark.parametrize("ncells", [1, 31, 20011])
def test_prefix_sum_on_one_thread_matches_numpy(circles_cpu, chunk, group, ncells):
    """The serial variant, which a small discrete step runs (backend.SERIAL_N)."""
    check_prefix_sum(chunk, group, ncells, True)


def check_prefix_sum(chunk, group, ncells, serial):
    counts = np.random.default_rng(ncells).integers(0, 5, ncells)
    count, start = scan_with(chunk, group, serial)(counts)
    expected = np.concatenate([[0], np.cumsum(counts)])
    assert np.array_equal(start[: ncells + 1], expected)
    assert (count[:ncells] == 0).all()  # counts are cleared for the next build ...
    assert (count[ncells:] == 7).all() and (start[ncells + 1:] == -5).all()  # ... and nothing past them is touched


def cell_xy(p, ncx, ncy, box, transposed=False):
    """The cell coordinates (cx, cy) along the grid's axes of positions p on ncx x ncy cells over
    the box: the box's x and y, or y and x when `transposed` (`grid.Grid`)."""
    if transposed:
        p, box = p[:, ::-1], box[::-1]
    cx = np.minimum((p[:, 0] * ncx / box[0]).astype(int), ncx - 1)
    cy = np.minimum((p[:, 1] * ncy / box[1]).astype(int), ncy - 1)
    return cx, cy


def check_walled_cells(g, p, box):
    """The cells of grid g, built on positions p in a walled box, list every circle once, in its
    own cell."""
    cell_of, cell_start, sorted_ids = g.cells_numpy()
    cx, cy = cell_xy(p, g.ncx, g.ncy, box, g.transposed)
    # Walled layout: rows of ncx + 1 cells, the first of each empty, an empty row below and above.
    expected = (cy + 1) * (g.ncx + 1) + cx + 1
    ncells = (g.ncy + 2) * (g.ncx + 1) + 1
    assert np.array_equal(cell_of, expected)
    assert np.array_equal(np.sort(sorted_ids), np.arange(len(p)))
    assert len(cell_start) == ncells + 1
    assert np.array_equal(np.diff(cell_start), np.bincount(expected, minlength=ncells))
    assert (cell_of[sorted_ids] == np.repeat(np.arange(ncells), np.diff(cell_start))).all()


@pytest.mark.parametrize("transposed", [False, True])
def test_cells_list_every_circle_once(circles_cpu, transposed):
    """Every circle once, in its cell; transposed, the grid's rows are the box's columns: 25 rows
    of 40 cells become 40 rows of 25."""
    rng = np.random.default_rng(5)
    n, box = 5000, (40.0, 25.0)
    pos = ti.Vector.ndarray(2, ti.f64, shape=n)
    p = rng.uniform((0, 0), box, (n, 2))
    pos.from_numpy(p)
    g = grid.Grid(n, box, periodic=False, transposed=transposed)
    g.build(pos, 1.0)
    assert (g.ncx, g.ncy) == ((25, 40) if transposed else (40, 25))
    check_walled_cells(g, p, box)


@pytest.mark.parametrize("serial,transposed", [(False, False), (True, False), (False, True)])
def test_cells_counted_in_parts_list_every_circle_once(circles_cpu, serial, transposed):
    """A CPU counts circles into cells in parts without atomics (grid.enter_cells): each part
    owns the cells from where its first circle was at the last count, and circles in cells
    that another part owns are counted afterwards as strays. Whatever cell_of holds on entry
    (left over from other positions, or garbage), the cells must list every circle once, in
    its own cell; circles in cell order must leave few strays (the point of the parts)."""
    rng = np.random.default_rng(11)
    n, box = 20_003, (120.0, 70.0)  # not a multiple of the group of 8 circles
    g = grid.Grid(n, box, periodic=False, serial=serial, transposed=transposed)
    pos = ti.Vector.ndarray(2, ti.f64, shape=n)

    def check(p):
        pos.from_numpy(p)
        g.build(pos, 1.0)
        check_walled_cells(g, p, box)
        parts = grid.count_parts()
        return int(g.parts.to_numpy()[parts + 1:].sum()) if parts else 0

    scattered = rng.uniform((0, 0), box, (n, 2))
    check(scattered)  # a fresh grid: cell_of as allocated
    garbage = rng.integers(-10**9, 10**9, n).astype(np.int32)
    g.cell_of.from_numpy(garbage)
    check(scattered)
    cx, cy = cell_xy(scattered, g.ncx, g.ncy, box, transposed)
    ordered = scattered[np.lexsort((cx, cy))]
    check(ordered)  # the parts' cells now come from the ordered positions
    strays = check(ordered + rng.uniform(-0.05, 0.05, (n, 2)).clip(-ordered, np.array(box) - ordered - 1e-9))
    assert strays <= 0.01 * n


def test_cells_counted_with_atomics_as_on_a_gpu(circles_cpu, monkeypatch):
    """A GPU counts circles into cells with an atomic add each (grid.enter_cells without parts)
    and scatters them one per thread: that branch, compiled here on the CPU into a kernel of
    its own (count_parts is read when a kernel compiles), lists every circle once, in its own
    cell."""
    monkeypatch.setattr(grid, "count_parts", lambda: 0)
    nd = ti.types.ndarray(ndim=1)

    @ti.kernel
    def build(pos: nd, cell_of: nd, slot: nd, count: nd, start: nd, sorted_ids: nd, parts: nd, ncx: ti.i32,
              ncy: ti.i32, inv_cw: ti.f64, inv_ch: ti.f64, transposed: ti.i32):
        grid.build_cells(pos, parts, cell_of, slot, count, start, sorted_ids, parts, ncx, ncy, inv_cw, inv_ch,
                         transposed, False, False, False)

    rng = np.random.default_rng(12)
    n, box = 7001, (60.0, 35.0)
    p = rng.uniform((0, 0), box, (n, 2))
    pos = ti.Vector.ndarray(2, ti.f64, shape=n)
    pos.from_numpy(p)
    for transposed in (False, True):
        g = grid.Grid(n, box, periodic=False, transposed=transposed)
        _, cell_of, slot, count, start, sorted_ids, *shape = g.prepare(1.0)
        assert g.parts.shape == (1,)  # sized by the patched count_parts: no parts
        build(pos, cell_of, slot, count, start, sorted_ids, g.parts, *shape)
        check_walled_cells(g, p, box)


@pytest.mark.parametrize("periodic", [False, True])
@pytest.mark.parametrize("box,transposed", [((40.0, 25.0), False), ((40.0, 25.0), True), ((2.5, 7.0), False),
                                            ((7.0, 2.5), True), ((1.0, 1.0), False)])
def test_neighbour_ranges_cover_the_3x3_block(circles_cpu, periodic, box, transposed):
    """The slot ranges of `neighbour_range` list exactly the circles of the 3 x 3 cells around
    each circle's cell (each once, the block wrapped in a periodic box and cut at the walls),
    and the forward half (`forward_range`, walls, or periodic on 3 x 3 cells and more) lists
    each neighbouring pair exactly once."""
    from circles.geometry import forward_fits, forward_parts, forward_range, neighbour_range, spans
    rng = np.random.default_rng(9)
    n = 400
    pos = ti.Vector.ndarray(2, ti.f64, shape=n)
    p = rng.uniform((0, 0), box, (n, 2))
    pos.from_numpy(p)
    g = grid.Grid(n, box, periodic=periodic, transposed=transposed)
    g.build(pos, 1.0)
    rows, segs = spans(g.ncx, g.ncy, periodic)
    full = ti.ndarray(ti.i32, shape=(n, n + 1))
    fwd = ti.ndarray(ti.i32, shape=(n, n + 1))

    @ti.kernel
    def ranges(cell_of: ti.types.ndarray(ndim=1), cell_start: ti.types.ndarray(ndim=1),
               sorted_ids: ti.types.ndarray(ndim=1), ncx: ti.i32, ncy: ti.i32, rows: ti.i32, segs: ti.i32,
               full: ti.types.ndarray(ndim=2), fwd: ti.types.ndarray(ndim=2)):
        for own in range(sorted_ids.shape[0]):
            i = sorted_ids[own]
            c = cell_of[i]
            m = 0
            for row, seg in ti.ndrange(rows, segs):
                lo, hi = neighbour_range(c, row, seg, cell_start, ncx, ncy, periodic)
                for k in range(lo, hi):
                    full[i, m] = sorted_ids[k]
                    m += 1
            full[i, m] = -1
            m = 0
            if forward_fits(ncx, ncy, periodic):
                cx = 0
                cy = 0
                if ti.static(periodic):
                    cy = c // ncx
                    cx = c - cy * ncx
                for q in ti.static(range(forward_parts(periodic))):
                    lo, hi = forward_range(q, c, cx, cy, own, cell_start, ncx, ncy, periodic)
                    for k in range(lo, hi):
                        fwd[i, m] = sorted_ids[k]
                        m += 1
            fwd[i, m] = -1

    ranges(*g.args(), full, fwd)
    full, fwd = full.to_numpy(), fwd.to_numpy()
    ncx, ncy = g.ncx, g.ncy
    cx, cy = cell_xy(p, ncx, ncy, box, transposed)

    def near(a, b, m):  # cells a and b within one cell of each other along an axis of m cells
        d = np.abs(a - b)
        return (d <= 1) | (periodic & (d == m - 1))

    pairs = set()
    for i in range(n):
        listed = list(full[i, :list(full[i]).index(-1)])
        assert len(listed) == len(set(listed))
        expected = np.nonzero(near(cx, cx[i], ncx) & near(cy, cy[i], ncy))[0]
        assert sorted(listed) == sorted(expected)
        for j in fwd[i, :list(fwd[i]).index(-1)]:
            pairs.add((min(i, j), max(i, j)) if i != j else (i, i))
    if not periodic or (ncx >= 3 and ncy >= 3):
        every = {(i, j) for i in range(n) for j in np.nonzero(near(cx, cx[i], ncx) & near(cy, cy[i], ncy))[0] if i < j}
        assert pairs == every  # each pair once: a set of unordered pairs, and no (i, i)
        assert sum(list(fwd[i]).index(-1) for i in range(n)) == len(every)


@pytest.mark.parametrize("precision", ["f32", pytest.param("f64", marks=pytest.mark.slow)])
def test_discrete_two_level_grid_matches_one_level(circles_cpu, monkeypatch, precision):
    """A walled box with 2% of the circles 10 times larger: the discrete scheme sizes its cells
    for the small circles and lets each large one search the block its reach spans
    (discrete.wide_row). It must find exactly the pairs of the one-level grid (cells as wide as
    the largest diameter), so the states agree bit for bit, through every path: small-small,
    small-large and large-large pairs, and circles with more contacts than their list holds
    (which search their cells again)."""
    import circles
    from circles import simulation
    from circles.discrete import stepper as discrete_stepper
    from physics_util import two_size_mixture

    pos, vel, radius, box = two_size_mixture(precision)

    def run(max_fraction):
        monkeypatch.setattr(simulation, "TWO_LEVEL_MAX_FRACTION", max_fraction)
        sim = circles.Simulation.from_arrays(pos, vel, radius, mass="radius", box=box, scheme="discrete",
                                             precision=precision, dt=0.02)
        most = 0
        for _ in range(20):  # 20 steps: the arrays are reordered on the way (REORDER_EVERY)
            sim.step(1)
            most = max(most, int(sim._n_contacts.to_numpy().max()))
        return sim, most

    two, most = run(0.05)
    one, _ = run(0.0)
    assert two._two_level and not one._two_level
    # The one-level grid of this 1.5:1 box runs along the box's y (`simulation.TRANSPOSE_WIDE_GRIDS`).
    assert one.grid.transposed and not two.grid.transposed
    assert two.grid.ncx > 3 * one.grid.ncy  # the cells along x are sized for the small circles
    assert most > discrete_stepper.DISCRETE_CONTACTS  # some circle outgrew its contact list
    a, b = two.state(), one.state()
    assert np.array_equal(a.pos, b.pos) and np.array_equal(a.vel, b.vel)
    sa, sb = two.stats(), one.stats()
    assert sa["pair_collisions"] == sb["pair_collisions"] > 500
    assert sa["wall_collisions"] == sb["wall_collisions"]


@pytest.mark.parametrize("scheme", ["discrete", "event"])
def test_reorder_keeps_the_arrays_in_cell_order(circles_cpu, scheme):
    """A reorder sorts the arrays by the cells of the last step's grid; one right after another
    (whose grid no longer names the new slots) builds a grid of its own. Measured: the share
    of slots whose circle's cell (of the grid the reorder used) is at least the one before.
    After the first reorder it is 1 but for circles that crossed into another cell since the
    grid was built (an event step's grid is built at its start); after the second, with a
    grid of the current positions, every slot is in order. (Sorting the second time by the
    first one's grid, whose slots name the circles of the order before, leaves about a fifth
    of the slots out of order; the order of creation, a quarter.) The state, read in creation
    order, does not change."""
    box = (300.0, 200.0)
    sim = circles_cpu.Simulation(circles_cpu.Scene(n=20000, box=box, radius=0.5, speed=(0.5, 1.0), scheme=scheme,
                                                   seed=41))
    sim.step(3)
    before = sim.state()

    def in_order():
        cx, cy = cell_xy(sim.pos.to_numpy().astype(np.float64), sim.grid.ncx, sim.grid.ncy, box,
                         sim.grid.transposed)
        return np.mean(np.diff(cy * sim.grid.ncx + cx) >= 0)

    assert in_order() < 0.8  # the order the circles were created in
    sim._reorder()
    assert in_order() > 0.9
    sim._reorder()
    assert in_order() > 0.999
    after = sim.state()
    assert np.array_equal(before.pos, after.pos) and np.array_equal(before.vel, after.vel)


@pytest.mark.parametrize("scheme,boundary,precision", [
    ("event", "walls", "f32"), *(pytest.param(*case, marks=pytest.mark.slow) for case in
                                 (("event", "periodic", "f64"), ("discrete", "walls", "f32"), ("discrete", "periodic", "f32")))])
def test_wide_box_grid_along_y_gives_the_same_state(circles_cpu, monkeypatch, scheme, boundary, precision):
    """In a box wider than tall the grid numbers its cells along the box's y
    (`simulation.TRANSPOSE_WIDE_GRIDS`): the event queue's parts become vertical strips. Only the
    numbering changes, so 40 steps (two reorders of the arrays on the way) must leave the same
    state bit for bit as the grid along x: positions, velocities, collisions and pressure sums.
    The loops run on the CPU's threads, the event queue in parts, as a large scene's do."""
    from circles import backend, simulation
    from circles.event import stepper as event_stepper
    monkeypatch.setattr(backend, "SERIAL_N", 0)
    monkeypatch.setattr(backend, "EVENT_SERIAL_WORK", 0)
    monkeypatch.setattr(event_stepper, "PART_CIRCLES", 200)
    scene = circles_cpu.Scene(n=2000, box=(1.6, 0.4), radius=0.006, speed=(0.5, 1.0), boundary=boundary,
                              scheme=scheme, precision=precision, seed=4)

    def run(transpose):
        monkeypatch.setattr(simulation, "TRANSPOSE_WIDE_GRIDS", transpose)
        sim = circles_cpu.Simulation(scene)
        assert sim.grid.transposed == transpose
        sim.step(40)
        if scheme == "event" and backend.cpu_threads() > 1:
            assert sim._parts and sim.parts_run >= 40
        return sim

    along_y, along_x = run(True), run(False)
    # Transposed, the strips run across the box's 1.6 width: 4 times as many rows of cells.
    assert along_y.grid.ncy == along_x.grid.ncx and along_y.grid.ncx == along_x.grid.ncy
    assert along_y.grid.ncy >= 4 * along_y.grid.ncx
    a, b = along_y.state(), along_x.state()
    assert np.array_equal(a.pos, b.pos) and np.array_equal(a.vel, b.vel)
    sa, sb = along_y.stats(), along_x.stats()
    assert sa["pair_collisions"] > 2000
    for key in ("pair_collisions", "wall_collisions", "virial", "wall_impulse"):
        assert sa[key] == sb[key], key
    # A box taller than wide keeps the box's axes.
    monkeypatch.setattr(simulation, "TRANSPOSE_WIDE_GRIDS", True)
    tall = circles_cpu.Simulation(circles_cpu.Scene(n=500, box=(0.4, 1.6), radius=0.006, scheme=scheme, seed=4))
    assert not tall.grid.transposed
