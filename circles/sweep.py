"""Sweeps: many scenes, each run and measured as a task on Dask's distributed scheduler.

A sweep file (TOML) holds a base scene, the fields to vary and how to measure::

    [scene]                  # the base scene: Scene's fields (box or area_fraction)
    n = 400
    radius = 0.05
    mass = "equal"
    boundary = "periodic"
    seed = 1

    [vary]                   # lists of values; every combination is a point
    area_fraction = [0.1, 0.3, 0.5]

    [sweep]                  # how each point is measured (defaults in SWEEP_DEFAULTS)
    repeats = 2              # runs per point, each with its own seed
    equilibrate = 2.0        # simulated time before measuring
    measure = 10.0           # simulated time measured, in `blocks` equal blocks
    blocks = 10
    observables = ["compressibility", "collision_rate", "energy_change"]

Each (point, repeat) is a task. Repeat r runs with the seed `repeat_seed(base seed, r)`,
the same at every point, so that the numbers of a point depend on nothing but the file.
Every observable is measured over each block (`circles.observables.interval`), and a
point's value is the mean over all blocks of all its repeats, with its standard error (the
spread of those block values over the square root of their count).

`run_sweep` streams a row per point into ``DIR/results.csv`` as the point's last task ends,
and a row per task into ``DIR/runs.csv``; it skips the points the file holds already (with as
many repeats: a point of fewer runs only the others), keeps each finished task of a point
not yet done in ``DIR/tasks/`` for a rerun to take, and draws a plot per observable
(`plot_sweep`).
Tasks are independent and their results are put together in repeat order, so the numbers
are the same whatever the number of workers or the order in which tasks finish.
"""
from __future__ import annotations

import csv
import hashlib
import itertools
import json
import math
import os
import shutil
import sys
import threading
import time
import uuid
from dataclasses import dataclass, field, fields
from numbers import Integral, Real
from pathlib import Path

from .command import (EXIT_BAD_INPUT, EXIT_FAILED, EXIT_INTERRUPTED, SWEEP_TABLES, Parser, UsageError,
                      make_folder, sweep_or_scene)

#: The observables a sweep may keep. Each is measured per block; energy_change is the change
#: of the kinetic energy over a block relative to the energy at the start of the run; reduced_pressure
#: (beta P d^2) needs equal radii; hexatic_order (|psi_6|, `circles.order`) is taken at each block's end.
OBSERVABLES = ("compressibility", "collision_rate", "energy_change", "pressure", "wall_pressure", "temperature",
               "reduced_pressure", "hexatic_order")
DEFAULT_OBSERVABLES = ("compressibility", "collision_rate", "energy_change")

#: The [sweep] table's keys and their defaults.
SWEEP_DEFAULTS = {"repeats": 1, "equilibrate": 1.0, "measure": 10.0, "blocks": 10,
                  "observables": list(DEFAULT_OBSERVABLES)}
#: Limits: repeats and blocks at most; tasks (points times repeats) at most; durations at most.
MOST_REPEATS = 1000
MOST_BLOCKS = 10_000
MOST_TASKS = 100_000
MOST_DURATION = 1e12
#: The top-level tables of a sweep file.
TABLES = SWEEP_TABLES
#: The names of the results file in the output folder (a row a point), of the file of a row a
#: task, and of the file that fixes the sweep they belong to (a rerun with another base scene or
#: [sweep] table, but for its repeats, is refused).
RESULTS = "results.csv"
RUNS = "runs.csv"
IDENTITY = "sweep.json"
#: The folder of the tasks' checkpoints, in the output folder, with [sweep] checkpoint_every.
CHECKPOINTS = "checkpoints"
#: The folder of the results of finished tasks whose point has no row yet, in the output folder.
TASKS = "tasks"


class SweepError(ValueError):
    """A sweep file or option that is refused: one line that names the key."""


# ---- the sweep file -----------------------------------------------------------------------

@dataclass(frozen=True)
class Sweep:
    """A checked sweep: the base scene's fields, the varied fields with their values, and the
    measurement. `points` lists each point's values of the varied fields, in the order of
    `itertools.product` over the [vary] table."""

    scene: dict
    vary: dict
    repeats: int
    equilibrate: float
    measure: float
    blocks: int
    observables: tuple
    points: list = field(default_factory=list)
    source: str = ""
    checkpoint_every: float | None = None

    @property
    def varied(self):
        return tuple(self.vary)

    def point_scene(self, index, repeat):
        """The Scene fields of a point's repeat (its values over the base, its repeat's seed)."""
        return scene_fields(self.scene, self.points[index], repeat_seed(self.scene.get("seed", 0), repeat))

    def identity(self) -> dict:
        """What fixes the meaning of a row: the base scene, the names of the varied fields and
        the measurement (not the values varied, nor the repeats: a sweep may be extended, and
        given more repeats)."""
        identity = {"scene": self.scene, "varied": list(self.varied),
                    "equilibrate": self.equilibrate, "measure": self.measure, "blocks": self.blocks,
                    "observables": list(self.observables)}
        if self.checkpoint_every is not None:  # it cuts the equilibration into pieces: other bits
            identity["checkpoint_every"] = self.checkpoint_every
        return identity


def repeat_seed(base_seed, repeat):
    """The seed of repeat `repeat`: drawn from numpy's SeedSequence of (base seed, repeat), so
    that repeats are independent streams and repeat 0 is not the base seed's own stream."""
    import numpy as np

    return int(np.random.SeedSequence([int(base_seed), int(repeat)]).generate_state(1, dtype=np.uint32)[0])


def scene_fields(base, values, seed):
    """The base scene's fields with a point's values put in: a box given takes the place of the
    base's area_fraction, and an area_fraction that of its box."""
    merged = dict(base)
    if "box" in values:
        merged.pop("area_fraction", None)
    if "area_fraction" in values:
        merged.pop("box", None)
    merged.update(values)
    merged["seed"] = seed
    return merged


