"""The project's performance targets, judged on the tables of one benchmark run.

    python bench/targets.py [FOLDER ...]      (default: every folder under outputs/bench)

`evaluate(tables, arch)` takes one run of bench.py (its rows as measured, or as read back from its
CSVs) and returns one row per target: what the target asks, what the run measured (medians with
[min, max] over its repeats) and whether it is met: "yes", "no", or "not measured" where the run
left out what the target needs (a --quick or --skip run, a section that failed). A target is
judged on the median of its run, the figure the run reports; no margin is added either way, so a
target whose figure swings across its threshold from run to run (a shared machine) says so in
its [min, max].

bench.py writes this table at the top of its results.md and as targets.csv. This script reads the
CSVs of finished runs and prints each run's table, so that runs made before the table existed,
or on other machines, can be judged the same way. It needs no Taichi.

The targets (all at area fraction 0.3, walls, one radius, default dt, float32; see bench.py):
on a CPU, the discrete scheme at 1e6 makes 40 M circle-steps/s; the event scheme at 1e6 makes
15 M circle-steps/s and 5 M pair collisions/s; at 1e5 a scheme makes 30 times pymunk's
circle-steps/s, side by side in the same run; each scheme's cost per circle-step stays within
1.5 times from 1e4 to 1e6; 1e6 circles place in under 3 s at area fraction 0.5 and under 20 s at
0.8; a 1920x1080 frame of 1e6 circles renders in under 0.1 s; a circle takes at most 200 bytes
at f32 (in arrays, and at the peak resident memory of the largest N); with 1% of the circles 50
times larger a circle-step costs at most 3 times an equal-radii one. On a GPU (--arch gpu): the
discrete scheme at 1e7 makes 5 G circle-steps/s and the event scheme 1 G, and 1e8 circles run.
"""
import csv
import os
import sys

#: The throughput rows the targets read: float32 throughout.
PRECISION = "f32"
#: The N of the speed targets on a CPU.
SPEED_N = 1_000_000
DISCRETE_1E6 = 40e6
EVENT_1E6 = 15e6
EVENT_COLLISIONS_1E6 = 5e6
PEER_RATIO = 30.0
PEER_N = 100_000
FLAT_SIZES = (10_000, 100_000, 1_000_000)
FLATNESS = 1.5
PLACEMENT_N = 1_000_000
PLACEMENT_S = ((0.5, 3.0), (0.8, 20.0))
RENDER_N = 1_000_000
RENDER_S = 0.1
BYTES_PER_CIRCLE = 200.0
SPREAD_COST = 3.0
GPU_N = 10_000_000
GPU_DISCRETE = 5e9
GPU_EVENT = 1e9
GPU_LARGEST_N = 100_000_000

NOT_MEASURED = "not measured"
#: The tables `evaluate` reads, by the names of bench.py's CSV files.
TABLES = ("throughput", "placement", "render", "memory", "spread", "peers")


def _num(row, key):
    """A row's number, whether measured (a float) or read back from a CSV (a string)."""
    return float(row[key])


def _si(v):
    """3 significant digits with an SI prefix: 49.9 M, 4.23 G."""
    for scale, prefix in ((1e9, " G"), (1e6, " M"), (1e3, " k")):
        if abs(v) >= scale:
            return f"{v / scale:.3g}{prefix}"
    return f"{v:.3g}"


def _median_range(row, stem, fmt=_si):
    return (f"{fmt(_num(row, stem + '_median'))} [{fmt(_num(row, stem + '_min'))}, "
            f"{fmt(_num(row, stem + '_max'))}]")


def _power(n):
    """1e4 for 10000."""
    return f"{n:.0e}".replace("e+0", "e").replace("e+", "e")


def _seconds(v):
    return f"{v:.3g} s"


def _met(ok):
    return "yes" if ok else "no"


def _throughput_row(tables, n, scheme):
    for row in tables.get("throughput") or ():
        if int(_num(row, "n")) == n and row["scheme"] == scheme and row["precision"] == PRECISION:
            return row
    return None


