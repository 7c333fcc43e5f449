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


def scan_with(chunk, group):
    arch = circles.backend.current_arch()
    saved = grid.PREFIX_CHUNK[arch], grid.PREFIX_GROUP[arch]
    grid.PREFIX_CHUNK[arch], grid.PREFIX_GROUP[arch] = chunk, group

    @ti.kernel
    def scan(count: ti.types.ndarray(ndim=1), start: ti.types.ndarray(ndim=1), ncells: ti.i32):
        grid.prefix_sum(count, start, ncells)

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
@pytest.mark.parametrize("ncells", [1, 2, 7, 30, 31, 500, 20011])
def test_prefix_sum_matches_numpy(circles_cpu, chunk, group, ncells):
    counts = np.random.default_rng(ncells).integers(0, 5, ncells)
    count, start = scan_with(chunk, group)(counts)
    expected = np.concatenate([[0], np.cumsum(counts)])
    assert np.array_equal(start[: ncells + 1], expected)
    assert (count[:ncells] == 0).all()  # counts are cleared for the next build ...
    assert (count[ncells:] == 7).all() and (start[ncells + 1:] == -5).all()  # ... and nothing past them is touched


def test_cells_list_every_circle_once(circles_cpu):
    rng = np.random.default_rng(5)
    n, box = 5000, (40.0, 25.0)
    pos = ti.Vector.ndarray(2, ti.f64, shape=n)
    p = rng.uniform((0, 0), box, (n, 2))
    pos.from_numpy(p)
    g = grid.Grid(n, box, periodic=False)
    g.build(pos, 1.0)
    cell_of, cell_start, sorted_ids = g.cells_numpy()
    expected = (np.minimum((p[:, 1] * g.ncy / box[1]).astype(int), g.ncy - 1) * g.ncx
                + np.minimum((p[:, 0] * g.ncx / box[0]).astype(int), g.ncx - 1))
    assert np.array_equal(cell_of, expected)
    assert np.array_equal(np.sort(sorted_ids), np.arange(n))
    assert np.array_equal(np.diff(cell_start), np.bincount(expected, minlength=g.ncx * g.ncy))
    for c in rng.integers(0, g.ncx * g.ncy, 200):
        assert (cell_of[sorted_ids[cell_start[c]:cell_start[c + 1]]] == c).all()