def read_sweep(path) -> Sweep:
    """Read and check a sweep file; a SweepError of one line naming the file and the key when
    anything is refused (every point's scene is made, so a value Scene refuses is caught here,
    before any task)."""
    from .scene import read_toml

    try:
        data = read_toml(path, "sweep file")
    except ValueError as error:
        raise SweepError(str(error)) from None
    try:
        return sweep_from_dict(data, source=str(path))
    except ValueError as error:
        message = str(error)
        raise SweepError(f"{path} {message}" if message.startswith("is a scene file") else f"{path}: {message}") from None


def _table(data, name, required):
    if name not in data:
        if required:
            raise ValueError(f"[{name}] is missing: {_HINTS[name]}")
        return {}
    table = data[name]
    if not isinstance(table, dict):
        raise ValueError(f"{name} = {table!r} must be a table [{name}]: {_HINTS[name]}")
    return table


_HINTS = {
    "scene": "give the base scene's fields in a [scene] table (n, radius, box or area_fraction, ...)",
    "vary": "give the fields to vary as lists in a [vary] table, e.g. area_fraction = [0.1, 0.3]",
    "sweep": "give repeats, equilibrate, measure, blocks and observables in a [sweep] table",
}


def _whole(key, value, least, most):
    if isinstance(value, bool) or not isinstance(value, Integral) or not least <= value <= most:
        raise ValueError(f"[sweep] {key} = {value!r} must be a whole number from {least} to {most}")
    return int(value)


def _duration(key, value, least_exclusive):
    if isinstance(value, bool) or not isinstance(value, Real) or not math.isfinite(value):
        raise ValueError(f"[sweep] {key} = {value!r} must be a finite number of simulated seconds")
    if (value <= 0 if least_exclusive else value < 0) or value > MOST_DURATION:
        bound = "> 0" if least_exclusive else ">= 0"
        raise ValueError(f"[sweep] {key} = {value!r} is out of range: give simulated seconds {bound} and at most "
                         f"{MOST_DURATION:g}")
    return float(value)


def sweep_from_dict(data: dict, source="") -> Sweep:
    """Check the contents of a sweep file (see the module's docstring) and return the Sweep."""
    from .scene import Scene, check_area_fraction_value, check_box

    unknown = sorted(set(data) - set(TABLES))
    if unknown and sweep_or_scene(data) == "scene" and "scene" not in data:
        raise ValueError("is a scene file (Scene fields at top level), not a sweep file: run it with circles run, "
                         f"or give a sweep file with the tables {', '.join(f'[{t}]' for t in TABLES)}")
    if unknown:
        raise ValueError(f"unknown key(s) {', '.join(unknown)}: a sweep file has the tables "
                         f"{', '.join(f'[{t}]' for t in TABLES)}")
    scene = dict(_table(data, "scene", True))
    vary = _table(data, "vary", True)
    settings = _table(data, "sweep", False)
    if "circle" in scene:
        raise ValueError("[scene] lists its circles ([[scene.circle]]): a sweep varies random scenes; give n, "
                         "radius and the other Scene fields instead")
    known = [f.name for f in fields(Scene)]
    unknown = sorted(set(scene) - set(known))
    if unknown:
        raise ValueError(f"[scene] unknown key(s) {', '.join(unknown)}: known keys are {', '.join(known)}")
    if "box" in scene and "area_fraction" in scene:
        raise ValueError("[scene] box and area_fraction are both given: give one of them")
    if not vary:
        raise ValueError(f"[vary] is empty: {_HINTS['vary']}")
    for key, values in vary.items():
        if key == "seed":
            raise ValueError("[vary] seed cannot be varied: each repeat has its own seed; set [sweep] repeats")
        if key not in known:
            raise ValueError(f"[vary] unknown key {key}: vary one of the Scene fields "
                             f"{', '.join(k for k in known if k != 'seed')}")
        if not isinstance(values, list) or not values:
            raise ValueError(f"[vary] {key} = {values!r} must be a non-empty list of values, e.g. {key} = [a, b]")
        keys = [json.dumps(v, sort_keys=True) for v in values]
        if len(set(keys)) < len(keys):
            twice = next(v for v, k in zip(values, keys) if keys.count(k) > 1)
            raise ValueError(f"[vary] {key} lists {twice!r} twice: give each value once")
    if "box" in vary and "area_fraction" in vary:
        raise ValueError("[vary] box and area_fraction are both varied: vary one of them")
    # A base box (area fraction) that a varied area fraction (box) replaces is still checked: a
    # malformed value is a mistake in the file, whether or not a point uses it.
    try:
        if "box" in scene and "area_fraction" in vary:
            check_box(scene["box"])
        if "area_fraction" in scene and "box" in vary:
            check_area_fraction_value(scene["area_fraction"])
    except (ValueError, TypeError) as error:
        raise ValueError(f"[scene] {error}") from None
    unknown = sorted(set(settings) - set(SWEEP_DEFAULTS) - {"checkpoint_every"})
    if unknown:
        raise ValueError(f"[sweep] unknown key(s) {', '.join(unknown)}: known keys are {', '.join(SWEEP_DEFAULTS)}, "
                         "checkpoint_every")
    every = settings.get("checkpoint_every")
    if every is not None:
        every = _duration("checkpoint_every", every, True)
    s = {**SWEEP_DEFAULTS, **settings}
    repeats = _whole("repeats", s["repeats"], 1, MOST_REPEATS)
    blocks = _whole("blocks", s["blocks"], 1, MOST_BLOCKS)
    equilibrate = _duration("equilibrate", s["equilibrate"], False)
    measure = _duration("measure", s["measure"], True)
    observables = s["observables"]
    if not isinstance(observables, list) or not observables or not all(isinstance(o, str) for o in observables):
        raise ValueError(f"[sweep] observables = {observables!r} must be a non-empty list of names from "
                         f"{', '.join(OBSERVABLES)}")
    for name in observables:
        if name not in OBSERVABLES:
            raise ValueError(f"[sweep] observables: {name!r} is unknown: use names from {', '.join(OBSERVABLES)}")
    if len(set(observables)) < len(observables):
        raise ValueError(f"[sweep] observables = {observables!r} names one twice: give each once")
    count = math.prod(len(v) for v in vary.values())
    if count * repeats > MOST_TASKS:
        raise ValueError(f"[vary] and [sweep] repeats make {count} points x {repeats} repeats = {count * repeats} "
                         f"tasks, more than {MOST_TASKS}: split the sweep")
    points = [dict(zip(vary, combo)) for combo in itertools.product(*vary.values())]
    sweep = Sweep(scene=scene, vary=dict(vary), repeats=repeats, equilibrate=equilibrate, measure=measure,
                  blocks=blocks, observables=tuple(observables), points=points, source=source,
                  checkpoint_every=every)
    base_seed = scene.get("seed", 0)
    from .scene import check_count
    check_count("[scene] seed", base_seed)
    for index, values in enumerate(points):
        try:
            made = Scene.from_dict(sweep.point_scene(index, 0))
        except (ValueError, TypeError) as error:
            where = ", ".join(f"{k} = {json.dumps(v)}" for k, v in values.items())
            raise ValueError(f"the point {where}: {error}") from None
        if "wall_pressure" in observables and made.boundary == "periodic":
            raise ValueError("[sweep] observables: wall_pressure needs walls, and the point's boundary is "
                             "periodic: drop wall_pressure or use boundary = \"walls\"")
        if "reduced_pressure" in observables and made.radius[0] != made.radius[1]:
            raise ValueError("[sweep] observables: reduced_pressure (beta P d^2) needs equal disks, and the point's "
                             f"radii range from {made.radius[0]:g} to {made.radius[1]:g}: drop it or give one radius")
        steps = (equilibrate + measure) / _step_of(made)
        if steps > 1e10:
            raise ValueError(f"[sweep] equilibrate + measure = {equilibrate + measure:g} s is {steps:.3g} steps of "
                             "the point's scene, more than 1e10: shorten them or give [scene] a longer dt")
    return sweep


