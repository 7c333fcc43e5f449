"""Benchmark of circles: throughput, the memory-bandwidth bound, the pymunk peer, work-precision.

    python bench/bench.py [--quick] [--arch cpu|gpu] [--out outputs/bench] [--skip SECTION,...] [--ecmc PATH]

Writes `<out>/<machine>/` (the machine is the CPU model, or the GPU name with --arch gpu):
throughput.csv, bandwidth.csv, compile.csv, placement.csv, render.csv, memory.csv, spread.csv,
peers.csv, work_precision.csv, targets.csv, results.md (every table, with the command and the
date, the project's performance targets first, judged on this run by `targets.py`),
work_precision.png, and dense.md, dense.csv and dense.png. A run first removes these files from that folder, so that the folder never
mixes two runs (a section skipped or failed leaves no file of an older run). The tables are
rewritten after every section, so a run stopped early leaves what it measured. With --arch gpu
the sizes go up to 1e8 in float32, and the pymunk, memory and work-precision sections are left
out (see GPU below).

`<out>` is outputs/bench by default (the results kept with the project). A run with --quick
(smaller sizes: up to 1e5 circles) or with --skip is no full run: unless --out is given it
writes to a scratch folder, `circles-bench-quick` in the system's temporary folder (QUICK_OUT),
and says where.

What is measured, all in one run and one process:

1. Throughput. Circles of one radius R at area fraction 0.3 in a 16:9 walled box, speeds
   uniform in SPEED, default dt of each scheme; N from 1e3 up, both schemes, f32 and f64.
   Each configuration: the first step (compilation and first touch) and a second step are
   timed apart as warm-up; then the scene relaxes untimed up to RELAX_STEPS steps in all (its
   speeds spread out from their uniform start: the fastest circle, and with it the event
   scheme's cells, grows over the first tens of steps), and one more step sets how many steps
   a repeat takes (about `target` seconds, at least one); then `reps` repeats, reported as
   median, min and max.
   Collisions per second: pair collisions per step over all repeats, times the median
   steps/s. The energy change and the largest overlap after the repeats go with every
   speed figure.
2. The bound. A Taichi kernel copies a large ndarray (dst[i] = src[i]); its best rate, bytes
   read plus bytes written per second, is the machine's copy bandwidth B. The model of
   bytes per circle-step is the state each step must at least read and write once:
   pos and vel read and written, radius read: 9 numbers, 36 B in f32 and 72 B in f64, for
   both schemes (grid arrays, neighbour reads, the event scheme's clocks and backups are
   left out, so the bound is optimistic). Bound = B / bytes per circle-step.
3. Peer. pymunk (see peer_pymunk.py) on the same scene, from the same start state, with
   the discrete scheme's default dt, side by side with circles at the same N in each scheme
   and precision of the throughput rows: every repeat times each engine in turn, so that the
   drift of a shared machine falls on all alike; ratios circles / pymunk of the medians, with
   the least and greatest ratio within one repeat.
4. Work-precision. N circles at area fractions 0.3 and 0.6 in a periodic square box, from
   one start state; reference: event scheme, f64, default dt. For dt from 0.01 to 2 mean free
   times (measured from the reference), `discrete` and `event` (f64) run the same simulated
   time T; cost = wall seconds per unit of simulated time; errors against the reference:
   pressure Z = 1 + virial / (2 T N kT) with kT = kinetic_energy / N, the pair collision
   count, the energy (largest |E - E0| / E0 seen at NSEG checkpoints), and the largest
   overlap at the checkpoints. pymunk has no periodic box: its rows use the same N and area
   fraction in a walled box, against an event f64 reference of that walled scene; its Z is
   the same pair-virial statistic (the walls' share of the pressure is left out of both).
   pymunk is timed without callbacks and measured in a second, identical run with them. Each
   discrete row is timed on a second run of it, so that no row pays for compiling a kernel
   its steps are the first to need (the extra rounds of long steps).
5. Dense. bench/dense.py, in processes of its own: equal disks near melting (area fraction
   0.70), collisions per second on 1 and 2 threads and against N, and the pressure's error
   against CPU time at N = 870 (dense.md, dense.csv, dense.png; see that script); with
   --ecmc PATH, event-chain Monte Carlo side by side (bench/peer_ecmc.py).
"""

import argparse
import csv
import datetime
import hashlib
import math
import os
import pathlib
import platform
import re
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np
import taichi as ti

import circles

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import peer_ecmc  # noqa: E402
import targets  # noqa: E402
try:
    import peer_pymunk  # noqa: E402
except ImportError:  # no pymunk (a GPU machine, say): the peer section cannot run
    peer_pymunk = None

#: Radius of every circle (world units); box sides follow from N and the area fraction.
R = 0.5
#: Speeds uniform in this range, directions uniform.
SPEED = (0.5, 1.0)
#: Box aspect W / H of the throughput scenes (the aspect of a 1920x1080 frame).
ASPECT = 16.0 / 9.0
AREA_FRACTION = 0.3
#: Numbers per circle-step in the bandwidth model: pos and vel read and written, radius read.
NUMBERS_PER_CIRCLE_STEP = 2 * 2 + 2 * 2 + 1
BYTES = {"f32": 4, "f64": 8}
#: Checkpoints per work-precision run (energy and overlap are sampled there).
NSEG = 10
SCHEMES = ("discrete", "event")
PRECISIONS = ("f32", "f64")

QUICK = dict(
    sizes=(1_000, 10_000, 100_000), event_sizes=(1_000, 10_000, 100_000), reps=5, target=0.3,
    peer_sizes=(1_000, 10_000, 100_000), dense_sizes=(300, 1_000), render_reps=3,
    copy_numbers=1 << 25, copy_reps=5,
    wp_n=500, wp_duration_mft=10.0, wp_factors=(0.01, 0.04, 0.15, 0.5, 2.0),
    memory_sizes=(100_000,), spread_sizes=(10_000,), placement_n=100_000)
FULL = dict(
    sizes=(1_000, 10_000, 100_000, 1_000_000), event_sizes=(1_000, 10_000, 100_000, 1_000_000), reps=5,
    target=1.0, peer_sizes=(1_000, 10_000, 100_000), dense_sizes=(300, 1_000, 3_000), render_reps=5,
    copy_numbers=1 << 27, copy_reps=10,
    wp_n=2000, wp_duration_mft=20.0, wp_factors=(0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0),
    memory_sizes=(1_000_000, 10_000_000), spread_sizes=(10_000, 100_000), placement_n=1_000_000)
#: With --arch gpu: sizes up to 1e8 in float32, no pymunk (a CPU peer), no
#: resident-memory rows (they measure host memory) and no work-precision (a CPU-size study).
GPU = dict(
    sizes=(10_000, 100_000, 1_000_000, 10_000_000, 100_000_000), event_sizes=(100_000, 1_000_000, 10_000_000),
    precisions=("f32",), reps=5, target=0.5, peer_sizes=(), dense_sizes=(1_000, 10_000), render_reps=5,
    copy_numbers=1 << 28, copy_reps=20, memory_sizes=(), spread_sizes=(1_000_000, 10_000_000),
    placement_n=1_000_000, skip=("peers", "wp", "memory", "dense"))
