"""The whole-array reductions against numpy."""

import numpy as np
import pytest
import taichi as ti

from circles import reductions


def vec_array(values, dtype):
    arr = ti.Vector.ndarray(2, dtype, shape=len(values))
    arr.from_numpy(values.astype(np.float32 if dtype == ti.f32 else np.float64))
    return arr


@pytest.mark.parametrize("threads", [-1, 0, 1, 7, 4096], ids=lambda t: f"threads{t}")
@pytest.mark.parametrize("dtype", [ti.f32, ti.f64], ids=["f32", "f64"])
def test_max_speed_matches_numpy(circles_cpu, dtype, threads):
    """The largest speed, and minus the count of circles with a NaN or infinite number, as one
    loop (threads = 0, the CPU's; -1 on one thread, a small scene's) and as strided threads
    (a GPU's); 5000 circles, so that every thread takes several. A float64 norm of the stored
    values: the same to round-off."""
    rng = np.random.default_rng(max(threads, 0))
    pos = rng.uniform(0, 10, (5000, 2))
    vel = rng.normal(0, 1, (5000, 2))
    vel[4321] = [30.0, -40.0]  # the largest speed, 50, in a late slot
    out = ti.ndarray(ti.f64, shape=2)
    stored = vel.astype(np.float32 if dtype == ti.f32 else np.float64).astype(np.float64)
    got = reductions.speed_from(reductions._max_speed(vec_array(pos, dtype), vec_array(vel, dtype), out, threads))
    assert got == pytest.approx(np.hypot(stored[:, 0], stored[:, 1]).max(), rel=1e-15)
    assert got == 50.0
    pos[17, 1] = np.nan
    vel[3000, 0] = np.inf
    vel[4999, 1] = -np.inf
    pos[4999, 0] = np.nan  # two bad numbers in one circle count once
    assert reductions._max_speed(vec_array(pos, dtype), vec_array(vel, dtype), out, threads) == -3.0


@pytest.mark.parametrize("serial", [True, False], ids=["serial", "parallel"])
@pytest.mark.parametrize("dtype", [ti.f32, ti.f64], ids=["f32", "f64"])
def test_event_finish_measures_the_largest_speed(circles_cpu, dtype, serial):
    """`event.finish` with `speed` returns what `reductions._max_speed` returns for the state it
    leaves: the largest |v|^2, and minus the count of circles not finite once a position it
    moves or a velocity is NaN or infinite; 5000 circles moved from clocks in [0, 0.01) to 0.01
    in a walled box."""
    from circles import event

    rng = np.random.default_rng(5)
    real = np.float32 if dtype == ti.f32 else np.float64
    pos = rng.uniform(1, 9, (5000, 2))
    vel = rng.normal(0, 1, (5000, 2))
    vel[2345] = [-30.0, 40.0]
    tau = ti.ndarray(dtype, shape=5000)
    out = ti.ndarray(ti.f64, shape=2)
    for broken in (False, True):
        if broken:
            vel[17, 1] = np.nan
            vel[4000, 0] = np.inf
            pos[4999, 0] = np.nan
        tau.from_numpy(rng.uniform(0, 0.01, 5000).astype(real))
        p, v = vec_array(pos, dtype), vec_array(vel, dtype)
        got = event.finish(p, v, tau, 0.01, 10.0, 10.0, out, dtype, False, serial, True)
        assert not np.any(tau.to_numpy())
        moved = p.to_numpy().astype(np.float64)
        assert np.isnan(moved[17, 1]) and np.isinf(moved[4000, 0]) if broken else np.all(np.isfinite(moved))
        again = reductions._max_speed(p, v, ti.ndarray(ti.f64, shape=2), -1)
        assert got == again
        assert got == (-3.0 if broken else 2500.0)
        assert reductions.speed_from(got) == (-3.0 if broken else 50.0)
        assert reductions.speed_in(out.to_numpy()) == reductions.speed_from(got)
