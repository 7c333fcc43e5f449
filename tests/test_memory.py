"""A scene too large for the memory is refused before anything is made (`check_memory`), from
the bytes per circle of the arrays a simulation holds (`ARRAY_BYTES`), which are counted here."""

import numpy as np
import pytest
import taichi as ti

from circles import cli
from circles import memory as simulation_module
from circles.backend import serial_loops
from circles.memory import (ARRAY_BYTES, LOG_BYTES, MOST_RECORDED, PART_BYTES, NotEnoughMemory,
                            available_memory, bytes_per_circle, check_memory)
from conftest import TEST_ARCH

pytestmark = pytest.mark.skipif(TEST_ARCH != "cpu", reason="the memory checked is a CPU's")

BYTES = {ti.f32: 4, ti.i32: 4, ti.f64: 8}


def held_bytes(sim):
    """Bytes of every Taichi array the simulation, its grid and its stepper hold (each counted once)."""
    seen = {}
    for obj in (sim, sim.grid, sim.stepper):
        for value in vars(obj).values():
            items = value.values() if isinstance(value, dict) else value if isinstance(value, (tuple, list)) else (
                value,)
            for a in items:
                if isinstance(a, ti.lang._ndarray.Ndarray):
                    seen[id(a)] = int(np.prod(a.shape)) * getattr(a, "n", 1) * BYTES[a.dtype]
    return sum(seen.values())


@pytest.mark.parametrize("scheme", ["event", "discrete"])
@pytest.mark.parametrize("precision", ["f32", "f64"])
def test_array_bytes_are_what_a_simulation_holds(circles_cpu, scheme, precision):
    """ARRAY_BYTES (with LIST_BYTES for one queue on one thread, which lists neighbours) is a
    floor: no simulation holds less a circle (else a scene that fits would be refused), and one
    of 60000 circles (one queue, no parts) holds at most 2% more (the per-circle arrays dominate;
    the rest is a few cells and buckets per circle)."""
    n = 60000
    scene = circles_cpu.Scene(n=n, box=(400.0, 300.0), radius=0.5, speed=(0.5, 1.0), scheme=scheme,
                              precision=precision, seed=0)
    sim = circles_cpu.Simulation(scene)
    sim.step(2)
    per = held_bytes(sim) / n
    floor = ARRAY_BYTES[(scheme, precision)]
    if scheme == "event" and serial_loops(n, "event"):
        floor += circles_cpu.event.stepper.EventStepper.LIST_BYTES
    assert bytes_per_circle(n, scheme, precision) == floor
    assert floor <= per <= 1.02 * floor, per


def test_a_queue_in_parts_counts_its_arrays(circles_cpu):
    """An event queue split into parts (several threads, 150000 circles) holds PART_BYTES a
    circle more, and the memory check counts them (it counted ARRAY_BYTES alone, so a scene
    needing 28.5 MB was let into 22.5)."""
    n = 150_000
    split = TEST_ARCH == "cpu" and not serial_loops(n, "event")
    per = ARRAY_BYTES[("event", "f32")] + (PART_BYTES["f32"] if split else 0)
    check_memory(n, "event", "f32", available=per * n)
    with pytest.raises(NotEnoughMemory, match=f"{per} bytes a circle"):
        check_memory(n, "event", "f32", available=per * n - 1)
    if split:
        sim = circles_cpu.Simulation(circles_cpu.Scene(n=n, box=(627.0, 353.0), radius=0.5, precision="f32",
                                                       seed=0))
        sim.step(2)
        assert sim._parts
        assert per <= held_bytes(sim) / n <= 1.02 * per, held_bytes(sim) / n


def test_a_scene_beyond_the_memory_is_refused_with_what_fits(circles_cpu, monkeypatch, tmp_path):
    with pytest.raises(NotEnoughMemory) as caught:
        check_memory(10 ** 6, "discrete", "f64", available=10 ** 8)
    message = str(caught.value)
    for part in ("n = 1000000 circles", "0.156 GB", "156 bytes a circle", "discrete scheme in f64", "0.1 GB",
                 "at most 641025 circles (in f32, 757575)"):
        assert part in message, message
    assert isinstance(caught.value, ValueError) and isinstance(caught.value, MemoryError)
    check_memory(10 ** 6, "discrete", "f64", available=156 * 10 ** 6)  # exactly enough: no error
    # Refused before the circles are drawn or placed, by the constructor and by from_arrays.
    monkeypatch.setattr(simulation_module, "available_memory", lambda: 2 * ARRAY_BYTES[("discrete", "f32")] - 1)
    with pytest.raises(NotEnoughMemory, match="n = 2 circles"):
        circles_cpu.Simulation(circles_cpu.Scene(n=2, box=(4.0, 4.0), radius=0.1, scheme="discrete",
                                                 precision="f32"))
    with pytest.raises(NotEnoughMemory, match="n = 2 circles"):
        circles_cpu.Simulation.from_arrays(np.array([[1.0, 1.0], [3.0, 3.0]]), np.zeros((2, 2)), [0.1, 0.1],
                                           box=(4.0, 4.0), scheme="discrete", precision="f32")
    one = circles_cpu.Simulation.from_arrays(np.array([[1.0, 1.0]]), np.zeros((1, 2)), [0.1], box=(4.0, 4.0),
                                             scheme="discrete", precision="f32")
    one.save(tmp_path / "one.npz")
    circles_cpu.Simulation.load(tmp_path / "one.npz")
    monkeypatch.setattr(simulation_module, "available_memory", lambda: ARRAY_BYTES[("discrete", "f32")] - 1)
    with pytest.raises(NotEnoughMemory, match="n = 1 circle needs at least"):
        circles_cpu.Simulation.load(tmp_path / "one.npz")


