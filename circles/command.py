"""What the commands `circles run`, `circles plot` and `circles sweep` share: exit statuses,
the parser that turns a bad argument into one line, and the checks that a destination can be
written before any work starts.

Exit statuses: 0 done; 2 bad input or a destination that cannot be written (one line on
stderr, before any work); 1 a failure during the work (one line, naming only files that
exist); 130 stopped by Ctrl-C.
"""
import argparse
import tempfile
from pathlib import Path

EXIT_BAD_INPUT = 2
EXIT_FAILED = 1
EXIT_INTERRUPTED = 130

#: The tables that tell a sweep file from a scene file.
SWEEP_TABLES = ("scene", "vary", "sweep")


class UsageError(ValueError):
    """Bad input: the message is printed as one line and the exit status is 2."""


class Parser(argparse.ArgumentParser):
    """An argument parser whose errors are UsageErrors (one line, exit status 2), not exits."""

    def error(self, message):
        raise UsageError(message)


def make_folder(folder, what, made=None):
    """Make `folder` and its missing parents, listing those made in `made` (deepest last) when
    given; then check that a file can be created in it. Raises UsageError naming `what` (the
    flag or argument) and the reason."""
    folder = Path(folder) if str(folder) else Path(".")
    blocking = next((f for f in [folder, *folder.parents] if f.exists() and not f.is_dir()), None)
    if blocking is not None:
        raise UsageError(f"{what}: {blocking} is a file, not a folder: give a path in a folder")
    missing = [f for f in [folder, *folder.parents] if not f.exists()][::-1]
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise UsageError(f"{what}: cannot make the folder {folder} ({error.strerror or error}): "
                         "choose another place") from None
    if made is not None:
        made.extend(missing)
    probe_folder(folder, what)
    return folder


def probe_folder(folder, what):
    """Raise UsageError unless a file can be created in `folder` (tried, and removed at once:
    permissions alone do not say it, as for root on a read-only file system)."""
    try:
        with tempfile.NamedTemporaryFile(dir=folder, prefix=".circles-check-"):
            pass
    except OSError as error:
        raise UsageError(f"{what}: cannot write in the folder {folder} ({error.strerror or error}): "
                         "choose another place") from None


def sweep_or_scene(data):
    """"sweep" when the tables of a TOML file are a sweep file's ([scene] with [vary] or
    [sweep]), else "scene"."""
    return "sweep" if "scene" in data and ({"vary", "sweep"} & set(data)) else "scene"


def remove_made(made):
    """Remove the folders listed in `made` (by `make_folder` or `video.check_writable`),
    deepest first, each only if it is still empty."""
    for folder in reversed(made):
        try:
            Path(folder).rmdir()
        except OSError:
            pass
    made.clear()