#: The sections a run can leave out (--skip).
SECTIONS = ("throughput", "placement", "memory", "spread", "peers", "wp", "dense")
#: The files a run writes into `<out>/<machine>/` (and removes there first).
OUTPUT_FILES = ("bandwidth.csv", "throughput.csv", "placement.csv", "render.csv", "compile.csv", "peers.csv",
                "work_precision.csv", "memory.csv", "spread.csv", "targets.csv", "results.md", "work_precision.png",
                "dense.md", "dense.csv", "dense.png")
#: Default --out: the results kept with the project; QUICK_OUT for --quick or --skip runs.
FULL_OUT = os.path.join("outputs", "bench")
QUICK_OUT = os.path.join(tempfile.gettempdir(), "circles-bench-quick")


def now():
    return time.perf_counter()


def log(*args):
    print(*args, flush=True)


def slug(text):
    text = re.sub(r"\((r|tm|c)\)", "", text.lower())
    return re.sub(r"[^a-z0-9]+", "-", text).strip("-") or "unknown"


def cpu_info():
    """The first processor's fields of /proc/cpuinfo ({} where it cannot be read)."""
    info = {}
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                key, _, value = line.partition(":")
                info.setdefault(key.strip(), value.strip())
    except OSError:
        pass
    return info


def cpu_model():
    info = cpu_info()
    return info["model name"] if "model name" in info else platform.processor() or platform.machine()


def cpu_details():
    """' (family F, model M, L2 ..., L3 ...)': the CPU's family and model and its caches (one
    core's L2, the L3), as Linux reports them, since hosts sold under one model name differ
    (see the Performance page of the docs); '' where none is known."""
    info = cpu_info()
    parts = [f"{key.split()[-1]} {info[key]}" for key in ("cpu family", "model") if info.get(key)]
    for index in (2, 3):
        try:
            with open(f"/sys/devices/system/cpu/cpu0/cache/index{index}/size") as f:
                parts.append(f"L{index} {f.read().strip()}")
        except OSError:
            pass
    return f" ({', '.join(parts)})" if parts else ""


def gpu_model():
    try:
        out = subprocess.run(["nvidia-smi", "--query-gpu=name", "--format=csv,noheader"], capture_output=True,
                             text=True, timeout=20)
        if out.returncode == 0 and out.stdout.strip():
            return out.stdout.strip().splitlines()[0]
    except (OSError, subprocess.SubprocessError):
        pass
    return "gpu"


def source_hash(root):
    """A hash of the engine's source (circles/*.py): names the engine also where no git metadata is."""
    h = hashlib.sha1()
    for path in sorted(pathlib.Path(root, "circles").glob("*.py")):
        h.update(path.name.encode() + b"\0" + path.read_bytes())
    return h.hexdigest()[:10]


def engine_revision():
    """The commit of the engine under test, marked when circles/ has uncommitted changes (read-only git
    calls), and the hash of its source."""
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    try:
        head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=root, capture_output=True, text=True,
                              timeout=20).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--", "circles"], cwd=root, capture_output=True,
                               text=True, timeout=20).stdout.strip()
        commit = (head or "unknown") + (" with uncommitted changes to circles/" if dirty else "")
    except (OSError, subprocess.SubprocessError):
        commit = "unknown"
    return f"{commit} (circles/ source hash {source_hash(root)})"


def box_for(n, fraction, aspect):
    """(W, H) with W / H = aspect holding n circles of radius R at this area fraction."""
    h = math.sqrt(n * math.pi * R * R / (fraction * aspect))
    return (aspect * h, h)


def spread(values):
    return dict(median=statistics.median(values), min=min(values), max=max(values))


# ------------------------------------------------------------------ bandwidth
@ti.kernel
def _copy(src: ti.types.ndarray(ndim=1), dst: ti.types.ndarray(ndim=1)):
    for i in range(src.shape[0]):
        dst[i] = src[i]


def measure_bandwidth(numbers, reps):
    """Copy bandwidth (bytes read + written per second) of a Taichi kernel on f32 ndarrays."""
    src = ti.ndarray(ti.f32, shape=numbers)
    dst = ti.ndarray(ti.f32, shape=numbers)
    src.fill(1.0)
    dst.fill(0.0)
    _copy(src, dst)  # compile and first touch
    ti.sync()
    rates = []
    for _ in range(reps):
        t0 = now()
        _copy(src, dst)
        ti.sync()
        rates.append(2 * 4 * numbers / (now() - t0))
    # numpy's copy of the same size, as a check on the kernel.
    a = np.ones(numbers, dtype=np.float32)
    b = np.empty_like(a)
    np.copyto(b, a)
    np_rates = []
    for _ in range(reps):
        t0 = now()
        np.copyto(b, a)
        np_rates.append(2 * 4 * numbers / (now() - t0))
    del src, dst, a, b
    return [dict(method="taichi ndarray copy", mbytes=8 * numbers / 1e6, reps=reps, **_gb(rates)),
            dict(method="numpy copyto (check)", mbytes=8 * numbers / 1e6, reps=reps, **_gb(np_rates))]


def _gb(rates):
    s = spread([r / 1e9 for r in rates])
    return {"gbps_best": s["max"], "gbps_median": s["median"], "gbps_min": s["min"]}


# ----------------------------------------------------------------- throughput
#: Steps of a throughput row's scene before its timed repeats (see 1. above): the steady state of
#: a run, not the cheaper first steps of a fresh scene.
RELAX_STEPS = 60


def measure_throughput(n, scheme, precision, reps, target, bound_bw, max_steps=100_000):
    box = box_for(n, AREA_FRACTION, ASPECT)
    scene = circles.Scene(n=n, box=box, radius=R, speed=SPEED, boundary="walls", scheme=scheme,
                          precision=precision, seed=0)
    t0 = now()
    sim = circles.Simulation(scene)
    place_s = now() - t0
    st0 = sim.stats()
    t0 = now()
    sim.step(1)
    first_s = now() - t0
    t0 = now()
    sim.step(1)
    second_s = now() - t0
    t0 = now()
    sim.step(RELAX_STEPS - 2)
    relax_s = now() - t0
    t0 = now()
    sim.step(1)
    sizing_s = now() - t0
    k = int(max(1, min(max_steps, round(target / max(sizing_s, 1e-9)))))
    st1 = sim.stats()
    times = []
    for _ in range(reps):
        t0 = now()
        sim.step(k)
        times.append(now() - t0)
    st2 = sim.stats()
    steps_per_s = [k / t for t in times]
    s = spread(steps_per_s)
    pairs = st2["pair_collisions"] - st1["pair_collisions"]
    walls = st2["wall_collisions"] - st1["wall_collisions"]
    bytes_per = NUMBERS_PER_CIRCLE_STEP * BYTES[precision]
    bound = bound_bw / bytes_per
    row = dict(
        n=n, scheme=scheme, precision=precision, dt=sim.dt, box_w=box[0], box_h=box[1], place_s=place_s,
        warmup_first_step_s=first_s, warmup_second_step_s=second_s, relax_steps=RELAX_STEPS, relax_s=relax_s,
        steps_per_rep=k, reps=reps,
        steps_per_s_median=s["median"], steps_per_s_min=s["min"], steps_per_s_max=s["max"],
        circle_steps_per_s_median=n * s["median"], circle_steps_per_s_min=n * s["min"],
        circle_steps_per_s_max=n * s["max"],
        # Per step over all repeats, times the median step rate: a repeat that happens to
        # compile a kernel (more rounds, first needed mid-run) does not skew the rate.
        pair_collisions_per_s=pairs / (reps * k) * s["median"], wall_collisions_per_s=walls / (reps * k) * s["median"],
        sim_time_per_wall_s=sim.dt * s["median"],
        bytes_per_circle_step=bytes_per, bound_circle_steps_per_s=bound,
        fraction_of_bound=n * s["median"] / bound,
        energy_rel_change=abs(st2["kinetic_energy"] - st0["kinetic_energy"]) / st0["kinetic_energy"],
        max_overlap=st2["max_overlap"], rounds_per_step=sim.rounds / max(sim.steps, 1))
    return row, sim


