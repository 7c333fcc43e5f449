"""Same scene and seed give a bit-identical state: on the CPU with 1 and with
2 threads (or in two GPU runs, when the suite runs on the GPU), and across save
and load. Bit-identical means np.array_equal, no tolerance: nothing that feeds the
state may depend on thread timing (event keys order every choice, see
circles.geometry), so any difference is a race, not round-off.

Each run is a process of its own (see process_util).
"""

import dataclasses
import json
import textwrap

import numpy as np
import pytest

from conftest import TEST_ARCH
from process_util import INIT, compared_runs, run_script

# Scenes that reach the code paths where order could leak in: random sequential
# placement and lattice-and-melt placement (area fraction 0.75), both schemes,
# both boundaries, run for about 2000 to 5000 collisions each, and for more steps than
# REORDER_EVERY, so the arrays are reordered (in an order that follows thread timing) on the way.
SCENES = {
    "event_walls": dict(n=1500, box=(1.2, 0.9), radius=(0.006, 0.012), boundary="walls",
                        scheme="event", seed=21, duration=0.07),
    "event_periodic": dict(n=1500, box=(1.2, 0.9), radius=(0.006, 0.012), boundary="periodic",
                           scheme="event", seed=22, duration=0.07),
    "event_dense": dict(n=400, box=(0.164, 0.164), radius=0.004, boundary="walls",
                        scheme="event", seed=23, duration=0.004),
    "discrete_walls": dict(n=1500, box=(1.2, 0.9), radius=(0.006, 0.012), boundary="walls",
                           scheme="discrete", seed=24, duration=0.04),
    "discrete_periodic": dict(n=1500, box=(1.2, 0.9), radius=(0.006, 0.012), boundary="periodic",
                              scheme="discrete", seed=25, duration=0.04),
}

SCRIPT = textwrap.dedent("""
    import json, sys
    import numpy as np
    import circles

    out, scenes = sys.argv[2], json.loads(sys.argv[3])
""") + INIT + textwrap.dedent("""
    # Every loop on the CPU's threads, as in a large scene (these scenes are small enough to
    # run on one thread otherwise, see backend.serial_loops): with two threads the event
    # queue runs in parts, with one from one queue.
    from circles import backend
    backend.SERIAL_N = 0
    backend.EVENT_SERIAL_WORK = 0
    if len(sys.argv) > 4:  # the circles from which one thread runs the event queue in parts
        backend.EVENT_PARTS_ONE_THREAD_N = int(sys.argv[4])
        import circles.event.stepper
        circles.event.stepper.PART_CIRCLES = 400  # a part each 400 circles: several parts
        circles.event.stepper.PART_MIN_ROWS = 2
    arrays = {}
    for name, kw in scenes.items():
        duration = kw.pop("duration")
        sim = circles.Simulation(circles.Scene(speed=(0.5, 1.0), precision="f64", **kw))
        start = sim.state()
        sim.advance(duration)
        s, st = sim.state(), sim.stats()
        arrays.update({f"{name}.start_pos": start.pos, f"{name}.start_vel": start.vel,
                       f"{name}.pos": s.pos, f"{name}.vel": s.vel, f"{name}.radius": s.radius,
                       f"{name}.mass": s.mass, f"{name}.color": s.color,
                       f"{name}.counts": np.array([st["pair_collisions"], st["wall_collisions"]])})
        if sim.scheme == "event":
            arrays[f"{name}.parts_run"] = np.array([sim.stepper.parts_run])
    np.savez(out, **arrays)
""")


# One scene of each scheme in the default suite, the other three in the slow one.
@pytest.mark.parametrize("names", [("event_periodic", "discrete_walls"),
                                   pytest.param(("event_walls", "event_dense", "discrete_periodic"),
                                                marks=pytest.mark.slow)], ids=["default", "rest"])
