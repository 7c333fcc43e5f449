"""``circles plot RUN.csv [--out RUN.png]``: a stats table (`circles run --stats`) against time.

Three panels over the simulated time: the kinetic energy; the pressure, from the virial and,
in a walled box, from the walls; the collision rate (pair collisions a circle takes part in per
unit time). Drawn with matplotlib, from the ``plot`` extra (``pip install circles-sim[plot]``).
"""
import sys
from pathlib import Path

from .command import EXIT_BAD_INPUT, EXIT_FAILED, Parser, UsageError, make_folder, remove_made

HINT = "circles: error: circles plot needs matplotlib: pip install 'circles-sim[plot]' (or pip install matplotlib)"


DESCRIPTION = ("Draw energy, pressure (virial and wall) and collision rate of a stats table (circles run "
               "--stats) against time, into a PNG.")


def add_parser(commands):
    """The ``plot`` subcommand's arguments, on the parser of subcommands `commands`."""
    plot = commands.add_parser("plot", help="draw a stats table against time into a PNG",
                               description=DESCRIPTION)
    _arguments(plot)
    return plot


def _arguments(parser):
    parser.add_argument("table", metavar="RUN.csv", help="a stats table written by circles run --stats")
    parser.add_argument("--out", metavar="RUN.png", help="the PNG to write (default: RUN.csv's name with .png)")


def draw(columns, out, title=None):
    """Draw the columns of a stats table (`writers.read_stats`) into the PNG `out`."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    t = columns["time"]
    fig, axes = plt.subplots(3, 1, figsize=(7, 7.5), sharex=True, constrained_layout=True)
    axes[0].plot(t, columns["kinetic_energy"], color="C0")
    axes[0].set_ylabel("kinetic energy")
    axes[1].plot(t, columns["pressure"], color="C1", label="virial")
    if np.any(np.isfinite(columns["wall_pressure"])):
        axes[1].plot(t, columns["wall_pressure"], color="C2", label="walls")
    axes[1].set_ylabel("pressure")
    axes[1].legend(loc="best")
    axes[2].plot(t, columns["collision_rate"], color="C3")
    axes[2].set_ylabel("collisions per circle\nper unit time")
    axes[2].set_xlabel("simulated time")
    if title:
        axes[0].set_title(title)
    fig.savefig(out, dpi=120)
    plt.close(fig)
    return out


def main(argv):
    """``circles plot``'s entry point; returns the exit status."""
    parser = Parser(prog="circles plot", description=DESCRIPTION)
    _arguments(parser)
    made = []  # folders made for the PNG, taken away again when nothing is written
    try:
        args = parser.parse_args(argv)
        table = Path(args.table)
        out = Path(args.out) if args.out else table.with_suffix(".png")
        try:
            import matplotlib  # noqa: F401
        except ImportError:
            print(HINT, file=sys.stderr)
            return EXIT_BAD_INPUT
        columns = _checked_table(table, out, made)
    except UsageError as error:
        print(f"circles plot: error: {error}", file=sys.stderr)
        remove_made(made)
        return EXIT_BAD_INPUT
    except SystemExit as exit_:  # --help
        return exit_.code if isinstance(exit_.code, int) else 0
    try:
        draw(columns, out, title=table.name)
    except OSError as error:
        out.unlink(missing_ok=True)
        remove_made(made)
        print(f"circles plot: the plot failed: cannot write {out}: {error.strerror or error}", file=sys.stderr)
        return EXIT_FAILED
    print(f"wrote       {out} ({len(columns['time'])} rows)")
    return 0


def _checked_table(table, out, made):
    """The columns of the stats table `table`, once `out` is known to be writable (its missing
    folders made, listed in `made`); a UsageError of one line otherwise."""
    from . import observables
    from .writers import read_stats

    if out.suffix.lower() != ".png":
        raise UsageError(f"--out {out}: the file name must end in .png")
    if out.is_dir():
        raise UsageError(f"--out {out} is a folder: give a .png file's path")
    if not table.is_file():
        raise UsageError(f"{table}: no such file (give a table written by circles run --stats)")
    try:
        columns = read_stats(table)
    except (OSError, UnicodeDecodeError, ValueError, IndexError) as error:
        raise UsageError(f"{table}: not a stats table ({error})") from None
    missing = [name for name in observables.COLUMNS if name not in columns]
    if missing:
        raise UsageError(f"{table}: not a stats table (no column {', '.join(missing)})")
    if len(columns["time"]) == 0:
        raise UsageError(f"{table}: the table has no rows yet")
    make_folder(out.parent, f"--out {out}", made)
    return columns