def test_an_event_log_beyond_the_memory_is_refused(circles_cpu, monkeypatch):
    """record_events counts in the memory a simulation needs (LOG_BYTES a collision): a log of
    2e9 collisions on a machine of 24 GB was killed by the system with no message, and 3e9 gave
    a raw Taichi error about the array's shape."""
    with pytest.raises(NotEnoughMemory) as caught:
        check_memory(1000, "event", "f64", available=10 ** 9, record_events=10 ** 8)
    message = str(caught.value)
    # 165 bytes a circle of arrays, and 68 of neighbour lists where one thread runs one queue.
    per = 165 + (68 if serial_loops(1000, "event") else 0)
    for part in ("record_events = 100000000", "1.6 GB", f"{LOG_BYTES} bytes a collision",
                 f"keep at most {(10 ** 9 - per * 1000) // LOG_BYTES} collisions"):
        assert part in message, message
    check_memory(1000, "event", "f64", available=per * 1000 + LOG_BYTES * 10 ** 6, record_events=10 ** 6)
    monkeypatch.setattr(simulation_module, "available_memory", lambda: 10 ** 9)
    pos, vel = np.array([[1.0, 1.0], [3.0, 3.0]]), np.zeros((2, 2))
    with pytest.raises(NotEnoughMemory, match="record_events = 100000000"):
        circles_cpu.Simulation.from_arrays(pos, vel, [0.1, 0.1], box=(4.0, 4.0), record_events=10 ** 8)
    with pytest.raises(NotEnoughMemory, match="record_events = 100000000"):
        circles_cpu.Simulation(circles_cpu.Scene(n=2, box=(4.0, 4.0), radius=0.1), record_events=10 ** 8)
    with pytest.raises(ValueError, match=f"record_events = 3000000000 is more than the {MOST_RECORDED}"):
        circles_cpu.Simulation.from_arrays(pos, vel, [0.1, 0.1], box=(4.0, 4.0), record_events=3 * 10 ** 9)


def test_the_command_line_refuses_it_with_status_2(circles_cpu, monkeypatch, capsys, tmp_path):
    monkeypatch.setattr(simulation_module, "available_memory", lambda: 10 ** 4)
    status = cli.main(["run", "--n", "1000", "--box", "40", "30", "--radius", "0.1", "--arch", "cpu",
                       "--out", str(tmp_path / "run.gif")])
    assert status == 2
    err = capsys.readouterr().err
    assert err.startswith("circles: error: n = 1000 circles need at least") and "more memory" in err, err
    assert not (tmp_path / "run.gif").exists()


def write(root, path, text):
    (root / path).parent.mkdir(parents=True, exist_ok=True)
    (root / path).write_text(text)


def test_available_memory_is_the_least_of_the_system_and_the_control_group(tmp_path):
    """MemAvailable (kB) alone; less when a control group's limit leaves less (the least of
    version 2's and version 1's); no limit ("max", or version 1's number near 2^63) changes
    nothing; None where nothing is said."""
    assert available_memory(tmp_path) is None
    write(tmp_path, "proc/meminfo", "MemTotal:  4000000 kB\nMemFree:  1000 kB\nMemAvailable:  2000000 kB\n")
    assert available_memory(tmp_path) == 2000000 * 1024
    write(tmp_path, "sys/fs/cgroup/memory/memory.limit_in_bytes", "9223372036854771712\n")
    write(tmp_path, "sys/fs/cgroup/memory/memory.usage_in_bytes", "1000\n")
    assert available_memory(tmp_path) == 2000000 * 1024
    write(tmp_path, "sys/fs/cgroup/memory/memory.limit_in_bytes", "1500000000\n")
    write(tmp_path, "sys/fs/cgroup/memory/memory.usage_in_bytes", "500000000\n")
    assert available_memory(tmp_path) == 10 ** 9
    write(tmp_path, "sys/fs/cgroup/memory.max", "max\n")
    write(tmp_path, "sys/fs/cgroup/memory.current", "7\n")
    assert available_memory(tmp_path) == 10 ** 9  # version 2 sets no limit; version 1's holds
    write(tmp_path, "sys/fs/cgroup/memory.max", "300\n")
    assert available_memory(tmp_path) == 293
    (tmp_path / "proc/meminfo").unlink()
    write(tmp_path, "sys/fs/cgroup/memory.current", "400\n")
    assert available_memory(tmp_path) == 0