def _discrete_1e6(tables):
    d = _throughput_row(tables, SPEED_N, "discrete")
    if d:
        return _median_range(d, "circle_steps_per_s"), _met(_num(d, "circle_steps_per_s_median") >= DISCRETE_1E6)
    return None


def _event_1e6(tables):
    e = _throughput_row(tables, SPEED_N, "event")
    if e:
        speed, collisions = _num(e, "circle_steps_per_s_median"), _num(e, "pair_collisions_per_s")
        return (f"{_median_range(e, 'circle_steps_per_s')} and {collisions / 1e6:.3g} M collisions/s",
                _met(speed >= EVENT_1E6 and collisions >= EVENT_COLLISIONS_1E6))
    return None


def _peer(tables):
    ratios = [r for r in tables.get("peers") or ()
              if r.get("scheme") and r["precision"] == PRECISION and int(_num(r, "n")) == PEER_N]
    if not ratios:
        return None
    measured = "; ".join(f"{r['scheme']} {_num(r, 'circle_steps_ratio'):.3g} times "
                         f"[{_num(r, 'ratio_min'):.3g}, {_num(r, 'ratio_max'):.3g}]" for r in ratios)
    return measured, _met(max(_num(r, "circle_steps_ratio") for r in ratios) >= PEER_RATIO)


def _flatness(tables):
    parts, verdicts = [], []
    for scheme in ("discrete", "event"):
        found = [_throughput_row(tables, n, scheme) for n in FLAT_SIZES]
        if not all(found):
            parts.append(f"{scheme} {NOT_MEASURED}")
            verdicts.append(None)
            continue
        speeds = {n: _num(r, "circle_steps_per_s_median") for n, r in zip(FLAT_SIZES, found)}
        dearest = min(speeds, key=speeds.get)
        cheapest = max(speeds, key=speeds.get)
        ratio = speeds[cheapest] / speeds[dearest]
        parts.append(f"{scheme} {ratio:.2f} ({_power(dearest)} against {_power(cheapest)})")
        verdicts.append(ratio <= FLATNESS)
    if verdicts == [None, None]:
        return None
    return "; ".join(parts), NOT_MEASURED if None in verdicts else _met(all(verdicts))


def _placement(tables):
    placed = {_num(r, "area_fraction"): r for r in tables.get("placement") or () if int(_num(r, "n")) == PLACEMENT_N}
    if not all(f in placed for f, _ in PLACEMENT_S):
        return None
    measured = "; ".join(f"{_median_range(placed[f], 'place_s', _seconds)} at {f}" for f, _ in PLACEMENT_S)
    return measured, _met(all(_num(placed[f], "place_s_median") < limit for f, limit in PLACEMENT_S))


def _render(tables):
    frames = [r for r in tables.get("render") or () if int(_num(r, "n")) == RENDER_N]
    if frames:
        return _median_range(frames[0], "frame_s", _seconds), _met(_num(frames[0], "frame_s_median") < RENDER_S)
    return None


def _memory(tables):
    memory = [r for r in tables.get("memory") or () if r["precision"] == PRECISION]
    if not memory:
        return None
    largest = max(int(_num(r, "n")) for r in memory)
    at_largest = [r for r in memory if int(_num(r, "n")) == largest]
    measured = "; ".join(f"{r['scheme']}: arrays {_num(r, 'array_bytes_per_circle'):.0f} B, peak at "
                         f"{_power(largest)} {_num(r, 'bytes_per_circle'):.0f} B" for r in at_largest)
    return measured, _met(all(max(_num(r, "array_bytes_per_circle"), _num(r, "bytes_per_circle"))
                              <= BYTES_PER_CIRCLE for r in at_largest))


def _spread(tables):
    spreads = tables.get("spread") or ()
    if not spreads:
        return None
    measured = "; ".join(f"{r['scheme']} {_num(r, 'cost_ratio'):.3g} at {_power(int(_num(r, 'n')))}" for r in spreads)
    return measured, _met(all(_num(r, "cost_ratio") <= SPREAD_COST for r in spreads))


