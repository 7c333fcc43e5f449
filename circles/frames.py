"""Start from a frame of a GSD file: `circles run --from FILE.gsd[:FRAME]`, a scene file's
``from = "FILE.gsd:FRAME"``, `circles compress --from`, and `circle_list_from_gsd` in Python.

What is read, as a `scenefile.CircleList` (the arguments of ``Simulation.from_arrays``):

- a file circles wrote (`--trajectory`, `circles compress --out`, a checkpoint): the circles
  as the simulation held them, in float64 (positions, velocities, radii, masses, colours, the
  box, the boundary), and its scheme, precision and dt unless the caller gives others;
- a HOOMD-blue file (or any of the HOOMD schema): ``particles/position`` (the box's centre moved
  to its corner, where circles puts the origin), ``particles/diameter`` (HOOMD's default 1),
  ``particles/mass`` (default 1) and ``particles/velocity`` when the frame or the first frame
  holds it; otherwise speeds drawn as the scene says (its speed range and seed), in random
  directions. The box is periodic, as HOOMD's is.

Refused, with one line naming the file and the fix: a frame that does not exist, a box that
is tilted or three-dimensional, a frame with no particles, and circles that overlap (the
pair and by how much).
"""
from __future__ import annotations

import os

import numpy as np


def split_spec(spec):
    """("FILE.gsd", FRAME) from "FILE.gsd" (the last frame, -1) or "FILE.gsd:FRAME"."""
    path, sep, frame = str(spec).rpartition(":")
    if not sep or not path.lower().endswith(".gsd"):
        return str(spec), -1
    try:
        return path, int(frame)
    except ValueError:
        raise ValueError(f"--from {spec}: the frame after the colon must be a whole number, e.g. {path}:0 "
                         "(or -1 for the last)") from None


def circle_list_from_gsd(spec, *, speed=(0.5, 1.0), seed=0, mass="radius", scheme=None, precision=None, dt=None):
    """The circles of frame FRAME of "FILE.gsd[:FRAME]" (the last by default) as a CircleList.
    speed, seed and mass fill in what a HOOMD file lacks (velocities; masses are HOOMD's own or
    1); scheme, precision and dt, when given, replace the file's (circles' files) or the
    defaults of `Scene`."""
    import gsd.fl
    import gsd.hoomd

    from .inputs import random_colors
    from .scene import Scene, check_dt
    from .scenefile import CircleList, _check_inside, first_overlap

    path, frame = split_spec(spec)
    if not path.lower().endswith(".gsd"):
        raise ValueError(f"--from {spec}: give a GSD file, FILE.gsd or FILE.gsd:FRAME")
    if not os.path.isfile(path):
        raise ValueError(f"--from {spec}: {path} does not exist")
    try:
        traj = gsd.hoomd.open(path, "r")
    except (RuntimeError, OSError) as error:
        raise ValueError(f"--from {spec}: {path} is not a GSD file gsd can read ({error})") from None
    with traj:
        frames = len(traj)
        if not -frames <= frame < frames:
            raise ValueError(f"--from {spec}: {path} holds {frames} frame{'s' if frames != 1 else ''}, so frame "
                             f"{frame} does not exist: give 0 to {frames - 1}, or -1 for the last")
        index = frame % frames
        snap = traj[index]
        log = snap.log
        if "particles/circles/position" in log:
            return _own(log, snap, scheme, precision, dt)
        box = np.asarray(snap.configuration.box, np.float64)
        if snap.configuration.dimensions != 2 or np.any(box[3:] != 0):
            raise ValueError(f"--from {spec}: frame {index} has a {snap.configuration.dimensions}D box with tilts "
                             f"{[float(t) for t in box[3:]]}: circles reads square-cornered 2D boxes (dimensions = 2, no tilt)")
        n = int(snap.particles.N)
        if n == 0:
            raise ValueError(f"--from {spec}: frame {index} holds no particles")
        size = box[:2]
        pos = np.asarray(snap.particles.position, np.float64)[:, :2] + size / 2.0
        pos = np.mod(pos, size)
        radius = np.asarray(snap.particles.diameter, np.float64) / 2.0
        masses = np.asarray(snap.particles.mass, np.float64)
        with gsd.fl.open(path, "r") as raw:
            has_velocity = raw.chunk_exists(index, "particles/velocity") or raw.chunk_exists(0, "particles/velocity")
    if has_velocity:
        vel = np.asarray(snap.particles.velocity, np.float64)[:, :2]
    else:
        rng = np.random.default_rng(seed)
        lo, hi = speed
        speeds = rng.uniform(lo, hi, n) if hi > lo else np.full(n, lo)
        angle = rng.uniform(0.0, 2.0 * np.pi, n)
        vel = np.stack([speeds * np.cos(angle), speeds * np.sin(angle)], axis=1)
    if np.any(radius <= 0) or np.any(masses <= 0):
        raise ValueError(f"--from {spec}: frame {index} has particles of diameter or mass 0 or less: circles needs "
                         "both above 0")
    boundary = "periodic"
    scheme = scheme or Scene.scheme
    precision = precision or Scene.precision
    box_t = (float(size[0]), float(size[1]))
    try:
        _check_inside(pos, radius, box_t, boundary, 0.0)
    except ValueError as error:
        raise ValueError(f"--from {spec}: frame {index}: {error}") from None
    pair = first_overlap(pos, radius, box_t, boundary)
    if pair is not None:
        i, j, distance = pair
        contact = radius[i] + radius[j]
        raise ValueError(f"--from {spec}: frame {index}: particles {i} and {j} overlap by {1 - distance / contact:.3g} "
                         f"of their contact distance {contact:.6g} (centres {distance:.6g} apart): hard disks must "
                         "be apart or touching")
    return CircleList(pos=pos, vel=vel, radius=radius, mass=masses, color=random_colors(n, np.random.default_rng(0)),
                      box=box_t, boundary=boundary, scheme=scheme, precision=precision, dt=check_dt(dt))


def _own(log, snap, scheme, precision, dt):
    """A CircleList of a frame that circles wrote, from its float64 log chunks."""
    from .scene import check_dt
    from .scenefile import CircleList

    # Files written before the box was kept in float64 have only the float32 one.
    box = log["circles/box"] if "circles/box" in log else snap.configuration.box
    return CircleList(pos=np.asarray(log["particles/circles/position"], np.float64),
                      vel=np.asarray(log["particles/circles/velocity"], np.float64),
                      radius=np.asarray(log["particles/circles/radius"], np.float64),
                      mass=np.asarray(log["particles/circles/mass"], np.float64),
                      color=np.asarray(log["particles/circles/color"], np.uint8),
                      box=tuple(float(b) for b in box[:2]),
                      boundary=bytes(log["circles/boundary"]).decode(),
                      scheme=scheme or bytes(log["circles/scheme"]).decode(),
                      precision=precision or ("f32" if int(log["circles/precision_bits"][0]) == 32 else "f64"),
                      dt=check_dt(dt if dt is not None else float(log["circles/dt"][0]) or None))
