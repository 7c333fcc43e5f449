"""The fast kernel calls of circles.launch launch the same compiled kernels as Taichi's own
calls, with the same arguments: runs with them and without them end in the same state, bit
for bit (np.array_equal, no tolerance: the arithmetic is the same, only the Python work
before each launch differs), and a reused launch context never reads a freed array or a
stale scalar."""

import math
import textwrap

import numpy as np
import pytest
import taichi as ti

from process_util import INIT, run_script

SCENES = {
    "discrete_walls": dict(n=1200, box=(1.2, 0.9), radius=(0.006, 0.012), boundary="walls", scheme="discrete"),
    "discrete_periodic": dict(n=1200, box=(1.2, 0.9), radius=(0.006, 0.012), boundary="periodic",
                              scheme="discrete"),
    "event_walls": dict(n=1200, box=(1.2, 0.9), radius=(0.006, 0.012), boundary="walls", scheme="event"),
    "event_periodic": dict(n=1200, box=(1.2, 0.9), radius=(0.006, 0.012), boundary="periodic", scheme="event"),
}


def _run(circles, launch, fast, cfg, precision):
    launch.enabled = fast
    try:
        sim = circles.Simulation(circles.Scene(**cfg, precision=precision, seed=5))
        # More steps than REORDER_EVERY: the reorder's kernels run, and their arrays are reused.
        sim.step(40)
        st = sim.state()
        return (st.pos, st.vel, sim.stats(), sim.rounds)
    finally:
        launch.enabled = True


# Each scene in one precision in the default suite, the other in the slow one.
DEFAULT_PRECISION = {"discrete_periodic": "f64", "discrete_walls": "f32", "event_periodic": "f64", "event_walls": "f32"}


@pytest.mark.parametrize("name,precision", [
    (name, precision) if precision == DEFAULT_PRECISION[name] else pytest.param(name, precision, marks=pytest.mark.slow)
    for precision in ("f32", "f64") for name in sorted(SCENES)])
def test_fast_calls_give_the_same_state_as_taichi_calls(circles_cpu, name, precision):
    from circles import launch

    plain = _run(circles_cpu, launch, False, SCENES[name], precision)
    fast = _run(circles_cpu, launch, True, SCENES[name], precision)
    assert np.array_equal(plain[0], fast[0])
    assert np.array_equal(plain[1], fast[1])
    assert plain[2] == fast[2]
    assert plain[3] == fast[3]
    assert plain[2]["pair_collisions"] > 100  # the scene collides: the rounds ran


@pytest.fixture(scope="module")
def fill_kernels(circles_cpu):
    from circles import launch

    @launch.kernel
    def fill(dst: ti.types.ndarray(ndim=1), value: ti.f64, count: ti.i32, real: ti.template()) -> ti.i32:
        for i in range(dst.shape[0]):
            dst[i] = ti.cast(value, real) if i < count else ti.cast(-1, real)
        return dst.shape[0]

    return fill


def test_a_reused_context_sees_new_scalars_and_new_arrays(fill_kernels):
    fill = fill_kernels
    a = ti.ndarray(ti.f64, shape=5)
    assert fill(a, 2.5, 5, ti.f64) == 5  # first call: through Taichi
    assert fill(a, 3.5, 2, ti.f64) == 5  # binds a context
    np.testing.assert_array_equal(a.to_numpy(), [3.5, 3.5, -1, -1, -1])
    assert fill(a, 4.5, 3, ti.f64) == 5  # reuses it with new scalars
    np.testing.assert_array_equal(a.to_numpy(), [4.5, 4.5, 4.5, -1, -1])
    # The sign of a zero is a change too.
    fill(a, 0.0, 5, ti.f64)
    fill(a, -0.0, 5, ti.f64)
    assert all(math.copysign(1.0, x) == -1.0 for x in a.to_numpy())
    # A new array of another size (perhaps where the old one was): a new binding, its own shape.
    del a
    b = ti.ndarray(ti.f64, shape=7)
    assert fill(b, 1.5, 7, ti.f64) == 7
    np.testing.assert_array_equal(b.to_numpy(), np.full(7, 1.5))
    # Another element type is another compiled kernel.
    c = ti.ndarray(ti.f32, shape=3)
    assert fill(c, 0.25, 3, ti.f32) == 3
    np.testing.assert_array_equal(c.to_numpy(), np.full(3, 0.25, dtype=np.float32))
    assert fill(b, 2.5, 1, ti.f64) == 7
    np.testing.assert_array_equal(b.to_numpy(), [2.5] + [-1] * 6)


def test_other_arguments_go_through_taichi(fill_kernels):
    fill = fill_kernels
    # A numpy array is not bound (Taichi copies it in and out): still filled.
    host = np.zeros(4)
    assert fill(host, 6.0, 4, ti.f64) == 4
    np.testing.assert_array_equal(host, np.full(4, 6.0))
    # Taichi's own checks still apply: a wrong element type is an error, not a wrong launch.
    d = ti.ndarray(ti.f64, shape=3)
    fill(d, 1.0, 3, ti.f64)
    fill(d, 1.0, 3, ti.f64)
    with pytest.raises(Exception):
        fill(d, 1.0, 3.5, ti.f64)


def test_a_new_taichi_program_compiles_anew(tmp_path):
    # ti.init resets every kernel: the bindings of the old program must not be used (a
    # process of its own, as ti.init must not run under the suite's simulations).
    script = textwrap.dedent("""
        import sys
        import numpy as np, taichi as ti
        import circles
        from circles import launch

        @launch.kernel
        def add(dst: ti.types.ndarray(ndim=1), value: ti.f64):
            for i in range(dst.shape[0]):
                dst[i] += value

        results = []
        for _ in range(2):
    """) + textwrap.indent(INIT, "    ") + textwrap.dedent("""
            a = ti.ndarray(ti.f64, shape=4)
            for v in (1.0, 2.0, 3.0):
                add(a, v)
            results.append(a.to_numpy())
        np.savez(sys.argv[2], first=results[0], second=results[1])
    """)
    # From a file: Taichi reads a kernel's source, which a `python -c` script does not keep.
    path = tmp_path / "reinit.py"
    path.write_text(script)
    out = run_script(f"import runpy, sys; runpy.run_path({str(path)!r}, run_name='__main__')", "cpu",
                     tmp_path / "out.npz")
    np.testing.assert_array_equal(out["first"], np.full(4, 6.0))
    np.testing.assert_array_equal(out["second"], np.full(4, 6.0))