def _gpu(tables):
    d = _throughput_row(tables, GPU_N, "discrete")
    e = _throughput_row(tables, GPU_N, "event")
    largest = _throughput_row(tables, GPU_LARGEST_N, "discrete")
    if not (d or e or largest):
        return None
    parts = [f"discrete {_median_range(d, 'circle_steps_per_s')}" if d else f"discrete {NOT_MEASURED}",
             f"event {_median_range(e, 'circle_steps_per_s')}" if e else f"event {NOT_MEASURED}",
             f"1e8: discrete {_median_range(largest, 'circle_steps_per_s')}" if largest else f"1e8 {NOT_MEASURED}"]
    met = NOT_MEASURED
    if d and e and largest:
        met = _met(_num(d, "circle_steps_per_s_median") >= GPU_DISCRETE
                   and _num(e, "circle_steps_per_s_median") >= GPU_EVENT)
    return "; ".join(parts), met


#: (target, judge): judge(tables) gives (measured, met), or None where the run measured nothing of it.
CPU_TARGETS = (
    ("discrete, 1e6 f32: 40 M circle-steps/s", _discrete_1e6),
    ("event, 1e6 f32: 15 M circle-steps/s and 5 M collisions/s", _event_1e6),
    ("1e5 f32: 30 times pymunk's circle-steps/s, side by side", _peer),
    ("cost per circle-step flat within 1.5 times from 1e4 to 1e6", _flatness),
    ("placement of 1e6: 3 s at area fraction 0.5, 20 s at 0.8", _placement),
    ("a 1920x1080 frame of 1e6 circles in 0.1 s", _render),
    ("200 bytes per circle, f32", _memory),
    ("1% of the circles 50 times larger: at most 3 times the equal-radii cost", _spread),
)
GPU_TARGETS = (("one GPU: discrete 5 G and event 1 G circle-steps/s at 1e7; 1e8 runs", _gpu),)


def evaluate(tables, arch="cpu"):
    """[(target, measured, met)] for the run whose tables (a dict: TABLES' names to lists of rows)
    `tables` holds; `arch` "cpu" judges the CPU targets, "gpu" the GPU's."""
    return [(target, *(judge(tables) or (NOT_MEASURED, NOT_MEASURED)))
            for target, judge in (GPU_TARGETS if arch == "gpu" else CPU_TARGETS)]


def markdown(rows):
    """The targets as a markdown table."""
    lines = ["| target | measured | met |", "|---|---|---|"]
    lines += [f"| {target} | {measured} | {met} |" for target, measured, met in rows]
    return "\n".join(lines)


def read_run(folder):
    """(tables, arch) of the run whose CSVs lie in `folder`: arch is "gpu" when its throughput rows
    reach GPU_N, as only a GPU run's do."""
    tables = {}
    for name in TABLES:
        path = os.path.join(folder, name + ".csv")
        if os.path.isfile(path):
            with open(path, newline="") as f:
                tables[name] = list(csv.DictReader(f))
    sizes = [int(_num(r, "n")) for r in tables.get("throughput") or ()]
    return tables, ("gpu" if sizes and max(sizes) >= GPU_N else "cpu")


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    root = os.path.join(os.path.dirname(os.path.abspath(__file__)), os.pardir, "outputs", "bench")
    # By default the kept runs whose CSVs are there (a run kept as results.md alone is left out).
    folders = argv or sorted(os.path.join(root, d) for d in os.listdir(root)
                             if os.path.isfile(os.path.join(root, d, "throughput.csv")))
    status = 0
    for folder in folders:
        if not os.path.isfile(os.path.join(folder, "throughput.csv")):
            print(f"{folder}: no throughput.csv there: give a folder that a run of bench/bench.py wrote",
                  file=sys.stderr)
            status = 2
            continue
        tables, arch = read_run(folder)
        print(f"{os.path.normpath(folder)} ({arch})\n\n{markdown(evaluate(tables, arch))}\n")
    return status


if __name__ == "__main__":
    sys.exit(main())