def _step_of(scene):
    """The scene's step: its dt, or the step the simulation would choose (a bound from below
    is enough here: the radii over the largest speed, as the default dt is made)."""
    if scene.dt is not None:
        return scene.dt
    vmax = scene.speed[1]
    return scene.radius[0] / vmax if vmax > 0 else math.inf


# ---- one task -----------------------------------------------------------------------------

_runtime_lock = threading.Lock()


def _ensure_runtime(threads):
    """Start Taichi on the CPU in this process once, with `threads` threads (None: the Dask
    worker's own thread count, or every core outside a worker). A process that already
    started it (the serial run in the caller's process) keeps its runtime."""
    from . import backend

    if backend._state["initialized"]:
        return
    if threads is None:
        try:
            from distributed import get_worker
            threads = get_worker().state.nthreads
        except (ImportError, ValueError):
            threads = os.cpu_count() or 1
    backend.init("cpu", cpu_max_num_threads=max(1, int(threads)))


def pieces(equilibrate, measure, blocks, every=None):
    """The simulated times a task advances to, in order, each with the block it ends (None for
    the equilibration). With `every`, the equilibration goes in pieces of that length, so that
    a checkpoint can fall within it; the pieces depend on nothing else, so a task resumed from
    a checkpoint takes the steps of one never stopped."""
    ends = []
    if every is not None:
        j = 1
        while j * every < equilibrate:
            ends.append((j * every, None))
            j += 1
    if equilibrate > 0:
        ends.append((equilibrate, None))
    return ends + [(equilibrate + measure * (k + 1) / blocks, k) for k in range(blocks)]


def run_task(scene_fields_, equilibrate, measure, blocks, threads=None, kept=(), checkpoint=None, every=None):
    """Run one (point, repeat): equilibrate, then measure every observable over each of
    `blocks` equal blocks of `measure` simulated seconds (hexatic_order, at each block's end,
    only when `kept` names it). Returns {"blocks": {observable: [values]}, "pair_collisions",
    "seconds", "pid", "resumed_at"}. Tasks in one process take turns (the Taichi runtime is
    the process's).

    With `checkpoint` (a path) and `every` (simulated seconds), the task keeps a restart point
    there (`circles.checkpoint`) at the end of the first piece (`pieces`) `every` or more after
    the last, and goes on from one it finds of the same task: a task run again after its
    worker died does only the rest, with the same result. ``resumed_at`` is the simulated time
    it went on from (0.0 from the start); the file is removed when the task ends."""
    from . import checkpoint as restart
    from .observables import interval
    from .order import hexatic_order, psi6
    from .scene import Scene
    from .trajectory import read_simulation

    task = {"scene": scene_fields_, "equilibrate": equilibrate, "measure": measure, "blocks": blocks,
            "every": every, "kept": list(kept)}
    task = json.loads(json.dumps(task))
    with _runtime_lock:
        _ensure_runtime(threads)
        from .simulation import Simulation

        started = time.perf_counter()
        scene = Scene.from_dict(scene_fields_)
        schedule = pieces(equilibrate, measure, blocks, every)
        progress = _task_progress(checkpoint, task)
        if progress is None:
            sim = Simulation(scene)
            energy_0 = sim.stats()["kinetic_energy"]
            values = {name: [] for name in OBSERVABLES}
            done, start_pairs = 0, None
        else:
            sim = read_simulation(checkpoint, 0, track_images=False)
            energy_0, values = progress["energy_0"], progress["values"]
            done, start_pairs = progress["piece"], progress["start_pairs"]
        resumed_at = sim.time
        last = sim.time
        before = sim.stats()
        if start_pairs is None and schedule[done][1] is not None:  # no equilibration left: measuring starts now
            start_pairs = before["pair_collisions"]
        radius = 0.5 * (scene.radius[0] + scene.radius[1])
        for index in range(done, len(schedule)):
            target, block = schedule[index]
            sim.advance(target - sim.time)
            if block is None:
                if index + 1 < len(schedule) and schedule[index + 1][1] is not None:  # the equilibration's end
                    before = sim.stats()
                    start_pairs = before["pair_collisions"]
            else:
                after = sim.stats()
                row = interval(before, after, scene.n, scene.box, scene.boundary, radius,
                               2.0 * scene.radius[0] if scene.radius[0] == scene.radius[1] else None)
                for name in ("compressibility", "collision_rate", "pressure", "wall_pressure", "temperature",
                             "reduced_pressure"):
                    values[name].append(row[name])
                if "hexatic_order" in kept:  # measured only when asked for: a pass over the neighbours
                    values["hexatic_order"].append(hexatic_order(psi6(sim.state().pos, sim.box, sim.periodic)))
                values["energy_change"].append((after["kinetic_energy"] - before["kinetic_energy"]) / energy_0
                                               if energy_0 > 0 else 0.0)
                before = after
            if checkpoint is not None and every is not None and index + 1 < len(schedule) \
                    and sim.time - last >= every:
                restart.write(checkpoint, sim, {"task": task, "piece": index + 1, "energy_0": energy_0,
                                                "values": values, "start_pairs": start_pairs})
                last = sim.time
        if checkpoint is not None:
            try:
                os.unlink(checkpoint)
            except FileNotFoundError:
                pass
        return {"blocks": values, "pair_collisions": before["pair_collisions"] - start_pairs,
                "seconds": time.perf_counter() - started, "pid": os.getpid(), "resumed_at": resumed_at}


