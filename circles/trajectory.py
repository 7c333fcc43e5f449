"""Trajectories in HOOMD-blue's GSD schema: write a simulation's frames, read one back.

`GSDWriter(path).write(sim, row)` appends the state of a `Simulation` to a GSD file as a frame
of HOOMD's schema (written with the `gsd` package, so gsd, freud and OVITO read it as they read
HOOMD's own files); `read_simulation(path, frame)` makes a `Simulation` of a frame again.

A frame holds, per circle in creation order (N circles):

==============================  =========  ===================================================
chunk                           type       what
==============================  =========  ===================================================
configuration/box               f32 (6,)   [W, H, 0, 0, 0, 0]
configuration/dimensions        u8         2
configuration/step              u64        steps taken since the start
particles/N                     u32        N
particles/position              f32 (N,3)  box-centred: (x - W/2, y - H/2, 0)
particles/velocity              f32 (N,3)  (vx, vy, 0)
particles/image                 i32 (N,3)  periodic box: wraps across each side (see below)
particles/diameter, mass        f32 (N,)   2 r, m
particles/typeid, types         u32, str   one type per distinct radius ("A", "B", ...)
log/circles/<column>            f64 (1,)   the stats row (`observables.COLUMNS`) of the frame
log/circles/box                 f64 (2,)   [W, H] in full precision
log/circles/dt, precision_bits  f64, u8    the step length; 32 or 64
log/circles/boundary, scheme    u8 text    "walls" or "periodic"; "event" or "discrete"
log/particles/circles/position  f32 / f64  (N, 2) as the simulation holds them, x in [0, W]
log/particles/circles/velocity  f32 / f64  (N, 2) as held
log/circles/totals              f64 (4,)   pair and wall collisions, virial, wall impulse
log/particles/circles/<sum>     i32 / f64  (N,) each circle's share of the totals: pair_count,
                                           virial and, with walls, wall_count, wall_impulse
log/particles/circles/radius    f64 (N,)   (first frame only: the same in every frame)
log/particles/circles/mass      f64 (N,)   (first frame only)
log/particles/circles/color     u8 (N,3)   (first frame only)
log/circles/run                 u8 text    what made the run, as JSON (first frame only; the
                                           command line's, checked by ``circles run --resume``)
==============================  =========  ===================================================

HOOMD's schema stores positions in float32; the `log/particles/circles/` chunks keep them in
the working precision (float64 for an f64 scene), so that `read_simulation` restarts a run
bit for bit: the same positions, velocities, radii, masses, time, step and dt, and the
per-circle sums that the stats totals add up, so that the totals go on as they would have.
Every frame is so a restart point (`circles.checkpoint`).

Image flags. In a periodic box a circle that leaves through one side comes back through the
other, and the image flag counts those crossings: the unwrapped position is
``position + image * (W, H)``. `ImageTracker` counts them exactly, after every step: a wrap is a
jump of more than half the box between two steps, and no circle moves that far in one step
(an event step moves a circle at most a quarter of the box's shorter side; a discrete step a
fraction of a radius). It keeps the previous positions and the counts in creation order, so
the simulation's reordering of its arrays does not matter, and it only reads the positions,
so a run with a trajectory is the same, bit for bit, as one without.
"""

import json
from pathlib import Path

import numpy as np
import taichi as ti

from . import observables
from .command import make_folder
from .writers import row_of

#: The per-circle sums behind the stats totals, in the order of log/circles/totals, and their types.
SHARES = {"pair_count": np.int32, "wall_count": np.int32, "virial": np.float64, "wall_impulse": np.float64}

#: Types are named "A", "B", ... one per distinct radius, up to MOST_TYPES; more radii than that
#: (a continuous range) get one type for all.
MOST_TYPES = 26

vec_arr = ti.types.ndarray(ndim=1)


@ti.kernel
def _count_wraps(pos: vec_arr, ids: vec_arr, previous: vec_arr, image: vec_arr, w: ti.f64, h: ti.f64):
    """Count each circle's crossings of the periodic box since the last call: pos and ids in
    storage order; previous (positions) and image (counts) in creation order."""
    for slot in range(pos.shape[0]):
        i = ids[slot]
        p = pos[slot]
        d = ti.cast(p - previous[i], ti.f64)
        if d[0] < -0.5 * w:
            image[i][0] += 1
        elif d[0] > 0.5 * w:
            image[i][0] -= 1
        if d[1] < -0.5 * h:
            image[i][1] += 1
        elif d[1] > 0.5 * h:
            image[i][1] -= 1
        previous[i] = p


