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
    got = reductions._max_speed(vec_array(pos, dtype), vec_array(vel, dtype), out, threads)
    assert got == pytest.approx(np.hypot(stored[:, 0], stored[:, 1]).max(), rel=1e-15)
    assert got == 50.0
    pos[17, 1] = np.nan
    vel[3000, 0] = np.inf
    vel[4999, 1] = -np.inf
    pos[4999, 0] = np.nan  # two bad numbers in one circle count once
    assert reductions._max_speed(vec_array(pos, dtype), vec_array(vel, dtype), out, threads) == -3.0