def _task_progress(path, task):
    """The progress a checkpoint at `path` holds of the task `task`, or None: no file, a file
    gsd cannot read, or one of another task (left by a sweep that was changed)."""
    from .trajectory import run_of

    if path is None or not os.path.exists(path):
        return None
    try:
        progress = run_of(path)
    except (RuntimeError, OSError, ValueError):
        return None
    if not progress or progress.get("task") != task:
        return None
    return progress


def point_row(sweep, index, results, before=None):
    """A point's row of results.csv from its tasks' results, given in repeat order: for each
    kept observable its mean over all blocks of all repeats and the standard error. `before`:
    the point's row of its first repeats, when `results` are the repeats added to them."""
    import numpy as np

    row = {key: json.dumps(value) for key, value in sweep.points[index].items()}
    row["repeats"] = sweep.repeats
    row["blocks"] = sweep.blocks
    for name in _names(sweep):
        samples = np.concatenate([np.asarray(r["blocks"][name], dtype=np.float64) for r in results])
        mean = float(np.mean(samples))
        se = float(np.std(samples, ddof=1) / math.sqrt(samples.size)) if samples.size > 1 else math.nan
        if before is not None:
            mean, se = pooled([(int(before["repeats"]) * sweep.blocks, float(before[name]), float(before[f"{name}_se"])),
                               (samples.size, mean, se)])
        row[name] = repr(mean)
        row[f"{name}_se"] = repr(se)
    row["pair_collisions"] = sum(int(r["pair_collisions"]) for r in results) + int((before or {}).get(
        "pair_collisions", 0))
    row["task_seconds"] = f"{sum(r['seconds'] for r in results) + float((before or {}).get('task_seconds', 0)):.3f}"
    return row


def pooled(parts):
    """The mean and standard error of the samples of several parts in one, each part given as
    (count, mean, standard error): the parts' sums of squared deviations, added with Chan et
    al.'s term for the differences of their means, so that nothing but the three numbers of each
    part is needed (the same to round-off as from all the samples)."""
    count, mean, squares = 0, 0.0, 0.0
    for size, part_mean, se in parts:
        total = count + size
        delta = part_mean - mean
        squares += (se * se * size * (size - 1) if size > 1 else 0.0) + delta * delta * count * size / total
        mean += delta * size / total
        count = total
    return mean, (math.sqrt(squares / (count - 1) / count) if count > 1 else math.nan)


def columns(sweep):
    """The columns of results.csv: the varied fields, repeats and blocks, each observable and
    its standard error (the temperature always), the pair collisions measured, the tasks'
    seconds."""
    return [*sweep.varied, "repeats", "blocks", *[c for n in _names(sweep) for c in (n, f"{n}_se")], "pair_collisions",
            "task_seconds"]


def run_columns(sweep):
    """The columns of runs.csv: the varied fields, the repeat and its seed, each observable's
    mean over the task's blocks (the temperature always), its pair collisions and seconds."""
    return [*sweep.varied, "repeat", "seed", *_names(sweep), "pair_collisions", "task_seconds"]


def run_row(sweep, point, repeat, result):
    """A task's row of runs.csv."""
    import numpy as np

    row = {key: json.dumps(value) for key, value in sweep.points[point].items()}
    row["repeat"] = repeat
    row["seed"] = sweep.point_scene(point, repeat)["seed"]
    for name in _names(sweep):
        row[name] = repr(float(np.mean(np.asarray(result["blocks"][name], dtype=np.float64))))
    row["pair_collisions"] = int(result["pair_collisions"])
    row["task_seconds"] = f"{result['seconds']:.3f}"
    return row


def _names(sweep):
    return list(sweep.observables) + (["temperature"] if "temperature" not in sweep.observables else [])


# ---- results.csv and runs.csv ---------------------------------------------------------------

def _fingerprint(sweep):
    return hashlib.sha256(json.dumps(sweep.identity(), sort_keys=True).encode()).hexdigest()


def _point_key(values):
    return tuple(json.dumps(v, sort_keys=True) for v in values)


