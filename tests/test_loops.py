"""`loops.each` visits every item once, whatever n is against the items per iteration."""
import numpy as np
import pytest
import taichi as ti

from circles import loops


@ti.func
def _visit(i, a: ti.template()):
    ti.atomic_add(a[0][i], i + 1)


@ti.kernel
def visit_all(n: ti.i32, hits: ti.types.ndarray(ndim=1), serial: ti.template()):
    loops.each(n, _visit, (hits,), serial)


@pytest.mark.parametrize("serial", [False, True])
@pytest.mark.parametrize("n", [0, 1, 7, 8, 9, 17, 1001])
def test_each_visits_every_item_once(circles_cpu, n, serial):
    # Two spare entries past n must stay untouched; item i adds i + 1 once.
    hits = ti.ndarray(ti.i32, shape=n + 2)
    hits.fill(0)
    visit_all(n, hits, serial)
    expected = np.concatenate([np.arange(1, n + 1), [0, 0]])
    assert np.array_equal(hits.to_numpy(), expected)


def test_unroll_is_cpu_unroll_on_a_cpu_and_one_on_a_gpu(circles_cpu):
    # On the CPU the loops take CPU_UNROLL items per iteration; a GPU keeps one per thread.
    expected = 1 if circles_cpu.backend.current_arch() == "gpu" else loops.CPU_UNROLL
    assert loops.unroll() == expected
