"""Storage of a simulation: the file that `Simulation.save` writes and `Simulation.load` reads
(an .npz archive of the state in creation order, exactly as stored, and what describes the
run), checked whole before a simulation is made from it."""
import contextlib
import math
import os
import zipfile
from pathlib import Path

import numpy as np

from .inputs import check_circles, check_colors, check_placed, masses_for, place_slack
from .scene import BOUNDARIES, PRECISIONS, SCHEMES, _choice, check_box, check_count, check_dt

#: The most collisions a circle's counters hold (32-bit integers).
COUNT_MAX = 2 ** 31 - 1
#: The arrays of a file that `Simulation.save` writes.
SAVED_FIELDS = ("pos", "vel", "radius", "mass", "color", "box", "boundary", "scheme", "precision", "dt", "time",
                "steps", "pair_count", "wall_count", "virial", "wall_impulse")


def read_saved(path):
    """The arrays of a file that `Simulation.save` wrote, by name; ValueError for any other file."""
    def refuse(why):
        return ValueError(f"{path} is not a simulation written by Simulation.save ({why}): load the file that "
                          "save wrote")

    try:
        f = np.load(path)
    except (FileNotFoundError, IsADirectoryError, PermissionError):
        raise
    except (ValueError, zipfile.BadZipFile):  # numpy takes what is neither .npy nor .npz for a pickle
        raise refuse("it is not an .npz archive") from None
    except (OSError, EOFError) as error:
        raise refuse(f"numpy cannot read it: {error}") from None
    if not isinstance(f, np.lib.npyio.NpzFile):
        raise refuse("it holds one array, not an .npz archive")
    with f:
        missing = [k for k in SAVED_FIELDS if k not in f.files]
        if missing:
            raise refuse(f"it lacks {', '.join(missing)}")
        try:
            d = {k: f[k] for k in SAVED_FIELDS}
        except (ValueError, OSError, EOFError, zipfile.BadZipFile) as error:  # a damaged member
            raise refuse(f"numpy cannot read its arrays: {error}") from None
    # Numbers of the right kind first: numpy casts complex numbers to reals with a warning (the
    # imaginary part dropped), and strings fail its arithmetic with messages of its own.
    kinds = {name: "iuf" for name in ("pos", "vel", "radius", "mass", "box", "dt", "time", "virial",
                                      "wall_impulse")}
    kinds.update(steps="iu", pair_count="iu", wall_count="iu")
    for name, kind in kinds.items():
        if d[name].dtype.kind not in kind:
            raise refuse(f"its {name} has type {d[name].dtype}, not {'integer' if kind == 'iu' else 'real number'}")
    if d["radius"].ndim != 1 or d["radius"].shape[0] == 0:
        raise refuse(f"its radius has shape {d['radius'].shape}, not (n,) for n >= 1 circles")
    n = d["radius"].shape[0]
    shapes = {"radius": (n,), "box": (2,), "boundary": (), "scheme": (), "precision": (), "dt": (), "time": (),
              "steps": (), "pair_count": (n,), "wall_count": (n,), "virial": (n,), "wall_impulse": (n,)}
    for name, shape in shapes.items():
        if d[name].shape != shape:
            raise refuse(f"its {name} has shape {d[name].shape}, not {shape}")
    for name in ("pair_count", "wall_count", "virial", "wall_impulse"):
        if not np.all(np.isfinite(d[name]) & (d[name] >= 0)):
            raise refuse(f"its {name} holds {d[name][~(np.isfinite(d[name]) & (d[name] >= 0))][0]}, not a "
                         "finite number >= 0")
    for name in ("pair_count", "wall_count"):  # a circle's counts are 32-bit integers in a run
        if np.any(d[name] > COUNT_MAX):
            raise refuse(f"its {name} holds {d[name].max()}, more than the {COUNT_MAX} a run counts for a circle")
    try:
        for name, allowed in (("boundary", BOUNDARIES), ("scheme", SCHEMES), ("precision", PRECISIONS)):
            _choice(name, str(d[name]), allowed)
        precision = str(d["precision"])
        box = check_box(tuple(float(x) for x in d["box"]))
        check_dt(float(d["dt"]))
        check_count("steps", int(d["steps"]))
        check_circles(d["pos"], d["vel"], d["radius"], box, precision)
        d["color"] = check_colors(d["color"], n)
        masses_for(d["mass"], d["radius"], precision)
        # A saved state lies inside the walls up to the rounding of its places.
        check_placed(d["pos"], d["radius"], box, str(d["boundary"]), place_slack(precision, box))
    except (ValueError, TypeError) as error:
        raise refuse(str(error)) from None
    if not (math.isfinite(float(d["time"])) and float(d["time"]) >= 0):
        raise refuse(f"its time {d['time']} is not a finite number >= 0")
    return d


def write_saved(path, fields) -> Path:
    """Write what `fields()` gives (`SAVED_FIELDS`), called once the path is known to be
    writable, to the file `path` as an .npz archive, whatever its suffix
    (numpy's own savez would add .npz to a name without it); returns the path. The archive is
    written beside it under a temporary name and then renamed, so a failed save leaves no
    partial file and keeps an older one."""
    path = Path(path)
    if path.is_dir():
        raise IsADirectoryError(f"cannot save to {path}: it is a folder; give a file's path, such as "
                                f"{path / 'run.npz'}")
    if not path.parent.is_dir():
        raise FileNotFoundError(f"cannot save to {path}: the folder {path.parent} does not exist; make it first")
    fields = fields()
    with replaced_whole(path) as part, open(part, "wb") as f:
        np.savez(f, **fields)
    return path


@contextlib.contextmanager
def replaced_whole(path):
    """The temporary path beside `path` to write a file's new content to: renamed to `path`
    when the block ends, removed when it fails, so that `path` holds the old file or the new
    one whole, never a part of one."""
    path = Path(path)
    # The temporary name holds at most 100 bytes of the file's (a name may take 255).
    short = path.name.encode()[:100].decode(errors="ignore")
    part = path.with_name(f".{short}.{os.getpid()}.part")
    try:
        yield part
        os.replace(part, path)
    finally:
        part.unlink(missing_ok=True)
