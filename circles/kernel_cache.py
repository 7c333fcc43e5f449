"""Whether this machine has built the kernels of a scene before, to say so when it has not.

Taichi compiles a scene's kernels on their first use (seconds each) and keeps them in its
offline cache, so a second run of the same kind of scene starts at once. What decides the
kernels is the kind of scene (scheme, precision, boundary, equal or mixed radii), where they
run (arch, threads), how they compile (with Taichi's CFG pass from `backend.OPTIMIZE_FROM_N`
circles), and the code (Taichi's version, this package's source). This module
keeps a list of those kinds beside Taichi's cache; a kind not on it is announced once
("compiling kernels for this scene; cached for next time") and put on it. A cache emptied by
hand, or shared with another machine, can make the list wrong: the message is a courtesy,
not a promise.
"""
from __future__ import annotations

import hashlib
import os

MESSAGE = "compiling kernels for this scene; cached for next time"
#: The list's file name, in Taichi's offline cache folder.
SEEN = "circles-kernels-seen.txt"


def cache_folder():
    """Taichi's offline cache folder: TI_OFFLINE_CACHE_FILE_PATH, or its default."""
    return os.environ.get("TI_OFFLINE_CACHE_FILE_PATH") or os.path.expanduser("~/.cache/taichi/ticache")


def _source_fingerprint():
    here = os.path.dirname(os.path.abspath(__file__))
    digest = hashlib.sha256()
    for name in sorted(os.listdir(here)):
        if name.endswith(".py"):
            info = os.stat(os.path.join(here, name))
            digest.update(f"{name}:{info.st_size}:{info.st_mtime_ns};".encode())
    return digest.hexdigest()


def kind_of(scene, arch, threads):
    """The key of a scene's kernel set: a `Scene` or a `scenefile.CircleList`, the arch asked
    for and the CPU threads (0: all)."""
    from importlib import metadata

    import numpy as np

    radius = np.asarray(scene.radius, dtype=np.float64)
    equal = bool(radius.min() == radius.max())
    try:
        taichi = metadata.version("taichi")
    except metadata.PackageNotFoundError:
        taichi = "?"
    from .backend import OPTIMIZE_FROM_N

    optimized = "optimized" if scene.n >= OPTIMIZE_FROM_N else "quick"  # how a CPU compiles it (backend.compile_for)
    text = (f"{taichi} {_source_fingerprint()} {arch} {threads} {scene.scheme} {scene.precision} "
            f"{scene.boundary} {'equal' if equal else 'mixed'} {optimized}")
    return hashlib.sha256(text.encode()).hexdigest()[:32]


def first_use(kind) -> bool:
    """True when `kind` is not on the list yet; it is put on it (the run about to start builds it)."""
    path = os.path.join(cache_folder(), SEEN)
    try:
        with open(path) as file:
            if kind in file.read().split():
                return False
    except OSError:
        pass
    try:
        os.makedirs(os.path.dirname(path), exist_ok=True)
        with open(path, "a") as file:
            file.write(kind + "\n")
    except OSError:
        pass  # a cache folder that cannot be written: the message comes again next time
    return True


def announce(scene, arch="auto", threads=0, stream=None):
    """Print MESSAGE on `stream` (stderr by default, a terminal or not) when the scene's kernel
    set is new here; True when it is. Compiling a new set takes seconds, so a run that would
    otherwise sit silent says why."""
    import sys

    new = first_use(kind_of(scene, arch, threads))
    if new:
        print(MESSAGE, file=sys.stderr if stream is None else stream, flush=True)
    return new