def test_same_state_with_1_and_2_threads(tmp_path, names):
    """On the CPU each scene runs its loops on the threads (one queue for the event scheme
    with one thread, parts with two); the states must agree bit for bit."""
    scenes = json.dumps({name: {k: list(v) if isinstance(v, tuple) else v for k, v in SCENES[name].items()}
                         for name in names})
    first, second = compared_runs()
    one = run_script(SCRIPT, first, tmp_path / "first.npz", scenes, timeout=600)
    two = run_script(SCRIPT, second, tmp_path / "second.npz", scenes, timeout=600)
    assert sorted(one.files) == sorted(two.files)
    different = [key for key in one.files if not np.array_equal(one[key], two[key]) and "parts_run" not in key]
    assert not different, f"differ between runs {first} and {second}: {different}"
    for name in names:
        assert one[f"{name}.counts"][0] > 500  # the runs did collide


@pytest.mark.skipif(TEST_ARCH != "cpu", reason="the threads of a CPU")
def test_one_thread_in_parts_gives_the_bits_of_one_queue(tmp_path):
    """One thread runs a scene of at least backend.EVENT_PARTS_ONE_THREAD_N circles in parts,
    the parts in turn (their arrays stay in the cache); a smaller one from one queue. The two
    give the same state bit for bit: here the limit is set to 0 for the parts."""
    names = ("event_periodic", "event_walls")
    scenes = json.dumps({name: {k: list(v) if isinstance(v, tuple) else v for k, v in SCENES[name].items()}
                         for name in names})
    queue = run_script(SCRIPT, "cpu:1", tmp_path / "queue.npz", scenes, timeout=600)
    parts = run_script(SCRIPT, "cpu:1", tmp_path / "parts.npz", scenes, "0", timeout=600)
    for name in names:
        assert queue[f"{name}.parts_run"][0] == 0 and parts[f"{name}.parts_run"][0] > 0
        assert queue[f"{name}.counts"][0] > 500
    different = [key for key in queue.files if not np.array_equal(queue[key], parts[key]) and "parts_run" not in key]
    assert not different, f"differ between one queue and parts on one thread: {different}"


# Every pair of a scheme, a boundary and a precision in the default suite (the four cases of an
# orthogonal array); the other four in the slow one.
@pytest.mark.parametrize("scheme,boundary,precision", [
    ("event", "walls", "f64"), ("event", "periodic", "f32"), ("discrete", "walls", "f32"), ("discrete", "periodic", "f64"),
    *(pytest.param(*case, marks=pytest.mark.slow) for case in (("event", "walls", "f32"), ("event", "periodic", "f64"),
                                                               ("discrete", "walls", "f64"), ("discrete", "periodic", "f32")))])
def test_save_load_continue_is_seamless(circles_cpu, tmp_path, scheme, boundary, precision):
    """2k steps straight equal k steps, save, load, k steps, bit for bit (the states load: their
    places pass load's checks, up to the rounding of the precision)."""
    scene = circles_cpu.Scene(n=800, box=(0.8, 0.6), radius=(0.006, 0.012), speed=(0.5, 1.0),
                              boundary=boundary, scheme=scheme, precision=precision, seed=31)
    k = 15
    straight = circles_cpu.Simulation(scene)
    straight.step(2 * k)

    first = circles_cpu.Simulation(scene)
    first.step(k)
    path = tmp_path / "run.npz"
    first.save(str(path))
    resumed = circles_cpu.Simulation.load(str(path))
    assert resumed.time == first.time and resumed.dt == first.dt and resumed.n == first.n
    resumed.step(k)

    a, b = straight.state(), resumed.state()
    for field in ("pos", "vel", "radius", "mass", "color"):
        x, y = getattr(a, field), getattr(b, field)
        if not np.array_equal(x, y):
            d = np.abs(x.astype(np.float64) - y.astype(np.float64)).reshape(len(x), -1)
            moved = int(np.sum(np.any(d != 0, axis=1)))
            pytest.fail(f"{field} differs after save/load for {moved} of {len(x)} circles, "
                        f"by up to {d.max():.3g}")
    assert resumed.time == straight.time
    assert straight.stats()["pair_collisions"] > 500