def read_results(out, sweep):
    """{point key: row} of the points DIR/results.csv holds (a last line cut short by a stop
    is dropped, and cut off the file). Refused when the folder holds another sweep's results."""
    results = os.path.join(out, RESULTS)
    identity = os.path.join(out, IDENTITY)
    if os.path.exists(identity):
        with open(identity) as file:
            try:
                held = json.load(file)
            except json.JSONDecodeError:
                held = None
        # A folder written when the repeats were part of a sweep's identity has them in its file.
        if not isinstance(held, dict) or {k: v for k, v in held.items() if k not in ("fingerprint", "repeats")} \
                != sweep.identity():
            raise SweepError(f"{out} holds the results of another sweep (its [scene], varied fields or [sweep] "
                             f"differ from {sweep.source or 'this one'}'s): give another --out, or remove {out}")
    elif os.path.exists(results):
        raise SweepError(f"{results} exists without {IDENTITY}: give another --out, or remove {results}")
    rows = {_point_key(json.loads(row[k]) for k in sweep.varied): row for row in _read_rows(results, columns(sweep))}
    most = max((int(row["repeats"]) for row in rows.values()), default=0)
    if most > sweep.repeats:
        raise SweepError(f"{results} holds points of {most} repeats, more than the {sweep.repeats} of "
                         f"{sweep.source or 'this sweep'}: set repeats = {most} or more, or give another --out")
    return rows


def read_runs(out, sweep):
    """{(point key, repeat): row} of the tasks DIR/runs.csv holds (a last line cut short by a
    stop is dropped, and cut off the file)."""
    rows = _read_rows(os.path.join(out, RUNS), run_columns(sweep))
    return {(_point_key(json.loads(row[k]) for k in sweep.varied), int(row["repeat"])): row for row in rows}


def _read_rows(path, names):
    """The rows of the CSV file at `path` (none when it is missing), its last line dropped and
    cut off the file when a stop left it short; refused when its header is not `names`."""
    if not os.path.exists(path):
        return []
    with open(path, "rb+") as file:
        data = file.read()
        if data and not data.endswith(b"\n"):
            keep = data.rfind(b"\n") + 1
            file.truncate(keep)
            data = data[:keep]
    lines = data.decode().splitlines()
    if lines and next(csv.reader(lines[:1])) != names:
        raise SweepError(f"{path} has other columns than this sweep writes: give another --out, or remove it")
    return list(csv.DictReader(lines))


def _write_identity(out, sweep):
    os.makedirs(out, exist_ok=True)
    with open(os.path.join(out, IDENTITY), "w") as file:
        json.dump({"fingerprint": _fingerprint(sweep), **sweep.identity()}, file, indent=1)


class _CsvFile:
    """A CSV file of the sweep's folder (results.csv, runs.csv), a row appended and flushed to
    disk as it comes."""

    def __init__(self, path, names):
        self.path = path
        self.columns = names
        new = not os.path.exists(self.path) or os.path.getsize(self.path) == 0
        self._open()
        if new:
            self.writer.writeheader()
            self._sync()

    def write(self, row, replaces=None):
        """Append `row`; with `replaces` (the row it takes the place of), write the file anew
        with `row` in that one's place, whole (renamed into place once on disk)."""
        if replaces is None:
            self.writer.writerow(row)
            self._sync()
            return
        from .storage import replaced_whole

        self.file.close()
        with open(self.path, newline="") as file:
            rows = list(csv.DictReader(file))
        if replaces in rows:
            rows[rows.index(replaces)] = row
        else:  # the row it replaces is not there: the new one comes last
            rows.append(row)
        with replaced_whole(self.path) as part:
            with open(part, "w", newline="") as file:
                writer = csv.DictWriter(file, self.columns, lineterminator="\n")
                writer.writeheader()
                writer.writerows(rows)
                file.flush()
                os.fsync(file.fileno())
        self._open()

    def _open(self):
        """Open the file to append rows to."""
        self.file = open(self.path, "a", newline="")
        self.writer = csv.DictWriter(self.file, self.columns, lineterminator="\n")

    def _sync(self):
        self.file.flush()
        os.fsync(self.file.fileno())

    def close(self):
        self.file.close()


# ---- running ------------------------------------------------------------------------------

def task_path(out, sweep, point, repeat):
    """Where the result of task (point, repeat) waits for its point's other tasks: named by a
    hash of the task's scene (its values and seed), so that values added to [vary], which
    renumber the points, do not give a result to another task."""
    scene = json.dumps(sweep.point_scene(point, repeat), sort_keys=True)
    name = hashlib.sha256(scene.encode()).hexdigest()[:24]
    return os.path.join(out, TASKS, f"{name}.json")


def _task_record(sweep, point, repeat):
    return {"fingerprint": _fingerprint(sweep), "scene": json.loads(json.dumps(sweep.point_scene(point, repeat))),
            "point": sweep.points[point], "repeat": repeat}


def keep_task(out, sweep, point, repeat, result):
    """Write a finished task's result to `task_path`, whole (renamed into place once on disk)."""
    from .storage import replaced_whole

    path = task_path(out, sweep, point, repeat)
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with replaced_whole(path) as part:
        with open(part, "w") as file:
            json.dump({**_task_record(sweep, point, repeat), "result": result}, file)
            file.flush()
            os.fsync(file.fileno())
    return path


def kept_task(out, sweep, point, repeat):
    """The result `keep_task` kept of task (point, repeat), or None: no file, a file cut short or
    not JSON, or one of another sweep or task."""
    path = task_path(out, sweep, point, repeat)
    try:
        with open(path) as file:
            held = json.load(file)
    except (OSError, ValueError):
        return None
    if not isinstance(held, dict) or {k: held.get(k) for k in ("fingerprint", "scene", "point", "repeat")} \
            != _task_record(sweep, point, repeat) or not isinstance(held.get("result"), dict):
        return None
    return held["result"]


def drop_tasks(out, sweep, point):
    """Remove the kept results of a point's tasks (its row holds them)."""
    for repeat in range(sweep.repeats):
        Path(task_path(out, sweep, point, repeat)).unlink(missing_ok=True)


@dataclass
class SweepRun:
    """What a run of a sweep did: the points run and skipped (indices), the rows written, the
    tasks' results by (point, repeat), the wall time, and the tasks whose result an earlier
    run had kept (not run again)."""

    ran: list
    skipped: list
    rows: list
    results: dict
    wall_s: float
    kept: list = field(default_factory=list)


