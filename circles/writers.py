"""Output of a run as writers fired every 1/fps of simulated time.

A run is cut into frame intervals: frames at t_k = k / fps for k = 0 .. frames - 1, and the
interval k ends at t_{k+1} (the last at the run's end). Writers of two kinds take part:

- at each frame instant t_k, with the state then and the stats row of the interval that ends
  there (all NaN rates at t = 0): the video's frames and `trajectory.GSDWriter`;
- at the end of each interval, with its stats row: `StatsWriter`, one CSV row.

`Run` drives a simulation through the intervals and fires them; `stats_rows` gives the rows
from Python without a file. The CLI (`circles run --stats --trajectory`) uses the same.
"""
import math
import time
from pathlib import Path

import numpy as np

from . import observables


def frame_times(duration, fps):
    """The frame instants k / fps, k = 0 .. ceil(duration * fps) - 1, and the run's end: the
    intervals' bounds (a list of frames + 1 times, the last = duration)."""
    frames = max(1, math.ceil(duration * fps - 1e-9))
    return [k / fps for k in range(frames)] + [float(duration)]


def row_of(before, after, sim):
    """The stats row (`observables.interval`) between two `stats()` of `sim`."""
    return observables.interval(before, after, sim.n, sim.box, sim.boundary, float(np.mean(sim._radius)),
                                observables.equal_diameter(sim._radius))


def stats_rows(sim, duration, fps):
    """Advance `sim` by `duration` in intervals of 1/fps and yield the stats row of each
    (`observables.COLUMNS`), at its end: ceil(duration * fps) rows."""
    start = sim.time
    before = sim.stats()
    for end in frame_times(duration, fps)[1:]:
        sim.advance(start + end - sim.time)
        after = sim.stats()
        yield row_of(before, after, sim)
        before = after


def _cell(value):
    """A CSV cell: integers as they are, floats to 17 significant digits, NaN empty."""
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    value = float(value)
    return "" if math.isnan(value) else repr(value)


class StatsWriter:
    """A stats table as CSV: a header of `observables.COLUMNS` (and `hexatic_order` with
    order=True, which the rows must then hold: `Run(order=True)`), then one row per `write`,
    written and flushed whole, so a run stopped at any point leaves whole rows. NaN (the wall
    pressure in a periodic box, rates over an empty interval) is an empty cell. keep=K goes on
    with a table that an earlier run wrote, after its first K rows (`circles run --resume`)."""

    def __init__(self, path, mode="w", order=False, keep=None):
        self.path = Path(path)
        self.columns = observables.COLUMNS + (("hexatic_order",) if order else ())
        self.rows = 0
        self.seconds = 0.0
        if keep is not None:
            self._file = self._continue(int(keep))
            return
        self._file = open(self.path, mode, encoding="utf-8", newline="")
        self._file.write(",".join(self.columns) + "\n")
        self._file.flush()

    def _continue(self, keep):
        """Open a table this writer wrote to go on after its first `keep` rows: what follows
        them (rows of a run that went further, a row cut short by a stop) is cut off."""
        header = ",".join(self.columns)
        with open(self.path, "rb") as file:
            lines = file.read().split(b"\n")
        whole = lines[:-1]  # the last piece has no newline: empty, or a row cut short
        if not whole or whole[0].decode(errors="replace") != header:
            held = whole[0].decode(errors="replace")[:80] if whole else "nothing"
            raise ValueError(f"{self.path} is not the stats table of this run: its header is {held!r}, not that of "
                             f"{'--order ' if 'hexatic_order' in self.columns else ''}--stats")
        if len(whole) - 1 < keep:
            raise ValueError(f"{self.path} holds {len(whole) - 1} rows, fewer than the {keep} the run had written "
                             "by its restart point: it is not this run's table")
        file = open(self.path, "r+", encoding="utf-8", newline="")
        file.truncate(sum(len(line) + 1 for line in whole[:keep + 1]))
        file.seek(0, 2)
        self.rows = keep
        return file

    def write(self, row):
        tick = time.perf_counter()
        self._file.write(",".join(_cell(row[name]) for name in self.columns) + "\n")
        self._file.flush()
        self.rows += 1
        self.seconds += time.perf_counter() - tick

    def close(self):
        self._file.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc_info):
        self.close()
        return False


def read_stats(path):
    """A stats CSV as a dict of float64 arrays by column (empty cells NaN)."""
    with open(path, encoding="utf-8") as file:
        header = file.readline().strip().split(",")
        rows = [line.rstrip("\n").split(",") for line in file if line.strip()]
    return {name: np.array([float(row[k]) if row[k] else math.nan for row in rows]) for k, name in enumerate(header)}


class Run:
    """A simulation advanced through frame intervals (`frame_times`) with writers fired on the
    way: `at_frame` writers' ``write(sim, row, stats)`` at each frame instant (`stats` the
    simulation's `stats()` then, None when no writer needs stats), `at_interval` writers'
    ``write(row)`` at each interval's end. Stats are taken only when a writer needs them.

    Use: ``for k in run: ...`` runs interval by interval (frame k's writers, then the advance
    to the interval's end, then the row), so that a caller can stop between two. order=True
    adds the global hexatic order |psi_6| at each row's end (`circles.order`) as
    ``hexatic_order``. start: the simulated time of frame 0 (the simulation's time now by
    default; a run continued from frame k passes its first start, and goes on with k), and
    `row` the row of the interval that ended now, which frame writers get first."""

    def __init__(self, sim, duration, fps, at_frame=(), at_interval=(), need_stats=None, order=False, start=None,
                 row=None):
        self.sim = sim
        self.times = frame_times(duration, fps)
        self.start = sim.time if start is None else float(start)
        self.at_frame = list(at_frame)
        self.at_interval = list(at_interval)
        self.need_stats = bool(self.at_interval) or any(getattr(w, "wants_row", True) for w in self.at_frame) \
            if need_stats is None else need_stats
        self.order = bool(order)
        self.before = sim.stats() if self.need_stats else None
        self.row = None if not self.need_stats else row if row is not None else self._row(self.before, self.before)
        self.stats_seconds = 0.0

    def _row(self, before, after):
        row = row_of(before, after, self.sim)
        if self.order:
            from .order import hexatic_order, psi6

            row["hexatic_order"] = hexatic_order(psi6(self.sim.state().pos, self.sim.box, self.sim.periodic))
        return row

    @property
    def frames(self):
        return len(self.times) - 1

    def fire_frame(self):
        """The frame writers, with the state now and the row of the interval that ended now."""
        for writer in self.at_frame:
            writer.write(self.sim, self.row, self.before)

    def advance(self, k):
        """Advance to the end of interval k."""
        self.sim.advance(self.start + self.times[k + 1] - self.sim.time)

    def fire_interval(self):
        """Stats at the end of an interval, and the interval writers with its row."""
        if not self.need_stats:
            return
        tick = time.perf_counter()
        after = self.sim.stats()
        self.row = self._row(self.before, after)
        self.before = after
        self.stats_seconds += time.perf_counter() - tick
        for writer in self.at_interval:
            writer.write(self.row)

    def __iter__(self):
        for k in range(self.frames):
            self.fire_frame()
            self.advance(k)
            self.fire_interval()
            yield k