class ImageTracker:
    """Image flags of a simulation in a periodic box, counted after each of its steps (see the
    module's docstring). Attaches itself to `sim.after_step`; `images()` gives (N, 2) int32 in
    creation order; `detach()` stops counting. `image` gives the counts to start from."""

    def __init__(self, sim, image=None):
        if sim.boundary != "periodic":
            raise ValueError("image flags count wraps of a periodic box; this simulation has walls")
        self.sim = sim
        n = sim.n
        self._previous = ti.Vector.ndarray(2, sim._real, shape=n)
        self._previous.from_numpy(sim._creation_order(sim.pos.to_numpy()))
        self._image = ti.Vector.ndarray(2, ti.i32, shape=n)
        start = np.zeros((n, 2), np.int32) if image is None else np.asarray(image, np.int32)[:, :2]
        self._image.from_numpy(np.ascontiguousarray(start))
        sim.after_step.append(self)

    def __call__(self, sim):
        _count_wraps(sim.pos, sim.ids, self._previous, self._image, sim.box[0], sim.box[1])

    def images(self):
        return self._image.to_numpy()

    def detach(self):
        if self in self.sim.after_step:
            self.sim.after_step.remove(self)


def type_names(radius):
    """(typeid (N,) uint32, types): one type per distinct radius, named A, B, ... in order of
    radius; a single type "A" for more than MOST_TYPES radii."""
    values, typeid = np.unique(radius, return_inverse=True)
    if len(values) > MOST_TYPES:
        return np.zeros(len(radius), np.uint32), ["A"]
    return typeid.astype(np.uint32), [chr(ord("A") + k) for k in range(len(values))]


def _text(value):
    return np.frombuffer(value.encode(), np.uint8).copy()


def check_path(path, force=False, suffix=".gsd", what="--trajectory", made=None, resumable=True):
    """Raise ValueError unless a data file can be written at `path`: the suffix, a writable
    folder, and no file there unless `force` (the refusal names --resume where the command has
    it: `resumable`). Missing folders are made and listed in `made` (deepest last), as
    `video.check_writable` does; no file is created."""
    path = Path(path)
    if path.suffix.lower() != suffix:
        raise ValueError(f"{what} {path}: the file name must end in {suffix}, e.g. run{suffix}")
    if path.is_dir():
        raise ValueError(f"{what} {path} is a folder: give a file's path, such as {path / ('run' + suffix)}")
    make_folder(path.parent, f"{what} {path}", made)
    if path.exists() and not force:
        resume = " --resume to continue its run," if resumable else ""
        raise ValueError(f"{what} {path} exists: give --force to overwrite it,{resume} or another name")
    return path