def run_sweep(sweep, out, client=None, threads=None, on_row=None, on_result=None):
    """Run the points of `sweep` that DIR/results.csv does not hold yet, a task per (point,
    repeat): on the Dask `client` (each task's key ends in -POINT-REPEAT) (distributed.Client) when given, else one by one in this
    process. Each task's own row is appended to DIR/runs.csv as it ends (`run_row`), once. A row
    is appended to DIR/results.csv when a point's last task ends; until then each
    finished task's result is kept in DIR/tasks/ (`keep_task`), so that a run stopped mid-point
    does not run it again. A point whose row has fewer repeats than the sweep runs the others,
    and its row is written anew with all of them. `on_row(row)` and `on_result((point, repeat), result)` are called as
    they come (first for the results kept). `threads`: Taichi's threads in each worker process
    (None: the worker's own thread count)."""
    started = time.perf_counter()
    done = read_results(out, sweep)
    before = {i: row for i, values in enumerate(sweep.points) if (row := done.get(_point_key(values.values())))}
    first = {i: int(row["repeats"]) for i, row in before.items()}  # a row of fewer repeats gets the others
    todo = [i for i in range(len(sweep.points)) if first.get(i, 0) < sweep.repeats]
    skipped = [i for i in range(len(sweep.points)) if i not in set(todo)]
    tasks = [(p, r) for p in todo for r in range(first.get(p, 0), sweep.repeats)]
    logged = set(read_runs(out, sweep))
    _write_identity(out, sweep)
    file = _CsvFile(os.path.join(out, RESULTS), columns(sweep))
    log = _CsvFile(os.path.join(out, RUNS), run_columns(sweep))
    results, rows = {}, []
    left = {p: sweep.repeats - first.get(p, 0) for p in todo}

    def finished(task, result, kept=False):
        """Keep the result (a task file, or the point's row when it is the last), then call back:
        a stop raised by a callback loses nothing that had ended."""
        results[task] = result
        point = task[0]
        if (key := (_point_key(sweep.points[point].values()), task[1])) not in logged:  # a task run again: once
            log.write(run_row(sweep, *task, result))
            logged.add(key)
        left[point] -= 1
        row = None
        if left[point] == 0:
            row = point_row(sweep, point, [results[(point, r)] for r in range(first.get(point, 0), sweep.repeats)],
                            before.get(point))
            file.write(row, replaces=before.get(point))
            rows.append(row)
            drop_tasks(out, sweep, point)  # results.csv holds them now
        elif not kept:
            keep_task(out, sweep, *task, result)
        if on_result is not None:
            on_result(task, result)
        if row is not None and on_row is not None:
            on_row(row)

    held = os.path.join(out, TASKS)
    kept = {}
    if os.path.isdir(held):
        kept = {task: result for task in tasks if (result := kept_task(out, sweep, *task)) is not None}
        for point in skipped:  # a stop between a row and the removal of its tasks' files
            drop_tasks(out, sweep, point)

    checkpoints = os.path.join(out, CHECKPOINTS) if sweep.checkpoint_every is not None else None
    if checkpoints is not None:
        os.makedirs(checkpoints, exist_ok=True)

    def args(task):
        where = None if checkpoints is None else os.path.join(checkpoints, f"point-{task[0]}-repeat-{task[1]}.gsd")
        return (sweep.point_scene(*task), sweep.equilibrate, sweep.measure, sweep.blocks, threads, sweep.observables,
                where, sweep.checkpoint_every)

    try:
        for task, result in kept.items():
            finished(task, result, kept=True)
        tasks = [task for task in tasks if task not in kept]
        if client is None:
            for task in tasks:
                finished(task, run_task(*args(task)))
        else:
            from distributed import as_completed

            # A key of this run's own: keys of a stopped run may still be held, cancelled, by the scheduler.
            tag = f"{_fingerprint(sweep)[:12]}-{uuid.uuid4().hex[:8]}"
            futures = {client.submit(run_task, *args(task), key=f"circles-sweep-{tag}-{task[0]}-{task[1]}",
                                     pure=False): task for task in tasks}
            try:
                for future in as_completed(futures):
                    finished(futures[future], future.result())
            finally:
                for future in futures:
                    future.cancel()
    finally:
        file.close()
        log.close()
    if checkpoints is not None and not any(p.endswith(".gsd") for p in os.listdir(checkpoints)):
        shutil.rmtree(checkpoints, ignore_errors=True)  # every task ended: what is left are temporary names
    if os.path.isdir(held) and not any(p.endswith(".json") for p in os.listdir(held)):
        shutil.rmtree(held, ignore_errors=True)  # every point has its row
    return SweepRun(ran=todo, skipped=skipped, rows=rows, results=results, wall_s=time.perf_counter() - started,
                    kept=list(kept))


def local_cluster(workers, threads_per_worker=1):
    """A Dask LocalCluster of `workers` worker processes on this machine, quiet, its dashboard on
    a free port (two sweeps at once do not meet on one)."""
    import logging

    from distributed import LocalCluster

    return LocalCluster(n_workers=workers, threads_per_worker=threads_per_worker, processes=True,
                        dashboard_address=":0", silence_logs=logging.ERROR)


# ---- plots --------------------------------------------------------------------------------

LABELS = {"compressibility": "compressibility Z = PA / NkT", "collision_rate": "collisions per circle per unit time",
          "energy_change": "relative energy change per block", "pressure": "pressure (virial)",
          "wall_pressure": "pressure on the walls", "temperature": "kT",
          "reduced_pressure": "reduced pressure beta P d^2", "hexatic_order": "hexatic order |psi_6|"}


def load_rows(out, sweep):
    """The rows of DIR/results.csv for the points of `sweep`, in the sweep's point order."""
    held = read_results(out, sweep)
    rows = []
    for values in sweep.points:
        row = held.get(_point_key(values.values()))
        if row is not None:
            rows.append((values, row))
    return rows