def measure_render(sim, reps, width=1920, height=1080):
    t0 = now()
    sim.render(width, height)
    first = now() - t0
    times = []
    for _ in range(reps):
        t0 = now()
        sim.render(width, height)
        times.append(now() - t0)
    s = spread(times)
    return dict(n=sim.n, width=width, height=height, first_s=first, reps=reps, frame_s_median=s["median"],
                frame_s_min=s["min"], frame_s_max=s["max"])


#: Placement rows of the largest scene (`placement_n` circles: 1e6, 1e5 with --quick), float32: (area
#: fraction, repeats); one or two repeats keep the run short.
PLACEMENT_LARGE = ((0.5, 2), (0.8, 1))


def measure_placement(n, fraction, reps, aspect=ASPECT, precision="f64"):
    """Seconds to make Simulation(Scene) (placement and set-up) of N circles of radius R, walls, seed 0."""
    from circles import placement as placement_module

    box = box_for(n, fraction, aspect)
    times = []
    for _ in range(reps):
        scene = circles.Scene(n=n, box=box, radius=R, speed=SPEED, boundary="walls", scheme="discrete",
                              precision=precision, seed=0)
        t0 = now()
        sim = circles.Simulation(scene)
        times.append(now() - t0)
    s = spread(times)
    return dict(n=n, area_fraction=fraction, precision=precision,
                method=placement_module.method(np.full(n, R), box, False, precision == "f32"),
                reps=reps, place_s_median=s["median"], place_s_min=s["min"], place_s_max=s["max"],
                max_overlap=sim.stats()["max_overlap"])


# ----------------------------------------------------------------------- peer
#: Radius spread scene: this fraction of the circles is SPREAD_RATIO times larger than the rest.
SPREAD_LARGE_FRACTION = 0.01
SPREAD_RATIO = 50.0

_MEMORY_SCRIPT = """
import resource, sys
import circles
from circles.scene import Scene
n, scheme, precision, w, h, r = int(sys.argv[1]), sys.argv[2], sys.argv[3], float(sys.argv[4]), float(sys.argv[5]), float(sys.argv[6])
circles.init(arch=sys.argv[7])
sim = circles.Simulation(Scene(n=n, box=(w, h), radius=r, speed=(0.5, 1.0), scheme=scheme, precision=precision))
sim.step(2)
sim.stats()
import numpy as np, taichi as ti
def arrays(obj):
    for v in vars(obj).values():
        for a in (v.values() if isinstance(v, dict) else v if isinstance(v, (tuple, list)) else (v,)):
            if isinstance(a, ti.lang._ndarray.Ndarray):
                yield a
seen = {id(a): a for a in list(arrays(sim)) + list(arrays(sim.grid)) + list(arrays(sim.stepper))}
size = {ti.f32: 4, ti.i32: 4, ti.f64: 8}
allocated = sum(int(np.prod(a.shape)) * getattr(a, "n", 1) * size[a.dtype] for a in seen.values())
print(allocated, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
"""


def _peak_kb(n, scheme, precision, arch):
    box = box_for(n, AREA_FRACTION, ASPECT)
    out = subprocess.run([sys.executable, "-c", _MEMORY_SCRIPT, str(n), scheme, precision, repr(box[0]),
                          repr(box[1]), repr(R), arch], capture_output=True, text=True, check=True)
    allocated, peak_kb = map(int, out.stdout.split()[-2:])
    return allocated, peak_kb


def measure_memory(n, scheme, precision, arch, small=1000):
    """Peak resident memory of a fresh process that places N circles, takes 2 steps and reads the stats.

    Per circle: (peak at N - peak at `small` circles) / (N - small), so the Taichi runtime (which
    reserves and touches a memory pool at start) and Python are left out, while placement's and
    stats()' temporary numpy arrays are in: they are part of the peak a user sees.
    """
    t0 = now()
    _, base_kb = _peak_kb(small, scheme, precision, arch)
    allocated, peak_kb = _peak_kb(n, scheme, precision, arch)
    return dict(n=n, scheme=scheme, precision=precision, runtime_mb=base_kb / 1024, peak_mb=peak_kb / 1024,
                bytes_per_circle=(peak_kb - base_kb) * 1024 / (n - small), array_bytes_per_circle=allocated / n,
                wall_s=now() - t0)


def spread_radii(n):
    """Radii SPREAD_RATIO R (the first 1%) and R (the rest); the box holds them at AREA_FRACTION.

    The large circles come first: placement settles conflicts in favour of lower ids, so they
    find room before the small ones fill the box.
    """
    radius = np.full(n, R)
    radius[: max(1, int(round(SPREAD_LARGE_FRACTION * n)))] = SPREAD_RATIO * R
    area = float(np.sum(np.pi * radius ** 2)) / AREA_FRACTION
    h = math.sqrt(area / ASPECT)
    return radius, (ASPECT * h, h)


def spread_start(n, precision):
    """(pos, vel, radius, box) of the 1:50 radius mixture (`spread_radii`), placed in the storage
    precision (so that rounding to float32 leaves no overlap), speeds as the throughput scene's."""
    from circles import placement
    radius, box = spread_radii(n)
    pos = placement.random_sequential(radius, box, False, 0, single=precision == "f32")
    if pos is None:
        raise RuntimeError(f"random sequential addition could not place the 1:{SPREAD_RATIO:g} mixture of {n}")
    rng = np.random.default_rng(1)
    speed = rng.uniform(*SPEED, n)
    angle = rng.uniform(0, 2 * np.pi, n)
    vel = np.stack([speed * np.cos(angle), speed * np.sin(angle)], axis=1)
    return pos, vel, radius, box


def measure_spread(n, scheme, precision, reps, target):
    """Circle-steps/s of the 1:50 radius mixture against equal radii at the same N, side by side."""
    pos, vel, radius, box = spread_start(n, precision)
    rows = {}
    for label, make in (("equal radii", lambda: circles.Simulation(circles.Scene(
            n=n, box=box_for(n, AREA_FRACTION, ASPECT), radius=R, speed=SPEED, scheme=scheme, precision=precision))),
                        (f"1:{SPREAD_RATIO:g} ({SPREAD_LARGE_FRACTION:.0%} large)", lambda: circles.Simulation.from_arrays(
            pos, vel, radius, mass="radius", box=box, scheme=scheme, precision=precision))):
        sim = make()
        sim.step(1)
        t0 = now()
        sim.step(1)
        k = int(max(1, round(target / max(now() - t0, 1e-9))))
        times = []
        for _ in range(reps):
            t0 = now()
            sim.step(k)
            times.append(now() - t0)
        s = spread([n * k / t for t in times])
        rows[label] = dict(s, dt=sim.dt)
    (eq_label, eq), (sp_label, sp) = rows.items()
    return dict(n=n, scheme=scheme, precision=precision, equal_dt=eq["dt"], spread_dt=sp["dt"],
                equal_circle_steps_per_s=eq["median"],
                spread_circle_steps_per_s=sp["median"], spread_min=sp["min"], spread_max=sp["max"],
                cost_ratio=eq["median"] / sp["median"])