class GSDWriter:
    """Appends frames of a `Simulation` to a GSD file (HOOMD schema, see the module).

    mode: "w" (a new file, overwriting), "x" (a new file; fails if it exists) or "a" (append to
    a file that a GSDWriter wrote, of the same circles). In a periodic box the image flags come
    from an `ImageTracker` attached to the simulation at the first `write` and detached by
    `close` (or given as `tracker`, which stays attached): frames are then written as the run
    goes, so that it sees every step. Each frame
    is flushed to the file when written, so a run stopped at any point leaves whole frames.

    What does not change over a run (diameters, masses, types, colours) is written in the first
    frame only; gsd.hoomd gives every frame the first frame's value of a chunk it lacks.

    order=True also writes each circle's local hexatic order psi_6 (`circles.order`) as
    ``log/particles/circles/psi6`` (N, 2) float64, its real and imaginary parts, and the global
    ``log/circles/hexatic_order``: a pass over the neighbours at each frame, so only when asked.

    run: what made the run (a dict that JSON writes), kept in the first frame as
    ``log/circles/run``; `run_of` reads it back. tracker=False writes no image flags (a
    restart point that no trajectory continues: `circles.checkpoint`).
    """

    def __init__(self, path, mode="w", tracker=None, order=False, run=None):
        import gsd
        import gsd.fl

        from . import __version__

        self.path = Path(path)
        self._file = gsd.fl.open(name=str(self.path), mode=mode, application=f"circles {__version__}",
                                 schema="hoomd", schema_version=[1, 4])
        self.tracker = tracker
        self.order = bool(order)
        self.run = run
        self._made_tracker = None  # the tracker this writer attached, detached again by close
        self.frames = self._file.nframes
        self.seconds = 0.0  # spent writing, wall-clock
        self.cpu_seconds = 0.0  # the process's processor time meanwhile

    def write(self, sim, row=None, stats=None):
        """Append the state of `sim` now, with `row` (a stats row, `observables.interval`) in its
        log (without one, the state's own values and NaN for the rates), and the totals of
        `stats` (its `stats()` now, taken when not given)."""
        import time as clock

        tick, cpu = clock.perf_counter(), clock.process_time()
        if sim.periodic and self.tracker is None:
            if sim.steps > 0:
                raise ValueError("a periodic run's trajectory must start before its first step, so that every "
                                 "wrap is counted: make the GSDWriter (or an ImageTracker) at the start")
            self.tracker = self._made_tracker = ImageTracker(sim)
        if stats is None or row is None:
            stats = sim.stats()
        if row is None:
            row = row_of(stats, stats, sim)
        n = sim.n
        w, h = sim.box
        held_pos, held_vel, pair_count, wall_count, virial, wall_impulse = sim._download()
        chunk = self._file.write_chunk
        chunk("configuration/step", np.array([sim.steps], np.uint64))
        if self.frames == 0:
            typeid, types = type_names(sim._radius)
            width = max(len(name) for name in types) + 1
            chunk("configuration/dimensions", np.array([2], np.uint8))
            chunk("configuration/box", np.array([w, h, 0, 0, 0, 0], np.float32))
            chunk("particles/N", np.array([n], np.uint32))
            chunk("particles/types", np.array(types, dtype=(bytes, width)).view(np.int8).reshape(len(types), width))
            chunk("particles/typeid", typeid)
            chunk("particles/diameter", (2.0 * sim._radius).astype(np.float32))
            chunk("particles/mass", sim._mass.astype(np.float32))
            chunk("log/particles/circles/radius", sim._radius)
            chunk("log/particles/circles/mass", sim._mass)
            chunk("log/particles/circles/color", np.ascontiguousarray(sim._color))
            if self.run is not None:
                chunk("log/circles/run", _text(json.dumps(self.run, sort_keys=True)))
        vec = np.zeros((n, 3), np.float32)
        np.subtract(held_pos, (0.5 * w, 0.5 * h), out=vec[:, :2], casting="unsafe")
        chunk("particles/position", vec)
        vec[:, :2] = held_vel
        chunk("particles/velocity", vec)
        if self.tracker:
            image = np.zeros((n, 3), np.int32)
            image[:, :2] = self.tracker.images()
            chunk("particles/image", image)
        for name in observables.COLUMNS:
            chunk(f"log/circles/{name}", np.array([row[name]], np.float64))
        if self.order:
            from .order import hexatic_order, psi6

            local = psi6(held_pos, sim.box, sim.periodic)
            chunk("log/particles/circles/psi6", np.stack([local.real, local.imag], axis=1))
            chunk("log/circles/hexatic_order", np.array([hexatic_order(local)], np.float64))
        chunk("log/circles/box", np.array([w, h], np.float64))  # configuration/box is float32
        chunk("log/circles/dt", np.array([sim.dt], np.float64))
        chunk("log/circles/precision_bits", np.array([32 if sim.precision == "f32" else 64], np.uint8))
        chunk("log/circles/boundary", _text(sim.boundary))
        chunk("log/circles/scheme", _text(sim.scheme))
        chunk("log/circles/totals", np.array([stats["pair_collisions"], stats["wall_collisions"], stats["virial"],
                                              stats["wall_impulse"]], np.float64))
        chunk("log/particles/circles/position", np.ascontiguousarray(held_pos))
        chunk("log/particles/circles/velocity", np.ascontiguousarray(held_vel))
        # Each circle's share of the totals, so that a restart adds up the same sums.
        chunk("log/particles/circles/pair_count", np.ascontiguousarray(pair_count, np.int32))
        chunk("log/particles/circles/virial", np.ascontiguousarray(virial, np.float64))
        if not sim.periodic:
            chunk("log/particles/circles/wall_count", np.ascontiguousarray(wall_count, np.int32))
            chunk("log/particles/circles/wall_impulse", np.ascontiguousarray(wall_impulse, np.float64))
        self._file.end_frame()
        self._file.flush()
        self.frames += 1
        self.seconds += clock.perf_counter() - tick
        self.cpu_seconds += clock.process_time() - cpu

    def close(self):
        if self._made_tracker is not None:
            self._made_tracker.detach()
        self._file.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc_info):
        self.close()
        return False