def theory(sweep, values, row):
    """{observable: value} of hard-disk theory at a point, for points of equal disks in a
    periodic box with a known area fraction: Liu's Z and Enskog's collision rate; and the
    published reduced pressure (`circles.reference`) where a series of the same N and box shape
    has this area fraction. Empty else."""
    from .reference import series
    from .scene import Scene
    from .theory import enskog_rate, liu_z

    scene = Scene.from_dict(scene_fields(sweep.scene, values, 0))
    r0, r1 = scene.radius
    if r0 != r1 or scene.boundary != "periodic" or "area_fraction" not in sweep.vary:
        return {}
    eta, r = scene.area_fraction, r0
    mass = {"equal": 1.0, "radius": r, "area": math.pi * r * r}[scene.mass]
    kT = float(row["temperature"])
    rho = scene.n / (scene.box[0] * scene.box[1])
    found = {"compressibility": liu_z(eta), "collision_rate": enskog_rate(eta, rho, 2 * r, kT, mass)}
    published = [p for p in series(scene.n, scene.box[0] / scene.box[1]) if math.isclose(p.eta, eta, abs_tol=1e-9)]
    if published:
        found["reduced_pressure"] = published[0].beta_p_d2
        found["reduced_pressure_se"] = published[0].se
    return found


def deviations(sweep, rows, name="compressibility"):
    """[(area fraction, measured, theory, relative deviation, deviation in standard errors)]
    of an observable against theory (`theory`), point by point."""
    out = []
    for values, row in rows:
        expect = theory(sweep, values, row).get(name)
        if expect is None or name not in row:
            continue
        got, se = float(row[name]), float(row[f"{name}_se"])
        out.append((float(values["area_fraction"]), got, expect, got / expect - 1.0,
                    (got - expect) / se if se > 0 else math.nan))
    return out


def plot_sweep(sweep, out):
    """A PNG per kept observable against the first varied field (a line per combination of the
    others), with error bars of one standard error, and Liu's Z and Enskog's collision rate
    beside them when the sweep varies the area fraction of equal disks in a periodic box.
    Returns the paths written; raises ImportError without matplotlib."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = load_rows(out, sweep)
    paths = []
    for name in sweep.observables:
        fig = sweep_figure(sweep, rows, name)
        fig.tight_layout()
        path = os.path.join(out, f"{name}.png")
        fig.savefig(path)
        plt.close(fig)
        paths.append(path)
    return paths


def sweep_figure(sweep, rows, name):
    """The figure of one observable (`plot_sweep`) of the rows (`load_rows`)."""
    import matplotlib.pyplot as plt

    x_key, others = sweep.varied[0], sweep.varied[1:]
    fig, ax = plt.subplots(figsize=(6.4, 4.2), dpi=100)
    groups = {}
    for values, row in rows:
        groups.setdefault(tuple(json.dumps(values[k]) for k in others), []).append((values, row))
    for group, members in groups.items():
        x = [_number_of(v[x_key]) for v, _ in members]
        y = [float(r[name]) for _, r in members]
        e = [float(r[f"{name}_se"]) for _, r in members]
        label = ", ".join(f"{k} {g}" for k, g in zip(others, group)) or "measured"
        ax.errorbar(x, y, yerr=e, fmt="o", ms=4, capsize=2, label=label)
        values, row = members[0]
        if name == "reduced_pressure":  # the published series, once, in place of a curve of theory
            if x_key == "area_fraction" and group == next(iter(groups)):
                _plot_published(ax, sweep, values)
        elif theory(sweep, values, row).get(name) is not None and x_key == "area_fraction" and len(x) > 1:
            # A smooth curve through the points' range, at the first point's temperature.
            grid = [min(x) + (max(x) - min(x)) * k / 200 for k in range(201)]
            curve = [theory(sweep, {**values, x_key: g}, row)[name] for g in grid]
            theory_name = {"compressibility": "Liu", "collision_rate": "Enskog (Liu's g)"}[name]
            ax.plot(grid, curve, "-", color="0.3", lw=1, label=theory_name)
    ax.set_xlabel(x_key)
    ax.set_ylabel(LABELS[name])
    if name == "compressibility" and x_key == "area_fraction":
        ax.set_yscale("log")
    ax.set_title(os.path.basename(sweep.source) or "sweep", fontsize=10)
    ax.legend(fontsize=8)
    return fig


def _plot_published(ax, sweep, values):
    """The published reduced pressures of the sweep's N and box shape (`circles.reference`): a
    line per source and method (solid, dashed, dotted), each by area fraction."""
    from .reference import series
    from .scene import Scene

    scene = Scene.from_dict(scene_fields(sweep.scene, values, 0))
    found = sorted(series(scene.n, scene.box[0] / scene.box[1]), key=lambda p: (p.source, p.method, p.eta))
    groups = itertools.groupby(found, key=lambda p: (p.source, p.method))
    for ((source, method), points), style in zip(groups, itertools.cycle(("-", "--", ":"))):
        points = list(points)
        ax.errorbar([p.eta for p in points], [p.beta_p_d2 for p in points], yerr=[p.se for p in points],
                    color="0.3", lw=1, ls=style, label=f"{source} ({method}), N = {scene.n}")


def _number_of(value):
    """Where a point goes on the x axis: a number as it is, a range ([low, high]) at its low end,
    anything else (a start, a list of species) as a category named by its text."""
    if isinstance(value, list) and value and isinstance(value[0], (int, float)):
        value = value[0]
    return value if isinstance(value, (int, float)) else str(value)


# ---- the command line ---------------------------------------------------------------------

DESCRIPTION = ("Run every point of a sweep file (a base scene and the fields to vary) as tasks on Dask, a row per "
               "point in DIR/results.csv and a plot per observable. Points already in DIR/results.csv are skipped.")


def add_sweep_command(commands):
    """The `circles sweep` subcommand, on the command line's subparsers."""
    # Listed in `circles --help` only: `circles sweep ...` goes to `main`, whose parser is its own.
    _sweep_arguments(commands.add_parser("sweep", help="run many scenes on Dask and measure each"))