def start_state(n, fraction, aspect, boundary, seed=0):
    box = box_for(n, fraction, aspect)
    scene = circles.Scene(n=n, box=box, radius=R, speed=SPEED, boundary=boundary, scheme="event",
                          precision="f64", seed=seed)
    s = circles.Simulation(scene).state()
    return s.pos, s.vel, s.radius, s.mass, box


def measure_peer(n, reps, target, configs):
    """pymunk and circles at N side by side: each (scheme, precision) of `configs` on the
    throughput rows' scene, pymunk on the same scene with the discrete scheme's default dt.
    Every repeat times each engine's steps (about `target` seconds each) one after another, so
    that the drift of a shared machine falls on all alike. Returns the pymunk row and one ratio
    row per configuration: the ratio of the medians, and the least and greatest ratio within
    one repeat."""
    pos, vel, radius, mass, box = start_state(n, AREA_FRACTION, ASPECT, "walls")
    t0 = now()
    gas = peer_pymunk.PymunkGas(pos, vel, radius, mass, box)
    build_s = now() - t0
    sims = {cfg: circles.Simulation(circles.Scene(n=n, box=box, radius=R, speed=SPEED, boundary="walls",
                                                  scheme=cfg[0], precision=cfg[1], seed=0)) for cfg in configs}
    dt = next((sim.dt for (scheme, _), sim in sims.items() if scheme == "discrete"),
              circles.schemes.default_dt("discrete", radius, vel))
    runners = {"pymunk": lambda k: gas.step(dt, k)}
    runners.update({cfg: sim.step for cfg, sim in sims.items()})
    e0 = gas.kinetic_energy()
    first, steps = {}, {}
    for key, run in runners.items():
        # Warm-up: the first step; for circles, steps up to its first reorder of the arrays (whose
        # kernels compile on first use); then a step that sets the repeat length.
        t0 = now()
        run(1)
        first[key] = now() - t0
        if key != "pymunk":
            run(circles.simulation.REORDER_EVERY)
        t0 = now()
        run(1)
        steps[key] = int(max(1, round(target / max(now() - t0, 1e-9))))
    rates = {key: [] for key in runners}
    for _ in range(reps):
        for key, run in runners.items():
            t0 = now()
            run(steps[key])
            rates[key].append(steps[key] / (now() - t0))
    p = spread(rates["pymunk"])
    peer = dict(peer="pymunk " + pymunk_version(), n=n, dt=dt, build_s=build_s, warmup_first_step_s=first["pymunk"],
                steps_per_rep=steps["pymunk"], reps=reps, steps_per_s_median=p["median"], steps_per_s_min=p["min"],
                steps_per_s_max=p["max"], circle_steps_per_s_median=n * p["median"],
                circle_steps_per_s_min=n * p["min"], circle_steps_per_s_max=n * p["max"],
                sim_time_per_wall_s=dt * p["median"],
                energy_rel_change=abs(gas.kinetic_energy() - e0) / e0, max_overlap=gas.max_overlap())
    ratios = []
    for (scheme, precision), sim in sims.items():
        c = spread(rates[(scheme, precision)])
        each = [a / b for a, b in zip(rates[(scheme, precision)], rates["pymunk"])]
        ratios.append(dict(n=n, scheme=scheme, precision=precision, dt=sim.dt, steps_per_rep=steps[(scheme, precision)],
                           circle_steps_per_s_median=n * c["median"], circle_steps_per_s_min=n * c["min"],
                           circle_steps_per_s_max=n * c["max"], circle_steps_ratio=c["median"] / p["median"],
                           ratio_min=min(each), ratio_max=max(each),
                           sim_time_ratio=sim.dt * c["median"] / (dt * p["median"])))
    return peer, ratios


def pymunk_version():
    if peer_pymunk is None:
        return "not installed"
    return peer_pymunk.pymunk.version


# ------------------------------------------------------------ work-precision
def run_circles(start, boundary, scheme, precision, dt, duration):
    pos, vel, radius, mass, box = start
    sim = circles.Simulation.from_arrays(pos, vel, radius, mass=mass, box=box, boundary=boundary, scheme=scheme,
                                         precision=precision, dt=dt)
    e0 = float(0.5 * np.sum(mass * (vel * vel).sum(axis=1)))
    wall = 0.0
    energy_err = overlap = 0.0
    seg_rate, seg_z = [], []
    last = dict(pair_collisions=0, virial=0.0)
    for _ in range(NSEG):
        t0 = now()
        sim.advance(duration / NSEG)
        wall += now() - t0
        st = sim.stats()
        energy_err = max(energy_err, abs(st["kinetic_energy"] - e0) / e0)
        overlap = max(overlap, st["max_overlap"])
        seg_rate.append((st["pair_collisions"] - last["pair_collisions"]) / (duration / NSEG))
        seg_z.append(1.0 + (st["virial"] - last["virial"]) / (2.0 * (duration / NSEG) * st["kinetic_energy"]))
        last = st
    return dict(dt=sim.dt, duration=duration, wall_s=wall, pair_collisions=st["pair_collisions"],
                virial=st["virial"], kinetic_energy=st["kinetic_energy"], energy_error=energy_err,
                max_overlap=overlap, steps=sim.steps, collision_floor=_standard_error(seg_rate),
                pressure_floor=_standard_error(seg_z))


def _standard_error(values):
    """Relative standard error of the mean of per-segment values: the statistical floor of a run this long."""
    values = np.asarray(values, dtype=np.float64)
    if len(values) < 2 or values.mean() == 0:
        return float("nan")
    return float(values.std(ddof=1) / math.sqrt(len(values)) / abs(values.mean()))