def test_stats_continue_after_load(circles_cpu, tmp_path):
    """stats() count since the simulation started, a loaded one included."""
    scene = circles_cpu.Scene(n=800, box=(0.8, 0.6), radius=(0.006, 0.012), speed=(0.5, 1.0),
                              boundary="walls", scheme="event", precision="f64", seed=32)
    straight = circles_cpu.Simulation(scene)
    straight.step(20)
    first = circles_cpu.Simulation(scene)
    first.step(10)
    first.save(str(tmp_path / "run.npz"))
    resumed = circles_cpu.Simulation.load(str(tmp_path / "run.npz"))
    assert resumed.stats()["pair_collisions"] == first.stats()["pair_collisions"]
    resumed.step(10)
    a, b = straight.stats(), resumed.stats()
    for key in ("pair_collisions", "wall_collisions"):
        assert a[key] == b[key], key
    for key in ("virial", "wall_impulse", "kinetic_energy"):
        assert b[key] == pytest.approx(a[key], rel=1e-12), key


def test_a_loaded_run_records_its_events_from_the_load(circles_cpu, tmp_path):
    """The event log is not saved; load(record_events=...) starts one (a loaded simulation
    could not record before), whose rows are those of the run straight from the load on."""
    scene = circles_cpu.Scene(n=300, box=(1.0, 1.0), radius=0.012, speed=1.0, seed=33)
    straight = circles_cpu.Simulation(scene, record_events=100_000)
    straight.step(10)
    straight.save(tmp_path / "run.npz")
    logged = len(straight.events())
    straight.step(10)
    resumed = circles_cpu.Simulation.load(tmp_path / "run.npz", record_events=100_000)
    resumed.step(10)
    assert logged > 100 and np.array_equal(resumed.events(), straight.events()[logged:])
    with pytest.raises(RuntimeError, match="give it to Simulation, Simulation.from_arrays or Simulation.load"):
        circles_cpu.Simulation.load(tmp_path / "run.npz").events()
    with pytest.raises(ValueError, match="record_events = -1 .*"):
        circles_cpu.Simulation.load(tmp_path / "run.npz", record_events=-1)
    discrete = circles_cpu.Simulation(dataclasses.replace(scene, scheme="discrete"))
    discrete.save(tmp_path / "discrete.npz")
    with pytest.raises(ValueError, match="only the event scheme logs .* holds a run of the discrete scheme"):
        circles_cpu.Simulation.load(tmp_path / "discrete.npz", record_events=10)


def test_save_writes_the_path_given_and_nothing_half_written(circles_cpu, tmp_path, monkeypatch):
    """save writes exactly the path it is given (numpy's savez would add .npz to it), and a
    save that fails leaves the older file as it was and no partial one beside it."""
    sim = circles_cpu.Simulation(circles_cpu.Scene(n=60, box=(3.0, 2.0), radius=0.08, seed=5))
    sim.step(3)
    path = tmp_path / "state.bin"
    assert sim.save(path) == path
    assert sorted(p.name for p in tmp_path.iterdir()) == ["state.bin"]
    loaded = circles_cpu.Simulation.load(path)
    assert loaded.time == sim.time and loaded.steps == sim.steps
    assert np.array_equal(loaded.state().pos, sim.state().pos)
    assert np.array_equal(loaded.state().vel, sim.state().vel)

    before = path.read_bytes()
    sim.step(2)

    def disk_full(file, **arrays):
        file.write(b"PK\x03\x04 the first bytes of an archive")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(np, "savez", disk_full)
    with pytest.raises(OSError, match="No space left"):
        sim.save(path)
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["state.bin"]
    monkeypatch.undo()

    with pytest.raises(IsADirectoryError, match="is a folder"):
        sim.save(tmp_path)
    with pytest.raises(FileNotFoundError, match="folder .*missing does not exist"):
        sim.save(tmp_path / "missing" / "run.npz")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["state.bin"]
    # A name of 250 bytes (up to 255 are allowed) was refused: the temporary name beside it
    # added the process id and ".part" to the whole of it.
    long = tmp_path / ("é" * 123 + "s.npz")
    assert len(long.name.encode()) == 251 and sim.save(long) == long
    assert np.array_equal(circles_cpu.Simulation.load(long).state().pos, sim.state().pos)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["state.bin", long.name])