def _sweep_arguments(sweep):
    sweep.add_argument("sweep", metavar="SWEEP.toml", help="sweep file: [scene], [vary] and [sweep] tables")
    where = sweep.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, metavar="N",
                       help="worker processes of the local cluster (default: one per core; 0 runs the tasks "
                            "one by one in this process, without Dask)")
    where.add_argument("--scheduler", metavar="ADDRESS",
                       help="the address of a running Dask scheduler (tcp://host:8786) to use instead")
    sweep.add_argument("--out", metavar="DIR", help="folder for results.csv and the plots (default "
                                                    "outputs/SWEEP, after the file's name)")


def worker_threads(cores, workers):
    """Taichi's threads in each of `workers` worker processes on `cores` cores: the cores shared
    out, at least one each."""
    return max(1, cores // workers)


def cluster_words(workers, threads):
    """How the command names a local cluster: "a local cluster of 2 worker processes, 1 thread each"."""
    return (f"a local cluster of {workers} worker process{'es' if workers > 1 else ''}, "
            f"{threads} thread{'s' if threads > 1 else ''} each")


def main(argv):
    """`circles sweep ...` (argv from "sweep" on): the exit status (0 done, 2 bad input, 1 failed,
    130 Ctrl-C)."""
    parser = Parser(prog="circles sweep", description=DESCRIPTION)
    _sweep_arguments(parser)
    try:
        args = parser.parse_args(argv[1:])
        sweep = read_sweep(args.sweep)
        if args.workers is not None and not 0 <= args.workers <= 4096:
            raise SweepError(f"--workers {args.workers} must be from 0 (no Dask: this process) to 4096")
        out = args.out or os.path.join("outputs", os.path.splitext(os.path.basename(args.sweep))[0])
        if os.path.exists(out) and not os.path.isdir(out):
            raise SweepError(f"--out {out} is a file: give a folder")
        read_results(out, sweep)  # another sweep's results are refused before any task
        if args.workers != 0:
            try:
                import distributed  # noqa: F401
            except ImportError:
                raise SweepError("circles sweep runs its tasks on Dask, which is not installed: pip install "
                                 "'circles-sim[sweep]', or give --workers 0 to run them one by one here") from None
        make_folder(out, f"--out {out}")  # before any cluster starts
    except (UsageError, SweepError) as error:
        print(f"circles: error: {error}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except SystemExit as exit_:  # --help
        return exit_.code if isinstance(exit_.code, int) else 0
    cluster = client = None
    try:
        total = len(sweep.points)
        cores = os.cpu_count() or 1
        threads = None
        if args.scheduler:
            from distributed import Client
            client = Client(args.scheduler, timeout="30s")
            where = f"the Dask scheduler at {args.scheduler}"
        elif args.workers == 0:
            where = "this process, task by task"
        else:
            workers = args.workers or cores
            threads = worker_threads(cores, workers)
            cluster = local_cluster(workers)
            from distributed import Client
            client = Client(cluster)
            where = cluster_words(workers, threads)
        print(f"sweep       {total} points x {sweep.repeats} repeats on {where}", flush=True)
        from .kernel_cache import announce
        from .scene import Scene
        announce(Scene.from_dict(sweep.point_scene(0, 0)), "cpu", threads or 0)
        def on_row(row):
            shown = ", ".join(f"{k} {row[k]}" for k in sweep.varied)
            print(f"point       {shown}: " + ", ".join(f"{n} {float(row[n]):.4g} +- {float(row[n + '_se']):.2g}"
                                                     for n in sweep.observables), flush=True)

        run = run_sweep(sweep, out, client=client, threads=threads, on_row=on_row)
        resumed = sum(1 for result in run.results.values() if result.get("resumed_at", 0.0) > 0)
        tasks = len(run.results) - len(run.kept)  # run now, not taken from DIR/tasks/
        print(f"done        {len(run.ran)} points run ({tasks} tasks), {len(run.skipped)} already in "
              f"{os.path.join(out, RESULTS)}, "
              f"{run.wall_s:.1f} s" + (f"; tasks that went on from a checkpoint: {resumed}" if resumed else "")
              + (f"; tasks done by an earlier run: {len(run.kept)}" if run.kept else ""), flush=True)
        try:
            paths = plot_sweep(sweep, out)
            print(f"plots       {', '.join(paths)}")
        except ImportError:
            print("plots       skipped: matplotlib is not installed (pip install 'circles-sim[plot]')")
        rows = load_rows(out, sweep)
        worst = max(deviations(sweep, rows), key=lambda d: abs(d[3]), default=None)
        if worst is not None:
            print(f"liu         largest deviation of Z from Liu's: {100 * worst[3]:+.2f}% ({worst[4]:+.1f} standard "
                  f"errors) at area fraction {worst[0]:g}")
        worst = max(deviations(sweep, rows, "reduced_pressure"), key=lambda d: abs(d[4]), default=None)
        if worst is not None:
            print(f"published   largest deviation of beta P d^2 from the published one at this N: {worst[1] - worst[2]:+.4f} "
                  f"({worst[4]:+.1f} standard errors) at area fraction {worst[0]:g}")
        return 0
    except KeyboardInterrupt:
        print("circles: stopped by Ctrl-C; the points done are in results.csv, and a rerun runs the others "
              "(the tasks done of those are kept)",
              file=sys.stderr)
        return EXIT_INTERRUPTED
    except Exception as error:  # a task's error, a worker lost too often (KilledWorker), a lost scheduler
        results = os.path.join(out, RESULTS)
        try:
            where = f"the points done are in {results}" if read_results(out, sweep) else "no point was done"
        except (SweepError, OSError) as unreadable:  # the folder changed under the run
            where = f"the points done cannot be told: {unreadable}"
        print(f"circles: the sweep failed: {type(error).__name__}: {error}; {where}", file=sys.stderr)
        return EXIT_FAILED
    finally:
        if client is not None:
            client.close()
        if cluster is not None:
            cluster.close()