def run_pymunk(start, dt, duration):
    pos, vel, radius, mass, box = start
    steps = max(NSEG, int(round(duration / dt)))
    per_seg = [steps // NSEG + (1 if i < steps % NSEG else 0) for i in range(NSEG)]
    timed = peer_pymunk.PymunkGas(pos, vel, radius, mass, box)
    t0 = now()
    timed.step(dt, steps)
    wall = now() - t0
    final_timed = timed.positions()
    gas = peer_pymunk.PymunkGas(pos, vel, radius, mass, box, observe=True)
    e0 = gas.kinetic_energy()
    energy_err = overlap = 0.0
    for k in per_seg:
        gas.step(dt, k)
        energy_err = max(energy_err, abs(gas.kinetic_energy() - e0) / e0)
        overlap = max(overlap, gas.max_overlap())
    same = bool(np.array_equal(final_timed, gas.positions()))
    return dict(dt=dt, duration=steps * dt, wall_s=wall, pair_collisions=gas.pair_collisions, virial=gas.virial,
                kinetic_energy=gas.kinetic_energy(), energy_error=energy_err, max_overlap=overlap, steps=steps,
                note="" if same else "timed and observed runs differ")


def compressibility(run, n):
    # Z = 1 + virial / (2 T N kT), kT = E / N.
    return 1.0 + run["virial"] / (2.0 * run["duration"] * run["kinetic_energy"])


def work_precision(cfg):
    n = cfg["wp_n"]
    rows = []
    for fraction in (0.3, 0.6):
        for boundary, runners in (("periodic", ("discrete", "event")), ("walls", ("pymunk",))):
            log(f"  work-precision: area fraction {fraction}, {boundary}: start state")
            start = start_state(n, fraction, 1.0, boundary, seed=1)
            # Warm the kernels of this boundary before anything is timed.
            for scheme in SCHEMES:
                run_circles(start, boundary, scheme, "f64", None, 1e-3)
            # Mean free time from a short reference run, then the reference over the full span.
            pilot = run_circles(start, boundary, "event", "f64", None, 2.0)
            mft = pilot["duration"] * n / max(2 * pilot["pair_collisions"], 1)
            duration = cfg["wp_duration_mft"] * mft
            ref = run_circles(start, boundary, "event", "f64", None, duration)
            mft = ref["duration"] * n / max(2 * ref["pair_collisions"], 1)
            z_ref = compressibility(ref, n)
            log(f"    mean free time {mft:.4g}, T = {duration:.4g}, reference: {ref['pair_collisions']} collisions, "
                f"Z = {z_ref:.4f}, {ref['wall_s']:.2f} s; statistical floor: Z {ref['pressure_floor']:.2g}, "
                f"collision rate {ref['collision_floor']:.2g}")

            def row(method, precision, factor, run):
                z = compressibility(run, n)
                rate = run["pair_collisions"] / run["duration"]
                ref_rate = ref["pair_collisions"] / ref["duration"]
                return dict(area_fraction=fraction, boundary=boundary, n=n, method=method, precision=precision,
                            dt_over_mft=factor, dt=run["dt"], mean_free_time=mft, duration=run["duration"],
                            steps=run["steps"], wall_s=run["wall_s"], cost_s_per_time=run["wall_s"] / run["duration"],
                            z=z, z_ref=z_ref, pressure_error=abs(z - z_ref) / z_ref,
                            collisions=run["pair_collisions"], collision_error=abs(rate - ref_rate) / ref_rate,
                            energy_error=run["energy_error"], max_overlap=run["max_overlap"],
                            pressure_floor=ref["pressure_floor"], collision_floor=ref["collision_floor"],
                            note=run.get("note", ""))

            rows.append(row("reference (event)", "f64", ref["dt"] / mft, ref))
            for method in runners:
                for factor in cfg["wp_factors"]:
                    dt = factor * mft
                    if method == "pymunk":
                        run = run_pymunk(start, dt, duration)
                        rows.append(row("pymunk", "f64", factor, run))
                    else:
                        if method == "discrete":
                            # An untimed run first: the first step that needs more rounds than one
                            # launch holds compiles their kernel, which would otherwise count in
                            # the row's time (0.04 s per time unit against 0.001 at dt 0.5 mft).
                            run_circles(start, boundary, method, "f64", dt, duration)
                        run = run_circles(start, boundary, method, "f64", dt, duration)
                        rows.append(row(method, "f64", factor, run))
                    r = rows[-1]
                    log(f"    {method:8s} dt = {factor:5.2f} mft: {r['cost_s_per_time']:.3g} s per time unit, "
                        f"Z error {r['pressure_error']:.2g}, collisions {r['collision_error']:.2g}, "
                        f"energy {r['energy_error']:.2g}, overlap {r['max_overlap']:.2g}")
    return rows


# ------------------------------------------------------------------- output
def write_csv(path, rows):
    if not rows:
        return
    keys = list(rows[0].keys())
    for r in rows[1:]:
        keys += [k for k in r if k not in keys]
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=keys)
        w.writeheader()
        for r in rows:
            w.writerow({k: _fmt(v) for k, v in r.items()})


def _fmt(v):
    if isinstance(v, float):
        return f"{v:.6g}"
    return v


def g(v, digits=3):
    if v is None or v == "":
        return ""
    if isinstance(v, float):
        if v == 0:
            return "0"
        return f"{v:.{digits}g}"
    return str(v)


def md_table(headers, rows):
    out = ["| " + " | ".join(headers) + " |", "|" + "|".join("---" for _ in headers) + "|"]
    out += ["| " + " | ".join(g(c) if not isinstance(c, str) else c for c in r) + " |" for r in rows]
    return "\n".join(out)