def read_simulation(path, frame=-1, *, track_images=True):
    """A `Simulation` in the state of frame `frame` of a GSD file that `GSDWriter` wrote: the
    positions and velocities as the simulation held them (bit for bit), radii, masses, colours,
    box, boundary, scheme, precision, dt, time and step count. In a periodic box it carries on
    the image flags (`sim.image_tracker`) unless `track_images` is False: to go on with the same
    trajectory, ``GSDWriter(path, "a", tracker=sim.image_tracker)``."""
    import gsd.hoomd

    from .simulation import Simulation

    with gsd.hoomd.open(str(path)) as traj:
        if len(traj) == 0:
            raise ValueError(f"{path} holds no frames")
        snap = traj[frame]
        log = snap.log  # gsd.hoomd gives every frame the first frame's radii, masses and colours
        if "particles/circles/position" not in log:
            raise ValueError(f"{path} was not written by circles (no log/particles/circles/position chunk): "
                             "read it with gsd.hoomd")
        # Files written before the box was kept in float64 have only the float32 one.
        box = log["circles/box"] if "circles/box" in log else snap.configuration.box[:2]
        fields = dict(pos=log["particles/circles/position"], vel=log["particles/circles/velocity"],
                      radius=log["particles/circles/radius"], mass=log["particles/circles/mass"],
                      color=log["particles/circles/color"], box=np.array(box, np.float64),
                      boundary=bytes(log["circles/boundary"]).decode(), scheme=bytes(log["circles/scheme"]).decode(),
                      precision="f32" if int(log["circles/precision_bits"][0]) == 32 else "f64",
                      dt=float(log["circles/dt"][0]), time=float(log["circles/time"][0]),
                      steps=int(snap.configuration.step))
        n = len(fields["radius"])
        if "particles/circles/pair_count" in log:  # each circle's share (a periodic box: none of the walls')
            for name, dtype in SHARES.items():
                fields[name] = log.get(f"particles/circles/{name}", np.zeros(n, dtype))
        else:
            fields.update(_totals_on_circle_0(log["circles/totals"], n))
        image = snap.particles.image if fields["boundary"] == "periodic" else None
    sim = Simulation._from_fields(fields)
    sim.image_tracker = ImageTracker(sim, image) if image is not None and track_images else None
    return sim


def _totals_on_circle_0(totals, n):
    """Per-circle sums for a frame of a file written before the shares were kept: each total
    on circle 0, and a count beyond int32's range spread over the first circles."""
    fields = {}
    for name, total in zip(SHARES, totals):
        values = np.zeros(n, SHARES[name])
        if SHARES[name] is np.int32:
            whole, k = int(total), 0
            while whole > 0:
                values[k] = min(whole, np.iinfo(np.int32).max)
                whole -= int(values[k])
                k += 1
        else:
            values[0] = total
        fields[name] = values
    return fields


def run_of(path):
    """What made the run of a GSD file that `GSDWriter` wrote with ``run=``: the dict of its
    first frame's ``log/circles/run``, or None (no such chunk, or no frame)."""
    import gsd.fl

    with gsd.fl.open(name=str(path), mode="r") as file:
        if file.nframes == 0 or not file.chunk_exists(0, "log/circles/run"):
            return None
        return json.loads(bytes(file.read_chunk(0, "log/circles/run")).decode())


def unwrapped(frame):
    """Unwrapped positions (N, 2) float64 of a gsd.hoomd frame, box-centred:
    position + image * (Lx, Ly), from the full-precision positions and box where the frame has
    them."""
    log = frame.log
    box = np.asarray(log["circles/box"] if "circles/box" in log else frame.configuration.box[:2])
    if "particles/circles/position" in log:
        pos = log["particles/circles/position"] - 0.5 * box
    else:
        pos = frame.particles.position[:, :2]
    return pos + frame.particles.image[:, :2] * box
