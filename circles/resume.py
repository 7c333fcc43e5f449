"""Where a stopped `circles run` goes on from: `circles run ... --resume`.

A run is deterministic, so a run continued from a restart point gives the same bits as one
never stopped. Its restart points are its trajectory's frames (each holds the whole state,
`circles.trajectory`) and its checkpoint (`circles.checkpoint`, with --checkpoint-every). A
checkpoint is the state at a frame instant before that frame's writers ran; a trajectory frame
the state after. The newest of the two wins; at the same frame, the trajectory's.

The files record what made the run (`identity`): the scene, the frame rate and whether the
hexatic order is measured. A run continues only with the same; the duration may differ, so
that a finished run can be made longer, provided it ended on a frame instant.
"""
import hashlib
import json
import math
from dataclasses import dataclass

import numpy as np


def identity(scene, fps, order):
    """What fixes a run's bits, as JSON gives it back: the scene (a `Scene`'s fields, or a
    digest of the circles a `CircleList` gives), the frame rate (the instants at which the
    run's advances stop) and whether the hexatic order is measured (the stats columns)."""
    if hasattr(scene, "to_dict"):
        described = scene.to_dict()
    else:
        digest = hashlib.sha256()
        for values in (scene.pos, scene.vel, scene.radius, scene.mass):
            digest.update(np.ascontiguousarray(values, np.float64).tobytes())
        if scene.color is not None:
            digest.update(np.ascontiguousarray(scene.color, np.uint8).tobytes())
        described = {"circles": int(scene.n), "sha256": digest.hexdigest(), "box": list(scene.box),
                     "boundary": scene.boundary, "scheme": scene.scheme, "precision": scene.precision,
                     "dt": scene.dt}
    return json.loads(json.dumps({"scene": described, "fps": float(fps), "order": bool(order)}))


def difference(held, wanted):
    """The first field in which two identities differ, as text ("seed 3, and this run has 4"),
    or None."""
    def flat(value, prefix=""):
        if isinstance(value, dict):
            out = {}
            for key, item in value.items():
                out.update(flat(item, f"{prefix}{key} " if prefix or key != "scene" else ""))
            return out
        return {prefix.strip(): value}

    def text(value):
        return "unset" if value is None else json.dumps(value)

    old, new = flat(held), flat(wanted)
    for key in sorted(set(old) | set(new)):
        if old.get(key) != new.get(key):
            return f"{key} {text(old.get(key))}, and this run has {text(new.get(key))}"
    return None


@dataclass
class RestartPoint:
    """Where a run goes on: the state of frame instant `frame` (`frame` rows of stats written)
    in the last frame of the file `source`, at simulated time `time`; `refire` True when that
    frame's writers have still to run (a checkpoint's); `start` the simulated time of frame 0;
    `row` the stats row of the interval that ended at a checkpoint (what that frame's writers
    get first)."""

    source: object
    frame: int
    time: float
    refire: bool
    start: float
    row: dict = None

    def simulation(self):
        """The simulation in this state, its image flags carried on (`trajectory.read_simulation`)."""
        from .trajectory import read_simulation

        return read_simulation(self.source)


def _refuse(text):
    from .command import UsageError

    return UsageError(f"--resume: {text}")


def _check_identity(path, held, wanted):
    if held is None:
        raise _refuse(f"{path} does not say what made its run (no log/circles/run chunk): it was not written by "
                      "circles run; drop --resume and give other files")
    why = difference(held, wanted)
    if why is not None:
        raise _refuse(f"{path} holds a run made with {why}: give the scene and flags that run was made with, or "
                      "drop --resume (with --force to overwrite the files)")


def _last_time(path):
    """The simulated time of the last frame of a GSD file that `trajectory.GSDWriter` wrote."""
    import gsd.fl

    with gsd.fl.open(name=str(path), mode="r") as file:
        return float(file.read_chunk(file.nframes - 1, "log/circles/time")[0])


def restart_point(trajectory, checkpoint_path, wanted):
    """The newest restart point of a run whose trajectory (or None) and checkpoint (a path that
    may not exist) are given, after checking that they hold the run `wanted` (`identity`);
    None when they hold no restart point yet (stopped before its first frame). Reads what the
    files say of themselves only: `RestartPoint.simulation` makes the simulation."""
    import gsd.fl

    from .trajectory import run_of

    frames = 0
    if trajectory is not None:
        try:
            with gsd.fl.open(name=str(trajectory), mode="r") as file:
                frames = file.nframes
        except RuntimeError as error:
            raise _refuse(f"{trajectory} is not a GSD file that gsd can read ({error})") from None
        if frames:
            held = run_of(trajectory)
            _check_identity(trajectory, held and held.get("run"), wanted)
    progress = None
    if checkpoint_path is not None and checkpoint_path.exists():
        try:
            progress = run_of(checkpoint_path)
        except (RuntimeError, OSError) as error:
            raise _refuse(f"{checkpoint_path} is not a checkpoint gsd can read ({error}): remove it to go on from "
                          "the trajectory's last frame") from None
        _check_identity(checkpoint_path, progress and progress.get("run"), wanted)
    if progress is not None and progress["frame"] >= frames:  # newer than the trajectory's last frame
        newest = progress["frame"]
        if trajectory is not None and frames != newest:
            raise _refuse(f"{checkpoint_path} is of frame {newest}, but {trajectory} holds {frames} frames, not the "
                          f"{newest} before it: the files are not of one run")
        return RestartPoint(checkpoint_path, int(newest), _last_time(checkpoint_path), True,
                            float(progress["start"]), progress.get("row"))
    if frames:
        return RestartPoint(trajectory, frames - 1, _last_time(trajectory), False, float(held["start"]))
    return None


def check_schedule(point, times, fps):
    """Refuse a restart point that the run's frame instants (`writers.frame_times`, from its
    start) cannot go on from: one past the run's end, or a run's end between two frames."""
    if point.frame > len(times) - 1 or point.time > point.start + times[-1]:
        raise _refuse(f"the run reached t = {point.time:.6g} s ({point.frame} frames), beyond this --duration "
                      f"{times[-1]:g} s: give a --duration of at least {point.time - point.start:.6g}")
    expected = point.start + times[point.frame]  # the last of the times is the run's end
    if not math.isclose(point.time, expected, rel_tol=1e-12):
        raise _refuse(f"the run stopped at t = {point.time:.6g} s, between frames (the frame instant there is "
                      f"{expected:.6g} s at {fps:g} fps): only a run whose duration is a whole number of frames "
                      "can be made longer")