def plot_work_precision(rows, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    measures = (("pressure_error", "pressure Z, relative error"), ("collision_error", "collision rate, relative error"),
                ("energy_error", "energy, largest relative change"), ("max_overlap", "largest overlap / contact"))
    fractions = sorted({r["area_fraction"] for r in rows})
    style = {"discrete": ("tab:orange", "o"), "event": ("tab:blue", "s"), "pymunk": ("tab:green", "^")}
    floor = 1e-17
    fig, axes = plt.subplots(len(fractions), len(measures), figsize=(4.2 * len(measures), 3.8 * len(fractions)),
                             squeeze=False)
    for i, fr in enumerate(fractions):
        for j, (key, label) in enumerate(measures):
            ax = axes[i][j]
            for method, (color, marker) in style.items():
                pts = sorted((r["dt_over_mft"], max(r[key], floor), r["cost_s_per_time"]) for r in rows
                             if r["area_fraction"] == fr and r["method"] == method)
                if not pts:
                    continue
                ax.loglog([p[1] for p in pts], [p[2] for p in pts], marker=marker, color=color, label=method)
                for f, x, y in (pts[0], pts[-1]):
                    ax.annotate(f"{f:g}", (x, y), textcoords="offset points", xytext=(4, 2), fontsize=7,
                                color=color)
            for r in rows:
                if r["area_fraction"] == fr and r["method"].startswith("reference") and r["boundary"] == "periodic":
                    ax.axhline(r["cost_s_per_time"], color="gray", lw=0.8, ls="--", label="reference cost")
                    floor_key = {"pressure_error": "pressure_floor", "collision_error": "collision_floor"}.get(key)
                    if floor_key and math.isfinite(r[floor_key]):
                        ax.axvline(r[floor_key], color="gray", lw=0.8, ls=":", label="statistical floor")
            ax.set_xlabel(label)
            if j == 0:
                ax.set_ylabel(f"phi = {fr}: wall s per unit time")
            ax.grid(True, which="both", lw=0.3)
    axes[0][0].legend(fontsize=8)
    fig.suptitle(f"work-precision, N = {rows[0]['n']} (labels: dt / mean free time; values below 1e-17 at 1e-17)",
                 fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def write_markdown(path, meta, compile_rows, bandwidth, throughput, placement, render, peers, ratios, wp, errors,
                   memory=(), spreads=(), goals=()):
    lines = [f"# circles benchmark: {meta['machine_name']}", "",
             f"Command: `{meta['command']}`  ", f"Date: {meta['date']}  ", f"Engine: {meta['revision']}  ",
             f"Machine: {meta['machine_name']}{meta['cpu_details']}, {meta['cores']} cores; arch {meta['arch']}; "
             f"taichi {meta['taichi']}, "
             f"pymunk {meta['pymunk']}, numpy {np.__version__}, Python {platform.python_version()}  ",
             f"Wall time of the whole run: {meta['wall_s']:.0f} s. Timings are noisy (a shared machine): "
             "medians with min and max over repeats.", ""]
    if meta.get("partial"):
        lines += [f"**Partial:** written after the section `{meta['partial']}`; the run did not reach its end "
                  "(the sections after it are missing).", ""]
    lines += [
             "Scene of the throughput and peer rows: circles of radius "
             f"{R} at area fraction {AREA_FRACTION} in a 16:9 walled box, speeds uniform in {SPEED}, "
             "mass = radius, default dt (event: the fastest circle moves 0.3 mean radii per step; discrete: 0.2 smallest radii).", ""]
    if goals:
        lines += ["## Targets", "",
                  "The project's performance targets judged on this run's tables (`bench/targets.py`: each on "
                  "its median, f32; \"not measured\" where the run left out what it needs).", "",
                  targets.markdown(goals), ""]
    lines += ["## Memory copy bandwidth", "",
              md_table(["method", "MB moved", "best GB/s", "median GB/s", "min GB/s"],
                       [[b["method"], b["mbytes"], b["gbps_best"], b["gbps_median"], b["gbps_min"]] for b in bandwidth]),
              "", f"Bound model: {NUMBERS_PER_CIRCLE_STEP} numbers per circle-step (pos and vel read and written, "
              "radius read): 36 B in f32, 72 B in f64, both schemes; grid, neighbour reads and the event scheme's "
              "extra arrays are not counted, so the bound is optimistic. Bound = best taichi copy bandwidth / bytes.", ""]
    lines += ["## Compilation", "",
              "First Simulation and 2 steps of N = 200 per scheme and precision, before anything else is timed: "
              "this is Taichi's compilation (or loading from its offline cache, when an earlier run compiled "
              "the same kernels). Every row below also reports its own first and second step apart.", "",
              md_table(["scheme", "prec", "first run s"],
                       [[c["scheme"], c["precision"], c["first_run_s"]] for c in compile_rows]), ""]
    lines += ["## Throughput", "",
              f"Each row: its first and second steps timed apart, then {RELAX_STEPS} steps in all before the timed "
              "repeats, so that the speeds have spread out from their start (a relaxed scene: the event scheme's "
              "cells follow the fastest circle, which grows over the first tens of steps).", "",
              md_table(["N", "scheme", "prec", "dt", "warm-up 1st / 2nd step s", "steps/rep", "steps/s median [min, max]",
                        "circle-steps/s", "pair coll./s", "sim time / wall s", "of bound", "energy change",
                        "max overlap"],
                       [[t["n"], t["scheme"], t["precision"], t["dt"],
                         f"{g(t['warmup_first_step_s'])} / {g(t['warmup_second_step_s'])}", t["steps_per_rep"],
                         f"{g(t['steps_per_s_median'])} [{g(t['steps_per_s_min'])}, {g(t['steps_per_s_max'])}]",
                         t["circle_steps_per_s_median"], t["pair_collisions_per_s"], t["sim_time_per_wall_s"],
                         t["fraction_of_bound"], t["energy_rel_change"], t["max_overlap"]] for t in throughput]), ""]
    lines += ["## Placement", "",
              "Seconds to make a Simulation of N circles of radius R in a 16:9 walled box (placement and set-up); "
              "the 0.3 rows are the throughput rows' scenes.", "",
              md_table(["N", "area fraction", "prec", "method", "reps", "s median [min, max]", "max overlap"],
                       [[p["n"], p["area_fraction"], p.get("precision", ""), p["method"], p["reps"],
                         f"{g(p['place_s_median'])} [{g(p['place_s_min'])}, {g(p['place_s_max'])}]",
                         p.get("max_overlap", "")]
                        for p in placement]), ""]
    lines += ["## Render, 1920x1080 frame", "",
              md_table(["N", "first call s (compile)", "s per frame median [min, max]"],
                       [[r["n"], r["first_s"], f"{g(r['frame_s_median'])} [{g(r['frame_s_min'])}, {g(r['frame_s_max'])}]"]
                        for r in render]), ""]
    if memory:
        lines += ["## Memory", "",
                  "Peak resident memory of a fresh process that places the scene (area fraction "
                  f"{AREA_FRACTION}, walls), takes 2 steps and reads the stats; per circle: (peak at N - peak at "
                  "1000 circles) / (N - 1000), so the Taichi runtime is left out and placement's temporary arrays "
                  "are in.", "",
                  "Taichi reserves and touches a memory pool at start, so below a few million circles the "
                  "peak does not move; the arrays column counts the bytes of every array the simulation and its "
                  "grid hold, divided by N.", "",
                  md_table(["N", "scheme", "prec", "peak MB at 1000", "peak MB", "peak bytes per circle",
                            "array bytes per circle"],
                           [[m["n"], m["scheme"], m["precision"], m["runtime_mb"], m["peak_mb"], m["bytes_per_circle"],
                             m["array_bytes_per_circle"]] for m in memory]), ""]
    if spreads:
        lines += ["## Radius spread", "",
                  f"{SPREAD_LARGE_FRACTION:.0%} of the circles {SPREAD_RATIO:g} times larger than the rest, area "
                  f"fraction {AREA_FRACTION} in all, walls, default dt; against equal radii at the same N and area "
                  "fraction, side by side. Cost ratio: equal radii circle-steps/s over the mixture's (above 1: the "
                  "mixture costs more per circle-step).", "",
                  md_table(["N", "scheme", "prec", "dt equal / mixture", "equal radii circle-steps/s",
                            "mixture circle-steps/s [min, max]", "cost ratio"],
                           [[sp["n"], sp["scheme"], sp["precision"], f"{g(sp['equal_dt'])} / {g(sp['spread_dt'])}",
                             sp["equal_circle_steps_per_s"],
                             f"{g(sp['spread_circle_steps_per_s'])} [{g(sp['spread_min'])}, {g(sp['spread_max'])}]",
                             sp["cost_ratio"]] for sp in spreads]), ""]
    lines += ["## Peer: pymunk (Chipmunk2D, one thread) on the same scene and dt as `discrete`", "",
              md_table(["N", "dt", "steps/s median [min, max]", "circle-steps/s", "sim time / wall s",
                        "energy change", "max overlap"],
                       [[p["n"], p["dt"], f"{g(p['steps_per_s_median'])} [{g(p['steps_per_s_min'])}, "
                         f"{g(p['steps_per_s_max'])}]", p["circle_steps_per_s_median"], p["sim_time_per_wall_s"],
                         p["energy_rel_change"], p["max_overlap"]] for p in peers]), "",
              "Ratios circles / pymunk at equal N (above 1: circles is faster), measured side by side with the "
              "pymunk row: each repeat times pymunk, then each circles configuration, on the same scene. "
              "circle-steps: per step of its own dt, the ratio of the medians with the least and greatest "
              "ratio within one repeat; sim time: simulated time per wall second (the event scheme takes "
              "1.5x longer steps).", "",
              md_table(["N", "scheme", "prec", "circles circle-steps/s median [min, max]", "circle-steps ratio",
                        "ratio in one repeat [min, max]", "sim-time ratio"],
                       [[r["n"], r["scheme"], r["precision"],
                         f"{g(r['circle_steps_per_s_median'])} [{g(r['circle_steps_per_s_min'])}, "
                         f"{g(r['circle_steps_per_s_max'])}]", r["circle_steps_ratio"],
                         f"[{g(r['ratio_min'])}, {g(r['ratio_max'])}]", r["sim_time_ratio"]]
                        for r in ratios]), ""]
    if wp:
        n = wp[0]["n"]
        lines += ["## Work-precision", "",
                  f"N = {n}; discrete and event in a periodic square box against an event f64 reference at its "
                  "default dt; pymunk in a walled square box (it has no periodic one) against the event f64 "
                  "reference of that walled scene. Cost: wall seconds per unit of simulated time. Errors: "
                  "pressure Z (pair virial), collision rate, largest energy change, largest overlap at "
                  f"{NSEG} checkpoints. The motion is chaotic: a run whose collisions differ from the reference's "
                  "soon follows another trajectory with the same statistics, so its Z and collision errors "
                  "cannot be resolved below the statistical floor of a run this long (the relative standard "
                  f"error of the reference's mean over its {NSEG} segments, the dotted line in the plot and the "
                  "`floor` columns). The event rows at other dt follow the reference's own collisions, so "
                  "their differences are round-off.", "", "![work-precision](work_precision.png)", "",
                  md_table(["phi", "box", "method", "dt / mft", "steps", "s per time", "Z", "Z error",
                            "Z floor", "collision error", "collision floor", "energy error", "max overlap"],
                           [[w["area_fraction"], w["boundary"], w["method"], w["dt_over_mft"], w["steps"],
                             w["cost_s_per_time"], w["z"], w["pressure_error"], w["pressure_floor"],
                             w["collision_error"], w["collision_floor"], w["energy_error"], w["max_overlap"]]
                            for w in wp]), ""]
    if errors:
        lines += ["## Failures", ""] + [f"- {e}" for e in errors] + [""]
    with open(path, "w") as f:
        f.write("\n".join(lines))


# ---------------------------------------------------------------------- main
def parse_args(argv=None):
    """The command line, checked before anything is compiled or measured."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true",
                    help="smaller sizes (up to 1e5 circles), a few minutes on a 2-core CPU; writes to the scratch "
                         f"folder {QUICK_OUT} unless --out is given")
    ap.add_argument("--arch", choices=("cpu", "gpu"), default="cpu", help="where the kernels run (default: cpu)")
    ap.add_argument("--out", default=None,
                    help=f"folder of the results, a subfolder per machine (default: {FULL_OUT}; with --quick or "
                         f"--skip: {QUICK_OUT})")
    ap.add_argument("--skip", default="", help=f"comma list of sections to skip: {','.join(SECTIONS)} (default: "
                    f"none); writes to {QUICK_OUT} unless --out is given")
    ap.add_argument("--ecmc", default=None, help="the dense section's peer: the StraightEcmc program of Li et al. "
                    "2022, built by you (see bench/peer_ecmc.py)")
    args = ap.parse_args(argv)
    if args.ecmc is not None and peer_ecmc.missing(args.ecmc):
        ap.error(peer_ecmc.missing(args.ecmc))
    args.skip = set(filter(None, (name.strip() for name in args.skip.split(","))))
    unknown = sorted(args.skip - set(SECTIONS))
    if unknown:
        ap.error(f"--skip {','.join(unknown)}: no such section; the sections are {','.join(SECTIONS)}")
    if args.out is None:
        args.out = QUICK_OUT if args.quick or args.skip else FULL_OUT
    return ap, args


def check_folder(ap, outdir):
    """Make `outdir`; a folder that cannot be written is a command-line error, found before any work."""
    try:
        os.makedirs(outdir, exist_ok=True)
    except OSError as e:
        ap.error(f"--out: cannot make {outdir} ({e.strerror}): give a folder you can write to")
    if not os.access(outdir, os.W_OK | os.X_OK):
        ap.error(f"--out: cannot write into {outdir}: give a folder you can write to")


def clear_folder(outdir):
    """Remove the files an earlier run wrote into `outdir` (OUTPUT_FILES): the folder then holds
    this run's results only, also where this run skips a section or a section fails."""
    removed = []
    for name in OUTPUT_FILES:
        path = os.path.join(outdir, name)
        if os.path.isfile(path):
            os.remove(path)
            removed.append(name)
    return removed


def main(argv=None):
    ap, args = parse_args(argv)
    start = now()
    # The machine's name (the subfolder) needs the arch only: the GPU's name comes from nvidia-smi,
    # so the folder is checked before Taichi starts.
    machine_name = cpu_model() if args.arch == "cpu" else gpu_model()
    outdir = os.path.join(args.out, slug(machine_name))
    check_folder(ap, outdir)
    arch = circles.init(arch=args.arch)
    removed = clear_folder(outdir)
    cfg = QUICK if args.quick else GPU if arch == "gpu" else FULL
    skip = args.skip | set(cfg.get("skip", ()))
    precisions = cfg.get("precisions", PRECISIONS)
    errors = []
    scratch = " (a scratch folder: give --out to keep the results elsewhere)" if args.out == QUICK_OUT else ""
    details = cpu_details() if arch == "cpu" else ""
    log(f"circles benchmark on {machine_name}{details} ({arch}), writing {outdir}{scratch}")
    if removed:
        log(f"  removed the earlier run's {', '.join(removed)} there")

    def guarded(what, fn, *a, **kw):
        try:
            return fn(*a, **kw)
        except Exception as e:  # a failure is a result: record it and go on
            msg = f"{what}: {type(e).__name__}: {' '.join(str(e).split())[:300]}"
            log("  FAILED " + msg)
            errors.append(msg)
            return None

    log("bandwidth")
    bandwidth = measure_bandwidth(cfg["copy_numbers"], cfg["copy_reps"])
    bw = bandwidth[0]["gbps_best"] * 1e9
    log("  " + ", ".join(f"{b['method']} {b['gbps_best']:.2f} GB/s best, median {b['gbps_median']:.2f} "
                         f"[{b['gbps_min']:.2f}, {b['gbps_best']:.2f}]" for b in bandwidth))

    # Compile the placement and step kernels on a small scene first, so that the first row does
    # not carry every compilation.
    # Taichi keeps compiled kernels in its offline cache between runs, so this depends on what ran before.
    compile_rows = []
    for scheme in SCHEMES:
        for precision in precisions:
            t0 = now()
            ok = guarded("warm-up", lambda: circles.Simulation(circles.Scene(
                n=200, box=box_for(200, AREA_FRACTION, ASPECT), radius=R, speed=SPEED, scheme=scheme,
                precision=precision)).step(2))
            compile_rows.append(dict(scheme=scheme, precision=precision, n=200, steps=2,
                                     first_run_s=now() - t0, ok=ok is not None))
    log("  first runs (compilation): " + ", ".join(f"{c['scheme']} {c['precision']} {c['first_run_s']:.2f} s"
                                                  for c in compile_rows))

    throughput, render, placement, memory, spreads, peers, ratios, wp = [], [], [], [], [], [], [], []
    command = "python " + " ".join([os.path.relpath(sys.argv[0])] + sys.argv[1:])

    def save(section, final=False):
        """Write every table so far: a run stopped later still leaves what it measured."""
        version = ti.__version__
        meta = dict(machine_name=machine_name, cpu_details=details, cores=os.cpu_count(), arch=arch,
                    taichi=".".join(map(str, version)) if isinstance(version, tuple) else str(version),
                    pymunk=pymunk_version(), revision=engine_revision(), command=command,
                    date=datetime.datetime.now().astimezone().strftime("%Y-%m-%d %H:%M %Z"), wall_s=now() - start,
                    partial=None if final else section)
        write_csv(os.path.join(outdir, "bandwidth.csv"), bandwidth)
        write_csv(os.path.join(outdir, "throughput.csv"), throughput)
        write_csv(os.path.join(outdir, "placement.csv"), placement)
        write_csv(os.path.join(outdir, "render.csv"), render)
        write_csv(os.path.join(outdir, "compile.csv"), compile_rows)
        write_csv(os.path.join(outdir, "peers.csv"), peers + [dict(peer="ratio circles/pymunk", **r) for r in ratios])
        write_csv(os.path.join(outdir, "work_precision.csv"), wp)
        write_csv(os.path.join(outdir, "memory.csv"), memory)
        write_csv(os.path.join(outdir, "spread.csv"), spreads)
        goals = targets.evaluate(dict(throughput=throughput, placement=placement, render=render, memory=memory,
                                      spread=spreads, peers=peers + ratios), arch)
        write_csv(os.path.join(outdir, "targets.csv"),
                  [dict(target=t, measured=m, met=ok) for t, m, ok in goals])
        if wp and final:
            guarded("plot", plot_work_precision, wp, os.path.join(outdir, "work_precision.png"))
        write_markdown(os.path.join(outdir, "results.md"), meta, compile_rows, bandwidth, throughput, placement,
                       render, peers, ratios, wp, errors, memory, spreads, goals)
        return goals

    if "throughput" not in skip:
        log("throughput")
        for n in cfg["sizes"]:
            for scheme in SCHEMES:
                if scheme == "event" and n not in cfg["event_sizes"]:
                    continue
                for precision in precisions:
                    res = guarded(f"throughput N={n} {scheme} {precision}", measure_throughput, n, scheme,
                                  precision, cfg["reps"], cfg["target"], bw)
                    if res is None:
                        continue
                    row, sim = res
                    throughput.append(row)
                    log(f"  N={n:>8} {scheme:8s} {precision}: {row['circle_steps_per_s_median']:.3g} circle-steps/s "
                        f"[{row['circle_steps_per_s_min']:.3g}, {row['circle_steps_per_s_max']:.3g}], "
                        f"{row['fraction_of_bound']:.2g} of bound, warm-up {row['warmup_first_step_s']:.2f} s, "
                        f"placement {row['place_s']:.2f} s")
                    if scheme == "discrete" and precision == "f32":
                        r = guarded(f"render N={n}", measure_render, sim, cfg["render_reps"])
                        if r:
                            render.append(r)
                            log(f"  render N={n}: {r['frame_s_median']:.3g} s per 1920x1080 frame "
                                f"[{r['frame_s_min']:.3g}, {r['frame_s_max']:.3g}]")
                    del sim
                    save(f"throughput N={n} {scheme} {precision}")
        # Placement at 0.3: every throughput row built its scene (same seed, so the same placement).
        for n in cfg["sizes"]:
            ts = [t["place_s"] for t in throughput if t["n"] == n]
            if ts:
                s = spread(ts)
                placement.append(dict(n=n, area_fraction=AREA_FRACTION, precision=", ".join(precisions),
                                      method="random sequential addition", reps=len(ts), place_s_median=s["median"],
                                      place_s_min=s["min"], place_s_max=s["max"], max_overlap=""))
    if "placement" not in skip:
        # The warm-up above placed at 0.3 only: compile the kernels of the denser methods first.
        for fraction in (0.5, 0.8):
            for precision in precisions:
                guarded("placement warm-up", measure_placement, 300, fraction, 1, precision=precision)
        log("placement at area fraction 0.8")
        for n in cfg["dense_sizes"]:
            p = guarded(f"placement N={n} fraction 0.8", measure_placement, n, 0.8, 1 if n > 1000 else 2)
            if p:
                placement.append(p)
                log(f"  N={n}: {p['place_s_median']:.3g} s")
        n = cfg["placement_n"]
        log(f"placement of {n} circles")
        for fraction, reps in PLACEMENT_LARGE:
            p = guarded(f"placement N={n} fraction {fraction}", measure_placement, n, fraction, reps,
                        precision="f32")
            if p:
                placement.append(p)
                log(f"  fraction {fraction}: {p['place_s_median']:.3g} s [{p['place_s_min']:.3g}, "
                    f"{p['place_s_max']:.3g}], largest overlap {p['max_overlap']:.3g}")

    save("placement")
    if "memory" not in skip:
        log("memory")
        for n in cfg["memory_sizes"]:
            for scheme in SCHEMES:
                m = guarded(f"memory N={n} {scheme}", measure_memory, n, scheme, "f32", arch)
                if m:
                    memory.append(m)
                    log(f"  N={n} {scheme} f32: {m['bytes_per_circle']:.0f} B per circle at peak, "
                        f"{m['array_bytes_per_circle']:.0f} B in arrays, peak {m['peak_mb']:.0f} MB")
    if "spread" not in skip:
        log("radius spread")
        for n in cfg["spread_sizes"]:
            for scheme in SCHEMES:
                sp = guarded(f"spread N={n} {scheme}", measure_spread, n, scheme, "f32", cfg["reps"], cfg["target"])
                if sp:
                    spreads.append(sp)
                    log(f"  N={n} {scheme}: 1:{SPREAD_RATIO:g} mixture costs {sp['cost_ratio']:.2f}x equal radii")

    save("spread")
    if "peers" not in skip:
        log("peer: pymunk")
        for n in cfg["peer_sizes"]:
            # The configurations of the throughput rows at this N (all of them when that section was skipped).
            configs = [(t["scheme"], t["precision"]) for t in throughput if t["n"] == n] or \
                [(scheme, precision) for scheme in SCHEMES for precision in precisions]
            measured = guarded(f"pymunk N={n}", measure_peer, n, cfg["reps"], cfg["target"], configs)
            if measured is None:
                continue
            p, side = measured
            peers.append(p)
            ratios.extend(side)
            log(f"  N={n:>8} pymunk: {p['circle_steps_per_s_median']:.3g} circle-steps/s "
                f"[{p['circle_steps_per_s_min']:.3g}, {p['circle_steps_per_s_max']:.3g}], energy change "
                f"{p['energy_rel_change']:.2g}, overlap {p['max_overlap']:.2g}; circles / pymunk: "
                + ", ".join(f"{r['scheme']} {r['precision']} {r['circle_steps_ratio']:.3g}x "
                            f"[{r['ratio_min']:.3g}, {r['ratio_max']:.3g}]" for r in side))

    save("peers")
    if "wp" not in skip:
        log("work-precision")
        wp.extend(guarded("work-precision", work_precision, cfg) or [])

    goals = save("work-precision", final=True)
    if "dense" not in skip:
        # Dense disks near melting (bench/dense.py), a process a row: its own threads.
        log("dense")
        dense = [sys.executable, os.path.join(os.path.dirname(os.path.abspath(__file__)), "dense.py"), "--out",
                 args.out] + (["--quick"] if args.quick else []) + (["--ecmc", args.ecmc] if args.ecmc else [])
        if subprocess.run(dense).returncode != 0:
            errors.append("dense: bench/dense.py failed (its output above)")
    log("targets")
    for target, measured, met in goals:
        log(f"  {met:>12}: {target}: {measured}")
    log(f"done in {now() - start:.0f} s: {outdir}")
    return 1 if errors else 0


if __name__ == "__main__":
    sys.exit(main())