def test_load_refuses_a_file_save_did_not_write(circles_cpu, tmp_path):
    sim = circles_cpu.Simulation(circles_cpu.Scene(n=40, box=(3.0, 2.0), radius=0.08, seed=6))
    good = sim.save(tmp_path / "good.npz")
    fields = dict(np.load(good))
    (tmp_path / "notes.npz").write_text("not an archive")
    np.save(tmp_path / "one.npy", fields["pos"])
    np.savez(tmp_path / "partial.npz", pos=fields["pos"], vel=fields["vel"])
    np.savez(tmp_path / "shape.npz", **{**fields, "pos": fields["pos"][:-1]})
    (tmp_path / "cut.npz").write_bytes(good.read_bytes()[: good.stat().st_size // 2])
    np.savez(tmp_path / "scheme.npz", **{**fields, "scheme": "magic"})
    np.savez(tmp_path / "radius.npz", **{**fields, "radius": np.where(np.arange(40) == 7, 0.0, fields["radius"])})
    np.savez(tmp_path / "time.npz", **{**fields, "time": np.nan})
    # States the simulation could not have reached: each would have run (wrongly) before.
    pos = fields["pos"].copy()
    outside, overlapping = pos.copy(), pos.copy()
    outside[5] = (7.5, 1.0)
    overlapping[9] = overlapping[4] + (0.1, 0.0)  # 0.1 apart, radii 0.08
    np.savez(tmp_path / "outside.npz", **{**fields, "pos": outside})
    np.savez(tmp_path / "overlap.npz", **{**fields, "pos": overlapping})
    np.savez(tmp_path / "large.npz", **{**fields, "radius": np.where(np.arange(40) == 3, 1.2, fields["radius"])})
    np.savez(tmp_path / "counts.npz", **{**fields, "pair_count": fields["pair_count"][:-1]})
    np.savez(tmp_path / "negative.npz", **{**fields, "wall_count": np.full(40, -5)})
    np.savez(tmp_path / "color.npz", **{**fields, "color": np.full((40, 3), 300)})
    np.savez(tmp_path / "steps.npz", **{**fields, "steps": 2.5})
    np.savez(tmp_path / "clock.npz", **{**fields, "time": "abc"})
    np.savez(tmp_path / "masses.npz", **{**fields, "mass": np.where(np.arange(40) == 2, 1e300, fields["mass"])})
    # Complex numbers were taken with a warning (numpy drops the imaginary part), strings failed
    # in numpy's arithmetic, no circles in its argmax, and a count past 32 bits wrapped.
    np.savez(tmp_path / "complex.npz", **{**fields, "pos": fields["pos"] + 0j})
    np.savez(tmp_path / "words.npz", **{**fields, "vel": fields["vel"].astype(str)})
    np.savez(tmp_path / "empty.npz", **{**{k: v[:0] if v.ndim else v for k, v in fields.items()}})
    np.savez(tmp_path / "wraps.npz", **{**fields, "pair_count": np.full(40, 2 ** 33 + 6)})
    for name, why in (("notes.npz", "not an .npz archive"), ("one.npy", "one array"),
                      ("partial.npz", "lacks radius, mass, color, box"), ("shape.npz", "pos has shape"),
                      ("cut.npz", "not an .npz archive"), ("scheme.npz", "scheme 'magic' is unknown"),
                      ("radius.npz", "radius 0.0 must be finite and > 0"), ("time.npz", "time nan"),
                      ("outside.npz", "circle 5 at (7.5, 1.0) with radius 0.08 is not inside the walls"),
                      ("overlap.npz", "circles overlap by "),
                      ("large.npz", "radius 1.2 is larger than the box"),
                      ("counts.npz", "pair_count has shape (39,), not (40,)"),
                      ("negative.npz", "wall_count holds -5, not a finite number >= 0"),
                      ("color.npz", "color of circle 0, [300, 300, 300], is not three whole numbers"),
                      ("steps.npz", "steps has type float64, not integer"),
                      ("clock.npz", "time has type <U3, not real number"),
                      ("masses.npz", "circle 2 (mass 1e+300) is"),
                      ("complex.npz", "pos has type complex128, not real number"),
                      ("words.npz", "vel has type <U32, not real number"),
                      ("empty.npz", "radius has shape (0,), not (n,) for n >= 1 circles"),
                      ("wraps.npz", "pair_count holds 8589934598, more than the 2147483647 a run counts")):
        with pytest.raises(ValueError, match="not a simulation written by Simulation.save") as refused:
            circles_cpu.Simulation.load(tmp_path / name)
        assert why in str(refused.value) and name in str(refused.value), str(refused.value)
    with pytest.raises(FileNotFoundError):
        circles_cpu.Simulation.load(tmp_path / "absent.npz")


RESTART = """
import io, sys
import numpy as np
import taichi as ti
import circles
sys.stdout = io.StringIO()  # what circles prints (its output is its own: nothing here)
circles.init(arch="cpu")
scene = circles.Scene(n=300, box=(4.0, 3.0), radius=(0.04, 0.06), seed=9)
a = circles.Simulation(scene)
a.step(3)
unknown = []
for options in ({"cpu_max_num_thread": 1}, {"cpu_max_num_threads": "two"}, {"debug": "yes"},
                {"cpu_max_num_threads": 0}, {"cpu_max_num_threads": -1}, {"cpu_max_num_threads": 2 ** 40},
                {"default_fp": "x"}, {"default_ip": ti.f32}, {"log_level": "nonsense"}):
    try:
        circles.init(arch="cpu", **options)  # refused before the runtime is touched
    except ValueError as error:
        unknown.append(str(error))
a.step(3)
a.render(64, 36)
before = a.state()
b = circles.Simulation(circles.Scene(n=300, box=(4.0, 3.0), radius=0.05, seed=9, scheme="discrete"))
b.step(2)
circles.init(arch="cpu", cpu_max_num_threads=1)
refused = []
for name, call in (("step", lambda: a.step(1)), ("advance", lambda: b.advance(0.1)), ("state", a.state),
                   ("stats", b.stats), ("render", lambda: a.render(64, 36)), ("save", lambda: a.save(sys.argv[2] + ".x")),
                   ("events", a.events)):
    try:
        call()
    except RuntimeError as error:
        if "made before circles.init was called again" in str(error):
            refused.append(name)
assert repr(a).startswith("Simulation(n=300, "), repr(a)
c = circles.Simulation(scene)
c.step(6)
c.render(64, 36)
d = circles.Simulation(circles.Scene(n=300, box=(4.0, 3.0), radius=0.05, seed=9, scheme="discrete"))
d.step(2)
c_pos, c_vel, pairs = c.state().pos, c.state().vel, d.stats()["pair_collisions"]
# Restarts in a row, each runtime running both schemes and drawing (a fast kernel kept the
# program of the runtime before; dropped after its end, it crashed the process within a few).
for k in range(6):
    circles.init(arch="cpu", cpu_max_num_threads=1 + k % 2)
    for name in ("event", "discrete"):
        e = circles.Simulation(circles.Scene(n=300, box=(4.0, 3.0), radius=0.05, seed=k, scheme=name))
        e.advance(0.3)
        e.render(64, 36)
        assert e.stats()["pair_collisions"] > 0
with open(sys.argv[2], "wb") as out:
    np.savez(out, pos_before=before.pos, vel_before=before.vel, pos=c_pos, vel=c_vel, refused=np.array(refused),
             pairs=pairs, unknown=np.array(unknown), printed=sys.stdout.getvalue())
"""


@pytest.mark.slow
def test_a_restart_of_the_runtime_leaves_old_simulations_refusing_and_new_ones_exact(tmp_path):
    """circles.init called again restarts Taichi: the simulations made before let go of their
    arrays and refuse every use with a RuntimeError that says so (before, a step of a new
    simulation after the restart ended the process with a segmentation fault), and a new
    simulation runs as in a fresh process (one thread now, two before: the same state bit for
    bit). Options ti.init would refuse are refused before the runtime is touched (ti.init stops
    the running runtime and then fails; the package was left unusable, and a runtime started
    after such a failure could crash the process), so the simulations made before go on."""
    out = run_script(RESTART, "cpu", tmp_path / "restart.npz", timeout=600)
    assert str(out["printed"]) == "", out["printed"]  # ti.init prints a line at each start
    unknown = out["unknown"].tolist()
    assert len(unknown) == 9, unknown
    assert "'cpu_max_num_thread' is not one that ti.init takes: did you mean cpu_max_num_threads?" in unknown[0]
    assert "cpu_max_num_threads = 'two' is not a value ti.init takes: give a whole number" in unknown[1]
    assert "debug = 'yes' is not a value ti.init takes: give True or False" in unknown[2]
    for shown in ("0", "-1"):  # ti.init takes both; the first kernel then ends the process
        assert f"cpu_max_num_threads = {shown} is not a thread count: give 1 or more" in unknown.pop(3)
    assert "= 1099511627776 is not a value ti.init takes: give a whole number from 1 to 2147483647" in unknown[3]
    assert "default_fp = 'x' is not a value ti.init takes: give ti.f16 or ti.f32 or ti.f64" in unknown[4]
    assert "default_ip = ti.f32 is not a value ti.init takes: give ti.i32 or ti.i64" in unknown[5]
    assert "log_level = 'nonsense' is not a value ti.init takes: give one of 'trace'" in unknown[6]
    assert sorted(out["refused"].tolist()) == ["advance", "events", "render", "save", "state", "stats", "step"]
    assert np.array_equal(out["pos"], out["pos_before"]) and np.array_equal(out["vel"], out["vel_before"])
    assert int(out["pairs"]) > 0


@pytest.mark.parametrize("scheme", ["event", "discrete"])
def test_copies_and_pickles_are_independent_and_go_on_bit_for_bit(circles_cpu, scheme):
    """copy.copy, copy.deepcopy, pickling and Simulation.copy each make a simulation with arrays
    of its own (before, copy.copy shared the original's arrays, so stepping the copy moved the
    original, and pickling failed on a Taichi assertion), which goes on as the original does,
    event log included."""
    import copy
    import pickle

    options = {"record_events": 100_000} if scheme == "event" else {}
    sim = circles_cpu.Simulation(circles_cpu.Scene(n=400, box=(4.0, 3.0), radius=(0.03, 0.06), seed=12,
                                                   scheme=scheme), **options)
    sim.step(5)
    at_copy = sim.state()
    copies = {"copy.copy": copy.copy(sim), "copy.deepcopy": copy.deepcopy(sim),
              "pickle": pickle.loads(pickle.dumps(sim)), "Simulation.copy": sim.copy()}
    for other in copies.values():
        other.step(8)
    assert np.array_equal(sim.state().pos, at_copy.pos), "stepping a copy moved the original"
    sim.step(8)
    end = sim.state()
    for name, other in copies.items():
        state = other.state()
        assert np.array_equal(state.pos, end.pos) and np.array_equal(state.vel, end.vel), name
        assert (other.time, other.steps, other.scene) == (sim.time, sim.steps, sim.scene), name
        assert other.stats()["pair_collisions"] == sim.stats()["pair_collisions"] > 0, name
        if scheme == "event":
            assert np.array_equal(other.events(), sim.events()), name


INTERRUPTED = """
import os, signal, sys
import numpy as np
import circles
from circles.discrete import rounds as discrete
from circles.event import queue as event
circles.init(arch="cpu")
# Python's own handler, which raises KeyboardInterrupt: a process started in the background
# by a shell inherits SIGINT ignored, and Python then leaves it so.
signal.signal(signal.SIGINT, signal.default_int_handler)
scheme, call = sys.argv[3], sys.argv[4]
scene = circles.Scene(n=400, box=(4.0, 3.0), radius=(0.03, 0.06), seed=13, scheme=scheme)
sim = circles.Simulation(scene)
sim.step(3)
# The kernels that move the circles: a step's, or a launch of several discrete steps.
hooked = [(discrete, "begin_step"), (discrete, "serial_steps")] if scheme == "discrete" else [(event, "queue_step")]
begun = []  # steps begun, launch by launch
pressed_at = []  # steps begun by the end of the launch after which Ctrl-C came

def hook(module, name):
    kernel = getattr(module, name)

    def pressed(*args):
        # Ctrl-C right after a kernel that moves the circles, once the 4th step has begun.
        result = kernel(*args)
        begun.append(abs(result) if name == "serial_steps" else 1)
        if sum(begun) >= 4 and not pressed_at:
            pressed_at.append(sum(begun))
            os.kill(os.getpid(), signal.SIGINT)
        return result
    setattr(module, name, pressed)
    return kernel

kernels = [hook(module, name) for module, name in hooked]
try:
    sim.step(10) if call == "step" else sim.advance(10 * sim.dt)
    stopped = False
except KeyboardInterrupt:
    stopped = True
for (module, name), kernel in zip(hooked, kernels):
    setattr(module, name, kernel)
straight = circles.Simulation(scene)
straight.step(sim.steps)
np.savez(sys.argv[2], stopped=stopped, steps=sim.steps, pressed_at=pressed_at[0], launches=len(begun),
         time=sim.time, straight_time=straight.time, pos=sim.state().pos, straight_pos=straight.state().pos,
         vel=sim.state().vel, straight_vel=straight.state().vel)
"""


@pytest.mark.parametrize("scheme", ["event", "discrete"])
@pytest.mark.parametrize("call", ["step", "advance"])
def test_ctrl_c_stops_between_steps_with_a_whole_state(tmp_path, scheme, call):
    """A Ctrl-C that comes in the middle of a step (sent right after the kernel that moves the
    circles, once the 4th step of the call has begun) raises KeyboardInterrupt once that step
    is done, or, where several discrete steps run in one launch (this scene's 400 circles run
    on one thread: `discrete.serial_steps`), once that launch's steps are: the simulation
    holds the state of its whole steps, as a run of that many steps does, bit for bit. Before,
    it stopped between two kernels of the step, with the circles moved and the clock not."""
    out = run_script(INTERRUPTED, "cpu", tmp_path / "stopped.npz", scheme, call, timeout=600)
    assert bool(out["stopped"]) and int(out["steps"]) == 3 + int(out["pressed_at"])
    if scheme == "event":
        assert int(out["pressed_at"]) == 4 and int(out["launches"]) == 4
    else:
        # The call's steps in batches: fewer launches than steps, the press after the 4th step.
        assert 4 <= int(out["pressed_at"]) <= 10 and int(out["launches"]) < int(out["pressed_at"])
    assert float(out["time"]) == pytest.approx(float(out["straight_time"]), rel=1e-12)
    assert np.array_equal(out["pos"], out["straight_pos"]) and np.array_equal(out["vel"], out["straight_vel"])


# T: state() hands back arrays of its own.
def test_state_arrays_are_the_callers(circles_cpu):
    sim = circles_cpu.Simulation(circles_cpu.Scene(n=50, box=(1.0, 1.0), radius=0.02, speed=(0.5, 1.0), seed=1))
    s = sim.state()
    radius, mass, color = s.radius.copy(), s.mass.copy(), s.color.copy()
    s.radius[:] = 0.001
    s.mass[:] = 7.0
    s.color[:] = 0
    t = sim.copy().state()
    assert np.array_equal(t.radius, radius) and np.array_equal(t.mass, mass) and np.array_equal(t.color, color)
