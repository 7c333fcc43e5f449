"""Restart points: the whole state of a simulation and how far its run got, in one GSD frame.

A checkpoint is a GSD file of one frame in the trajectory's schema (`circles.trajectory`):
positions and velocities in the working precision, each circle's share of the stats totals,
the image flags where a trajectory goes on from it, and in ``log/circles/run`` a JSON dict of
the run's progress. `read` makes the simulation again, so that it goes on bit for bit as the
one that wrote it. `write` replaces the file whole: it writes under a temporary name beside
it, syncs it to disk and renames it, so a stop at any moment leaves the old checkpoint or the
new one, never a part.
"""
import os
from pathlib import Path

#: The name of a run's checkpoint beside its data file: run.gsd -> run.checkpoint.gsd.
SUFFIX = ".checkpoint.gsd"


def path_beside(data_path):
    """The checkpoint of the run whose data file is `data_path` (its trajectory, or else its
    stats table): the same folder and stem, ending in SUFFIX."""
    data_path = Path(data_path)
    return data_path.with_name(data_path.stem + SUFFIX)


def write(path, sim, progress, tracker=None):
    """Replace the checkpoint at `path` by the state of `sim` now and `progress` (a dict that
    JSON writes). `tracker`: the run's `trajectory.ImageTracker`, whose image flags the frame
    then holds (none without it)."""
    from .storage import replaced_whole
    from .trajectory import GSDWriter

    path = Path(path)
    with replaced_whole(path) as part:
        with GSDWriter(part, tracker=False if tracker is None else tracker, run=progress) as writer:
            writer.write(sim)
        descriptor = os.open(part, os.O_RDONLY)  # on disk before it takes the old one's place
        try:
            os.fsync(descriptor)
        finally:
            os.close(descriptor)
    return path


def read(path):
    """(simulation, progress) of the checkpoint at `path`: the simulation in the state it was
    written in (its image flags in ``sim.image_tracker`` in a periodic box), and the progress
    dict. ValueError for a file that is not a checkpoint."""
    from .trajectory import read_simulation, run_of

    try:
        progress = run_of(path)
    except (RuntimeError, OSError) as error:
        if isinstance(error, FileNotFoundError):
            raise
        raise ValueError(f"{path} is not a checkpoint that circles wrote: gsd cannot read it ({error})") from None
    if progress is None:
        raise ValueError(f"{path} is not a checkpoint that circles wrote: it has no log/circles/run chunk")
    return read_simulation(path), progress
