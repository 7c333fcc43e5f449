"""Sweeps on a real Dask LocalCluster of two worker processes: the same numbers as a serial run,
whatever the order tasks finish in, when a worker process dies, and when a stopped sweep is
run again; bad sweep files refused before any task.

The worker processes start Taichi themselves and share the offline cache of this process
(TI_OFFLINE_CACHE_FILE_PATH in the environment they inherit).
"""

import csv
import math
import json
import os
import signal
import textwrap

import numpy as np
import pytest

from circles import sweep as sweeps

distributed = pytest.importorskip("distributed")

#: Tens of circles, a short run: a task takes a fraction of a second once the kernels are built.
TINY = """
[scene]
n = 40
radius = 0.05
speed = [1.0, 1.0]
mass = "equal"
boundary = "periodic"
seed = 3

[vary]
area_fraction = [0.1, 0.3, 0.5]

[sweep]
repeats = 2
equilibrate = 0.5
measure = 2.0
blocks = 4
observables = ["compressibility", "collision_rate", "energy_change"]
"""

#: The columns that depend on the simulation only (not task_seconds, a timing).
NUMBERS = [c for c in ("area_fraction", "repeats", "blocks", "compressibility", "compressibility_se",
                       "collision_rate", "collision_rate_se", "energy_change", "energy_change_se",
                       "temperature", "temperature_se", "pair_collisions")]


def write(tmp_path, text, name="sweep.toml"):
    path = tmp_path / name
    path.write_text(textwrap.dedent(text))
    return path


def executed(client):
    """The tasks the workers of `client`'s cluster have run so far."""
    return sum(client.run(lambda dask_worker: dask_worker.state.executed_count).values())


def table(out):
    """{area_fraction: the row's numbers, as written} of out/results.csv."""
    with open(out / "results.csv", newline="") as file:
        return {row["area_fraction"]: [row[c] for c in NUMBERS] for row in csv.DictReader(file)}


def assert_grown_row(phi, got, want):
    """A grown row's numbers (`table`) against a row of all its repeats in one go: the counts
    exactly, the means and standard errors to the round-off of their pairwise update."""
    for column, g, w in zip(NUMBERS, got, want):
        if column in ("area_fraction", "repeats", "blocks", "pair_collisions"):
            assert g == w, (phi, column)
        else:
            assert math.isclose(float(g), float(w), rel_tol=1e-9, abs_tol=1e-24), (phi, column, g, w)


def runs(out):
    """{(area_fraction, repeat): the task's row of out/runs.csv but its seconds}, and the count
    of its rows."""
    with open(out / "runs.csv", newline="") as file:
        rows = list(csv.DictReader(file))
    return {(row["area_fraction"], row["repeat"]): {k: v for k, v in row.items() if k != "task_seconds"}
            for row in rows}, len(rows)


@pytest.fixture(scope="module")
def cluster():
    cluster = sweeps.local_cluster(2)
    client = distributed.Client(cluster)
    yield client
    client.close()
    cluster.close()


@pytest.fixture(scope="module")
def serial(circles_cpu, tmp_path_factory):
    """The tiny sweep run task by task in this process: (sweep, its results folder)."""
    tmp = tmp_path_factory.mktemp("serial")
    sweep = sweeps.read_sweep(write(tmp, TINY))
    sweeps.run_sweep(sweep, tmp / "out")
    return sweep, tmp / "out"


def test_serial_sweep_measures_the_hard_disk_fluid(serial):
    """Z within 5 standard errors (and 10%) of Liu's; energy kept to round-off; every point once."""
    sweep, out = serial
    rows = table(out)
    assert sorted(rows) == ["0.1", "0.3", "0.5"]
    for phi, got, expect, rel, z in sweeps.deviations(sweep, sweeps.load_rows(out, sweep)):
        assert abs(rel) < 0.10 and abs(z) < 5, (phi, got, expect)
    for row in rows.values():
        assert abs(float(row[NUMBERS.index("energy_change")])) < 1e-13


def test_runs_csv_holds_each_task_and_its_point_s_row_is_their_mean(serial):
    """DIR/runs.csv: a row per task with its repeat's seed and its own means; with blocks alike,
    a point's mean is the mean of its tasks' means, and its pair collisions their sum."""
    sweep, out = serial
    held, count = runs(out)
    assert count == 6 and sorted(held) == [(phi, str(r)) for phi in ("0.1", "0.3", "0.5") for r in (0, 1)]
    assert list(next(iter(held.values()))) == [c for c in sweeps.run_columns(sweep) if c != "task_seconds"]
    with open(out / "results.csv", newline="") as file:
        points = {row["area_fraction"]: row for row in csv.DictReader(file)}
    for (phi, repeat), row in held.items():
        assert int(row["seed"]) == sweeps.repeat_seed(3, int(repeat))
    for phi, point in points.items():
        tasks = [held[phi, str(r)] for r in range(2)]
        for name in ("compressibility", "collision_rate", "temperature"):
            assert float(point[name]) == pytest.approx(np.mean([float(t[name]) for t in tasks]), rel=1e-13)
        assert int(point["pair_collisions"]) == sum(int(t["pair_collisions"]) for t in tasks)
    with open(out / "runs.csv", newline="") as file:
        seconds = [float(row["task_seconds"]) for row in csv.DictReader(file)]
    total = sum(float(point["task_seconds"]) for point in points.values())
    assert min(seconds) > 0 and sum(seconds) == pytest.approx(total, abs=0.001 * len(seconds))  # each to 1 ms


@pytest.mark.cluster
def test_local_cluster_gives_the_serial_numbers(serial, cluster, tmp_path):
    sweep, serial_out = serial
    run = sweeps.run_sweep(sweep, tmp_path / "out", client=cluster, threads=1)
    assert run.ran == [0, 1, 2] and run.skipped == []
    assert {r["pid"] for r in run.results.values()} <= set(cluster.run(os.getpid).values())
    assert table(tmp_path / "out") == table(serial_out)
    assert runs(tmp_path / "out") == runs(serial_out)


@pytest.mark.cluster
def test_a_stopped_sweep_run_again_runs_only_the_missing_points(serial, cluster, tmp_path):
    sweep, serial_out = serial
    out = tmp_path / "out"

    def stop(row):
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        sweeps.run_sweep(sweep, out, client=cluster, threads=1, on_row=stop)
    first = table(out)
    assert len(first) == 1
    # A stop while a row was written leaves part of a line: it is dropped, and its point run again.
    with open(out / "results.csv", "a") as file:
        file.write("0.7,2,4,1.5")
    run = sweeps.run_sweep(sweep, out, client=cluster, threads=1)
    done = sorted(json.dumps(sweep.points[i]["area_fraction"]) for i in run.ran)
    assert done == sorted(set(table(serial_out)) - set(first))
    assert len(run.results) == 2 * sweep.repeats
    assert table(out) == table(serial_out)
    again = sweeps.run_sweep(sweep, out, client=cluster, threads=1)
    assert again.ran == [] and again.results == {}


@pytest.mark.cluster
def test_a_worker_killed_mid_sweep_loses_no_point(serial, cluster, tmp_path):
    """The worker busy with a task is killed after the first task ends; the nanny starts a
    new one and the scheduler gives its task to a live worker: every point completes, with the
    serial numbers. Tasks are made long enough (a second or so) to be caught running."""
    sweep, _ = serial
    text = TINY.replace("measure = 2.0", "measure = 60.0").replace("blocks = 4", "blocks = 3")
    longer = sweeps.read_sweep(write(tmp_path, text))
    killed = {}

    def kill(task, result):
        if killed:
            return
        pids = cluster.run(os.getpid)
        busy = [address for address, keys in cluster.processing().items() if keys]
        victim = busy[0]
        killed.update(pid=pids[victim], keys=set(cluster.processing()[victim]))
        os.kill(pids[victim], signal.SIGKILL)

    run = sweeps.run_sweep(longer, tmp_path / "out", client=cluster, threads=1, on_result=kill)
    assert killed["keys"], "no task was running on the killed worker"
    assert len(run.rows) == 3 and len(run.results) == 3 * longer.repeats
    lost = [tuple(int(i) for i in key.rsplit("-", 2)[1:]) for key in killed["keys"]]
    # The scheduler's list may still hold a task that ended as the kill came (its result from the
    # killed process): at least one of them, the one running, ran again on another.
    assert lost and any(run.results[t]["pid"] != killed["pid"] for t in lost)
    serial_out = tmp_path / "serial"
    sweeps.run_sweep(longer, serial_out)
    assert table(tmp_path / "out") == table(serial_out)


#: The tiny sweep with tasks of a few seconds that keep a checkpoint after each block.
CHECKPOINTED = TINY.replace("equilibrate = 0.5", "equilibrate = 3.0").replace("measure = 2.0", "measure = 60.0") \
    .replace("blocks = 4", "blocks = 6\ncheckpoint_every = 1.4")


def test_pieces_cut_the_equilibration_only_with_checkpoints():
    assert sweeps.pieces(3.0, 6.0, 3) == [(3.0, None), (5.0, 0), (7.0, 1), (9.0, 2)]
    assert sweeps.pieces(3.0, 6.0, 3, every=1.4) == [(1.4, None), (2.8, None), (3.0, None), (5.0, 0), (7.0, 1),
                                                     (9.0, 2)]
    assert sweeps.pieces(0.0, 2.0, 2, every=1.0) == [(1.0, 0), (2.0, 1)]
    assert sweeps.pieces(2.0, 1.0, 1, every=1.0) == [(1.0, None), (2.0, None), (3.0, 0)]  # no piece twice
    assert sweeps.pieces(0.5, 1.0, 2) == [(0.5, None), (1.0, 0), (1.5, 1)]


def test_a_task_outside_a_worker_starts_taichi_on_the_cpu_with_the_threads_asked_for():
    """Where no runtime is running: the threads given (at least one), or every core outside a
    Dask worker; a runtime already running is kept. In a process of its own: the runtime it
    starts again would leave the kernels of this process's tests behind."""
    import subprocess
    import sys

    script = textwrap.dedent("""
        import os
        import taichi as ti
        from circles import backend, sweep as sweeps

        asked, start = [], backend.init
        backend.init = lambda *args, **kwargs: (asked.append(args[:1]), start(*args, **kwargs))[1]
        for threads, want in ((None, os.cpu_count() or 1), (3, 3), (0, 1)):
            backend._state["initialized"] = False
            sweeps._ensure_runtime(threads)
            assert backend._state["arch"] == "cpu" and asked[-1] == ("cpu",)  # the CPU asked for, GPU or not
            assert ti.lang.impl.current_cfg().cpu_max_num_threads == want, (threads, want)
        runtime = backend._state["runtime"]
        sweeps._ensure_runtime(5)
        assert backend._state["runtime"] == runtime
        print("checked")
    """)
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0 and done.stdout.split()[-1] == "checked", done.stderr[-2000:]


def test_a_task_that_died_goes_on_from_its_checkpoint_with_the_same_result(circles_cpu, tmp_path, monkeypatch):
    """A task stopped right after its third checkpoint (the process dies: here an exception),
    run again, goes on from that checkpoint, does only the rest, and returns what a task never
    stopped returns; its checkpoint is gone once it ends."""
    from circles import checkpoint

    sweep = sweeps.read_sweep(write(tmp_path, CHECKPOINTED))
    args = (sweep.point_scene(1, 0), sweep.equilibrate, sweep.measure, sweep.blocks, None, sweep.observables)
    path = tmp_path / "task.gsd"
    whole = sweeps.run_task(*args, str(path), sweep.checkpoint_every)
    assert whole["resumed_at"] == 0.0 and not path.exists()

    written = []
    real = checkpoint.write

    def dies_after_the_third(*a, **k):
        real(*a, **k)
        written.append(a[1].time)
        if len(written) == 3:
            raise KeyboardInterrupt

    monkeypatch.setattr(checkpoint, "write", dies_after_the_third)
    with pytest.raises(KeyboardInterrupt):
        sweeps.run_task(*args, str(path), sweep.checkpoint_every)
    monkeypatch.setattr(checkpoint, "write", real)
    # Checkpoints at the equilibration's pieces 1.4 and 2.8, then at the first block's end.
    assert written == [1.4, 2.8, 13.0] and path.exists()
    again = sweeps.run_task(*args, str(path), sweep.checkpoint_every)
    assert again["resumed_at"] == 13.0
    assert json.dumps(again["blocks"], sort_keys=True) == json.dumps(whole["blocks"], sort_keys=True)  # every value, bit for bit (NaN too)
    assert again["pair_collisions"] == whole["pair_collisions"]
    assert not path.exists()
    # A checkpoint of another task is not taken up: it starts from the beginning.
    monkeypatch.setattr(checkpoint, "write", dies_after_the_third)
    written.clear()
    with pytest.raises(KeyboardInterrupt):
        sweeps.run_task(*args, str(path), sweep.checkpoint_every)
    monkeypatch.setattr(checkpoint, "write", real)
    other = sweeps.run_task(sweep.point_scene(1, 1), *args[1:], str(path), sweep.checkpoint_every)
    assert other["resumed_at"] == 0.0


@pytest.mark.cluster
def test_a_worker_killed_mid_task_resumes_the_task_from_its_checkpoint(cluster, tmp_path):
    """The worker running a task is killed once the task has written a checkpoint; the task
    runs again on a live worker from that checkpoint (it simulates less than a whole task) and
    the results equal those of the sweep run in this process without a stop."""
    import threading
    import time

    sweep = sweeps.read_sweep(write(tmp_path, CHECKPOINTED))
    out = tmp_path / "out"
    killed = {}

    def kill_when_a_checkpoint_appears():
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and not killed.get("done"):
            folder = out / sweeps.CHECKPOINTS
            names = [p.name for p in folder.glob("point-*.gsd")] if folder.exists() else []
            for name in names:
                point, repeat = int(name.split("-")[1]), int(name.split("-")[3].split(".")[0])
                for address, keys in cluster.processing().items():
                    if any(key.endswith(f"-{point}-{repeat}") for key in keys):
                        pid = cluster.run(os.getpid)[address]
                        killed.update(pid=pid, task=(point, repeat))
                        os.kill(pid, signal.SIGKILL)
                        return
            time.sleep(0.02)

    watcher = threading.Thread(target=kill_when_a_checkpoint_appears)
    watcher.start()
    try:
        run = sweeps.run_sweep(sweep, out, client=cluster, threads=1)
    finally:
        killed["done"] = True
        watcher.join()
    assert "task" in killed, "no task was caught with a checkpoint"
    result = run.results[killed["task"]]
    assert result["pid"] != killed["pid"] and result["resumed_at"] > 0
    assert not (out / sweeps.CHECKPOINTS).exists()
    serial_out = tmp_path / "serial"
    sweeps.run_sweep(sweep, serial_out)
    assert table(out) == table(serial_out)


# ---- bad sweep files ----------------------------------------------------------------------

@pytest.mark.parametrize("change, words", [
    (("[vary]\n", "[vary]\ncolour = [1, 2]\n"), ["[vary]", "colour"]),
    (("area_fraction = [0.1, 0.3, 0.5]", "area_fraction = []"), ["[vary]", "area_fraction", "non-empty"]),
    (("area_fraction = [0.1, 0.3, 0.5]", "area_fraction = [0.1, 0.95]"), ["area_fraction", "0.95"]),
    (("radius = 0.05", "radius = -0.05"), ["radius", "-0.05"]),
    (("repeats = 2", "repeats = 0"), ["repeats", "0"]),
    (("measure = 2.0", "measure = nan"), ["measure", "nan"]),
    (("blocks = 4", "blocks = 4\nwarmup = 3"), ["[sweep]", "warmup"]),
    (('"energy_change"]', '"entropy"]'), ["observables", "entropy"]),
    (("[vary]\n", "[vary]\nseed = [1, 2]\n"), ["seed", "repeats"]),
    (("n = 40", "n = 40\nbox = [2.0, 2.0]\narea_fraction = 0.2"), ["box", "area_fraction"]),
], ids=["unknown-field", "empty-list", "scene-refuses", "base-refused", "repeats", "nan", "sweep-key",
        "observable", "seed", "box-and-fraction"])
def test_bad_sweep_files_are_refused_before_any_task(tmp_path, capsys, change, words):
    old, new = change
    assert old in TINY
    path = write(tmp_path, TINY.replace(old, new, 1))
    out = tmp_path / "out"
    assert sweeps.main(["sweep", str(path), "--workers", "2", "--out", str(out)]) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and captured.out == "", captured.err
    assert lines[0].startswith("circles: error: ") and str(path) in lines[0]
    for word in words:
        assert word in lines[0]
    assert not out.exists()


OBSERVABLE_NAMES = ("compressibility, collision_rate, energy_change, pressure, wall_pressure, temperature, "
                    "reduced_pressure, hexatic_order")
SCENE_KEYS = ("n, box, radius, speed, mass, boundary, scheme, precision, dt, seed, area_fraction, crystal, start, "
              "species, aspect")
SWEEP_KEYS = "repeats, equilibrate, measure, blocks, observables, checkpoint_every"
OUT_OF_RANGE = "is out of range: give simulated seconds"
FRACTION = "0.1, 0.3, 0.5]"


@pytest.mark.parametrize("old, new, message", [
    ("[vary]\n", "[vary]\ncolour = [1, 2]\n", "[vary] unknown key colour: vary one of the Scene fields n, box, radius, "
     "speed, mass, boundary, scheme, precision, dt, area_fraction, crystal, start, species, aspect"),
    (FRACTION, "]", "[vary] area_fraction = [] must be a non-empty list of values, e.g. area_fraction = [a, b]"),
    ("[" + FRACTION, "0.3", "[vary] area_fraction = 0.3 must be a non-empty list of values, e.g. area_fraction = "
     "[a, b]"),
    (FRACTION, "0.1, 0.3, 0.1]", "[vary] area_fraction lists 0.1 twice: give each value once"),
    (FRACTION, "0.1]\nbox = [[2.0, 2.0]]", "[vary] box and area_fraction are both varied: vary one of them"),
    ("n = 40", "n = 40\nbox = []", "[scene] box = [] must be a pair (W, H)"),
    ("n = 40", "n = 40\nbox = [2.0, -1.0]", "[scene] box = (2.0, -1.0): both sides must be > 0"),
    ("seed = 3\n\n[vary]\narea_fraction = [" + FRACTION, "seed = 3\narea_fraction = 2.0\n[vary]\nbox = [[2.0, 2.0]]",
     "[scene] area_fraction = 2.0 is out of range: give a fraction > 0 and at most the densest packing 0.9069 (below "
     "about 0.7 for a fluid)"),
    ("area_fraction = [" + FRACTION, "", "[vary] is empty: give the fields to vary as lists in a [vary] table, e.g. "
     "area_fraction = [0.1, 0.3]"),
    ("[vary]\n", "[vary]\nseed = [1, 2]\n", "[vary] seed cannot be varied: each repeat has its own seed; set [sweep] "
     "repeats"),
    (FRACTION, "0.1, 0.95]", "the point area_fraction = 0.95: area_fraction = 0.95 is out of range: give a fraction > 0 "
     "and at most the densest packing 0.9069 (below about 0.7 for a fluid)"),
    ("radius = 0.05", "radius = -0.05", "the point area_fraction = 0.1: radius = -0.05: the smallest value -0.05 is "
     "out of range (must be > 0)"),
    ("repeats = 2", "repeats = 0", "[sweep] repeats = 0 must be a whole number from 1 to 1000"),
    ("repeats = 2", "repeats = 1001", "[sweep] repeats = 1001 must be a whole number from 1 to 1000"),
    ("repeats = 2", "repeats = true", "[sweep] repeats = True must be a whole number from 1 to 1000"),
    ("repeats = 2", "repeats = 2.0", "[sweep] repeats = 2.0 must be a whole number from 1 to 1000"),
    ("blocks = 4", "blocks = 0", "[sweep] blocks = 0 must be a whole number from 1 to 10000"),
    ("blocks = 4", "blocks = 10001", "[sweep] blocks = 10001 must be a whole number from 1 to 10000"),
    ("measure = 2.0", "measure = nan", "[sweep] measure = nan must be a finite number of simulated seconds"),
    ("measure = 2.0", "measure = true", "[sweep] measure = True must be a finite number of simulated seconds"),
    ("measure = 2.0", "measure = 0.0", f"[sweep] measure = 0.0 {OUT_OF_RANGE} > 0 and at most 1e+12"),
    ("measure = 2.0", "measure = 1.0000001e12", f"[sweep] measure = 1000000100000.0 {OUT_OF_RANGE} > 0 and at most "
     "1e+12"),
    ("equilibrate = 0.5", "equilibrate = -0.5", f"[sweep] equilibrate = -0.5 {OUT_OF_RANGE} >= 0 and at most 1e+12"),
    ("blocks = 4", "blocks = 4\ncheckpoint_every = 0.0", f"[sweep] checkpoint_every = 0.0 {OUT_OF_RANGE} > 0 and at "
     "most 1e+12"),
    ("blocks = 4", 'blocks = 4\ncheckpoint_every = "1"', "[sweep] checkpoint_every = '1' must be a finite number of "
     "simulated seconds"),
    ("blocks = 4", "blocks = 4\nwarmup = 3", f"[sweep] unknown key(s) warmup: known keys are {SWEEP_KEYS}"),
    ("blocks = 4", "blocks = 4\nwarmup = 3\ncooldown = 1", "[sweep] unknown key(s) cooldown, warmup: known keys are "
     f"{SWEEP_KEYS}"),
    ("n = 40", "n = 40\ncolour = 3\nshade = 4", f"[scene] unknown key(s) colour, shade: known keys are {SCENE_KEYS}"),
    ("[sweep]", "[extra]\nx = 1\n[more]\ny = 2\n[sweep]", "unknown key(s) extra, more: a sweep file has the tables "
     "[scene], [vary], [sweep]"),
    (FRACTION, "0.1, 0.3, 0.3]", "[vary] area_fraction lists 0.3 twice: give each value once"),
    ("area_fraction = [" + FRACTION, "species = [[{count = 40, radius = 0.05}], [{radius = 0.05, count = 40}]]",
     "[vary] species lists [{'count': 40, 'radius': 0.05}] twice: give each value once"),
    (FRACTION, "0.1, 0.95]\nn = [40, 41]", "the point area_fraction = 0.95, n = 40: area_fraction = 0.95 is out of "
     "range: give a fraction > 0 and at most the densest packing 0.9069 (below about 0.7 for a fluid)"),
    ('"energy_change"]', '"entropy"]', f"[sweep] observables: 'entropy' is unknown: use names from {OBSERVABLE_NAMES}"),
    ('["compressibility", "collision_rate", "energy_change"]', "[]", f"[sweep] observables = [] must be a non-empty "
     f"list of names from {OBSERVABLE_NAMES}"),
    ('["compressibility", "collision_rate", "energy_change"]', '"compressibility"', "[sweep] observables = "
     f"'compressibility' must be a non-empty list of names from {OBSERVABLE_NAMES}"),
    ('["compressibility", "collision_rate", "energy_change"]', "[1]", "[sweep] observables = [1] must be a non-empty "
     f"list of names from {OBSERVABLE_NAMES}"),
    ('"collision_rate", "energy_change"]', '"compressibility"]', "[sweep] observables = ['compressibility', "
     "'compressibility'] names one twice: give each once"),
    ('["compressibility", "collision_rate", "energy_change"]', '["wall_pressure"]', "[sweep] observables: "
     "wall_pressure needs walls, and the point's boundary is periodic: drop wall_pressure or use boundary = \"walls\""),
    ("radius = 0.05", "radius = [0.05, 0.06]\n", None),  # accepted: reduced_pressure is not asked for
    ('["compressibility", "collision_rate", "energy_change"]\n', '["reduced_pressure"]\n[scene.x]\n', None),
    ("n = 40", "n = 40\nbox = [2.0, 2.0]\narea_fraction = 0.2", "[scene] box and area_fraction are both given: give "
     "one of them"),
    ("n = 40", "n = 40\ncolour = 3", f"[scene] unknown key(s) colour: known keys are {SCENE_KEYS}"),
    ("seed = 3", "seed = -3", "[scene] seed = -3 must be a whole number >= 0"),
    ("[sweep]", "[extra]\nx = 1\n[sweep]", "unknown key(s) extra: a sweep file has the tables [scene], [vary], "
     "[sweep]"),
    ("speed = [1.0, 1.0]", "speed = [1.0, 1.0]\ndt = 1e-12", "[sweep] equilibrate + measure = 2.5 s is 2.5e+12 steps "
     "of the point's scene, more than 1e10: shorten them or give [scene] a longer dt"),
])
def test_each_refusal_of_a_sweep_file_says_its_key_value_and_fix_word_for_word(tmp_path, old, new, message):
    """Every refusal of read_sweep, each its own line as a user reads it (after the file's name).
    The None rows stand beside a refusal to show that its limit is where it says."""
    assert old in TINY, old
    text = TINY.replace(old, new, 1)
    if new.endswith("[scene.x]\n"):  # reduced_pressure with radii that differ
        text = text.replace("[scene.x]\n", "").replace("radius = 0.05", "radius = [0.05, 0.06]")
        message = ("[sweep] observables: reduced_pressure (beta P d^2) needs equal disks, and the point's radii range "
                   "from 0.05 to 0.06: drop it or give one radius")
    path = write(tmp_path, text)
    if message is None:
        sweeps.read_sweep(path)
        return
    with pytest.raises(sweeps.SweepError) as refused:
        sweeps.read_sweep(path)
    assert str(refused.value) == f"{path}: {message}"


def test_a_sweep_of_more_than_100000_tasks_is_refused_and_one_of_100000_is_not(tmp_path):
    """100 points of n: 100 x 1000 = 100000 tasks pass; 101 points x 991 = 100091 do not."""
    def points(count):
        return TINY.replace("n = 40\n", "").replace("area_fraction = [" + FRACTION, "n = [" + ", ".join(
            str(40 + k) for k in range(count)) + "]")

    assert len(sweeps.read_sweep(write(tmp_path, points(100).replace("repeats = 2", "repeats = 1000"))).points) == 100
    text = points(101)
    path = write(tmp_path, text.replace("repeats = 2", "repeats = 991"))
    with pytest.raises(sweeps.SweepError) as refused:
        sweeps.read_sweep(path)
    assert str(refused.value) == (f"{path}: [vary] and [sweep] repeats make 101 points x 991 repeats = 100091 tasks, "
                                  "more than 100000: split the sweep")


@pytest.mark.parametrize("text, message", [
    ("n = 40\nradius = 0.05\n", "{path} is a scene file (Scene fields at top level), not a sweep file: run it with "
     "circles run, or give a sweep file with the tables [scene], [vary], [sweep]"),
    ("[scene]\nn = 40\n[sweep]\nrepeats = 1\n", "{path}: [vary] is missing: give the fields to vary as lists in a "
     "[vary] table, e.g. area_fraction = [0.1, 0.3]"),
    ("[vary]\nn = [40]\n", "{path}: [scene] is missing: give the base scene's fields in a [scene] table (n, radius, "
     "box or area_fraction, ...)"),
    ("scene = 3\n[vary]\nn = [40]\n", "{path}: scene = 3 must be a table [scene]: give the base scene's fields in a "
     "[scene] table (n, radius, box or area_fraction, ...)"),
    ("vary = [3]\n[scene]\nn = 40\n", "{path}: vary = [3] must be a table [vary]: give the fields to vary as lists in "
     "a [vary] table, e.g. area_fraction = [0.1, 0.3]"),
    ("sweep = 3\n[scene]\nn = 40\n[vary]\nn = [40, 41]\n", "{path}: sweep = 3 must be a table [sweep]: give repeats, "
     "equilibrate, measure, blocks and observables in a [sweep] table"),
    ("[scene]\nn = 40\n[vary]\nn = [40]\n[[scene.circle]]\nx = 1\n", "{path}: [scene] lists its circles "
     "([[scene.circle]]): a sweep varies random scenes; give n, radius and the other Scene fields instead"),
    ("[scene]\nn = 40\n[scene", "{path}: not valid TOML (Cannot declare ('scene',) twice (at end of document))"),
])
def test_a_file_that_is_no_sweep_file_is_refused_word_for_word(tmp_path, text, message):
    path = write(tmp_path, text)
    with pytest.raises(sweeps.SweepError) as refused:
        sweeps.read_sweep(path)
    assert str(refused.value) == message.format(path=path)


def test_a_folder_with_another_sweeps_results_is_refused(serial, tmp_path, capsys):
    sweep, out = serial
    other = write(tmp_path, TINY.replace("measure = 2.0", "measure = 3.0"))
    assert sweeps.main(["sweep", str(other), "--workers", "0", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "another sweep" in err and str(out) in err and len(err.strip().splitlines()) == 1


def test_repeat_seeds_are_distinct_and_fixed_by_the_base_seed():
    seeds = [sweeps.repeat_seed(3, r) for r in range(100)]
    assert len(set(seeds)) == 100 and seeds == [sweeps.repeat_seed(3, r) for r in range(100)]
    assert sweeps.repeat_seed(4, 0) not in seeds


@pytest.mark.cluster
def test_the_command_runs_a_sweep_on_a_local_cluster_and_plots_it(serial, tmp_path, capsys, monkeypatch):
    """`circles sweep` end to end: its own cluster of two workers, the serial numbers, a plot per
    observable, and Liu's deviation said; run again, every point is skipped. On a machine of
    four cores (as the command sees it), each worker runs Taichi on two threads, and the kernel
    note is of the CPU with two threads."""
    from circles import kernel_cache
    from circles.scene import Scene

    sweep, serial_out = serial
    path = write(tmp_path, TINY)
    out = tmp_path / "out"
    monkeypatch.setattr(sweeps.os, "cpu_count", lambda: 4)
    monkeypatch.setattr(kernel_cache, "cache_folder", lambda: str(tmp_path / "cache"))  # this process's list only
    made, real = [], sweeps.local_cluster

    def taichi_threads(dask_worker):  # of a worker that ran a task, and so started Taichi
        import taichi as ti

        return ti.lang.impl.current_cfg().cpu_max_num_threads if dask_worker.state.executed_count else None

    def counted(workers, threads_per_worker=1):  # the cluster made, the tasks its workers ran, their threads
        cluster = real(workers, threads_per_worker)
        close = cluster.close

        def close_counted(*args, **kwargs):
            with distributed.Client(cluster) as client:
                made.append((workers, executed(client), set(client.run(taichi_threads).values()) - {None}))
            return close(*args, **kwargs)

        cluster.close = close_counted
        return cluster

    monkeypatch.setattr(sweeps, "local_cluster", counted)
    assert sweeps.main(["sweep", str(path), "--workers", "2", "--out", str(out)]) == 0
    assert made == [(2, 3 * 2, {2})]  # every task on the cluster the command made, and that cluster closed
    listed = (tmp_path / "cache" / kernel_cache.SEEN).read_text().split()
    assert listed == [kernel_cache.kind_of(Scene.from_dict(sweep.point_scene(0, 0)), "cpu", 2)]
    said = capsys.readouterr().out
    lines = said.splitlines()
    assert lines[0] == "sweep       3 points x 2 repeats on a local cluster of 2 worker processes, 2 threads each"
    assert lines[4].startswith(f"done        3 points run (6 tasks), 0 already in {out / 'results.csv'}, ")
    assert "deviation of Z from Liu's" in said
    assert table(out) == table(serial_out)
    for name in sweep.observables:
        assert (out / f"{name}.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert sweeps.main(["sweep", str(path), "--workers", "0", "--out", str(out)]) == 0
    assert "0 points run (0 tasks), 3 already in" in capsys.readouterr().out


def test_the_command_runs_a_sweep_in_this_process_and_plots_it(serial, tmp_path, capsys):
    """`circles sweep --workers 0`: the tasks one by one here, the serial numbers, a plot per
    observable, Liu's deviation said and the rerun skipping every point."""
    sweep, serial_out = serial
    path = write(tmp_path, TINY)
    out = tmp_path / "out"
    assert sweeps.main(["sweep", str(path), "--workers", "0", "--out", str(out)]) == 0
    said = capsys.readouterr().out
    assert "this process, task by task" in said and "3 points run (6 tasks), 0 already in" in said
    assert said.count("point       area_fraction") == 3
    worst = max(sweeps.deviations(sweep, sweeps.load_rows(out, sweep)), key=lambda d: abs(d[3]))
    assert f"{100 * worst[3]:+.2f}% ({worst[4]:+.1f} standard errors) at area fraction {worst[0]:g}" in said
    assert table(out) == table(serial_out)
    for name in sweep.observables:
        assert (out / f"{name}.png").stat().st_size > 10_000
    assert sweeps.main(["sweep", str(path), "--workers", "0", "--out", str(out)]) == 0
    assert "0 points run (0 tasks), 3 already in" in capsys.readouterr().out


@pytest.mark.cluster
def test_the_command_uses_a_running_scheduler(serial, cluster, tmp_path, capsys):
    """--scheduler ADDRESS: the tasks go to that cluster's workers, Taichi on each worker's own
    thread count, and the numbers are the serial ones."""
    sweep, serial_out = serial
    address = cluster.scheduler.address
    out = tmp_path / "out"
    before = executed(cluster)
    assert sweeps.main(["sweep", str(write(tmp_path, TINY)), "--scheduler", address, "--out", str(out)]) == 0
    assert executed(cluster) - before == 3 * 2  # every task on that cluster, not here or on a cluster of its own
    said = capsys.readouterr().out.splitlines()
    assert said[0] == f"sweep       3 points x 2 repeats on the Dask scheduler at {address}"
    assert said[4].startswith(f"done        3 points run (6 tasks), 0 already in {out / 'results.csv'}, ")
    assert table(out) == table(serial_out)


# ---- statistics and reruns, against numbers worked out here -------------------------------

def test_a_rerun_runs_exactly_the_points_results_csv_lacks(serial, tmp_path):
    """A folder whose results.csv holds the first and last points but not the middle one (as a
    stop can leave with tasks finishing out of order): the rerun runs the middle point alone,
    and the table ends as the serial one."""
    import shutil

    sweep, serial_out = serial
    out = tmp_path / "out"
    shutil.copytree(serial_out, out)
    with open(out / "results.csv", newline="") as file:
        rows = list(csv.reader(file))
    header, body = rows[0], rows[1:]
    kept = [row for row in body if row[header.index("area_fraction")] != "0.3"]
    assert len(kept) == 2
    with open(out / "results.csv", "w", newline="") as file:
        csv.writer(file, lineterminator="\n").writerows([header, *kept])
    run = sweeps.run_sweep(sweep, out)
    assert run.ran == [1] and run.skipped == [0, 2]
    assert sorted(run.results) == [(1, r) for r in range(sweep.repeats)]
    assert table(out) == table(serial_out)
    assert b"\r" not in (out / "results.csv").read_bytes()  # lines end in \n alone, on every system


def same(a, b):
    """Equal results, NaN (the wall pressure of a periodic box) equal to NaN."""
    return json.dumps(a, sort_keys=True) == json.dumps(b, sort_keys=True)


def stop_after(count):
    """An on_result that stops the run (as Ctrl-C does) when `count` tasks have ended, and the
    results it saw."""
    seen = {}

    def on_result(task, result):
        seen[task] = result
        if len(seen) == count:
            raise KeyboardInterrupt

    return on_result, seen


def test_a_sweep_stopped_mid_point_keeps_its_finished_tasks_and_the_rerun_takes_them(serial, tmp_path):
    """Stopped after three tasks: point 0 has its row, and the result of point 1's first repeat
    waits in DIR/tasks/ under its own name. The rerun takes it (the same result, seconds and
    all: not run again), runs the three others, gives the serial table, and leaves no tasks/."""
    sweep, serial_out = serial
    out = tmp_path / "out"
    on_result, seen = stop_after(3)
    with pytest.raises(KeyboardInterrupt):
        sweeps.run_sweep(sweep, out, on_result=on_result)
    assert list(table(out)) == ["0.1"]
    assert os.listdir(out / sweeps.TASKS) == [os.path.basename(sweeps.task_path(out, sweep, 1, 0))]
    assert same(sweeps.kept_task(out, sweep, 1, 0), seen[1, 0])
    # A stop raised as the result that ends a point comes: its row was written before.
    on_result, _ = stop_after(2)
    with pytest.raises(KeyboardInterrupt):
        sweeps.run_sweep(sweep, tmp_path / "two", on_result=on_result)
    assert list(table(tmp_path / "two")) == ["0.1"] and os.listdir(tmp_path / "two" / sweeps.TASKS) == []
    ran = []
    run = sweeps.run_sweep(sweep, out, on_result=lambda task, result: ran.append(task))
    assert run.kept == [(1, 0)] and same(run.results[1, 0], seen[1, 0])
    assert ran == [(1, 0), (1, 1), (2, 0), (2, 1)] and run.ran == [1, 2]
    assert table(out) == table(serial_out)
    assert runs(out) == runs(serial_out)  # the kept task's row once
    assert not (out / sweeps.TASKS).exists()
    # A stop between a point's row and the removal of its tasks' files: the next run removes them.
    sweeps.keep_task(out, sweep, 2, 1, run.results[2, 1])
    again = sweeps.run_sweep(sweep, out)
    assert again.ran == [] and again.kept == [] and not (out / sweeps.TASKS).exists()


def test_a_kept_task_is_taken_only_by_its_own_task_of_its_own_sweep(serial, tmp_path):
    """A task file cut short, of another task, or of another sweep is not taken: that task runs
    again. The file is named by the task's scene, not its point's number: with a value added
    before it in [vary], the point (now the third) still finds its own result, and the same
    sweep file with its [scene] written in another order names it alike. The file holds the
    task's scene, so that a person can tell which task it is."""
    sweep, serial_out = serial
    out = tmp_path / "out"
    on_result, seen = stop_after(3)
    with pytest.raises(KeyboardInterrupt):
        sweeps.run_sweep(sweep, out, on_result=on_result)
    path = sweeps.task_path(out, sweep, 1, 0)
    whole = open(path).read()
    assert json.loads(whole)["scene"] == {**sweep.scene, "area_fraction": 0.3, "seed": sweep.point_scene(1, 0)["seed"]}
    reordered = sweeps.read_sweep(write(tmp_path, TINY.replace("n = 40\n", "").replace("seed = 3\n", "seed = 3\nn = 40\n"),
                                        "reordered.toml"))
    assert list(reordered.scene) != list(sweep.scene) and reordered.identity() == sweep.identity()
    assert sweeps.task_path(out, reordered, 1, 0) == path
    wider = sweeps.read_sweep(write(tmp_path, TINY.replace("[0.1, 0.3, 0.5]", "[0.05, 0.1, 0.3, 0.5]"), "wider.toml"))
    assert sweeps.task_path(out, wider, 2, 0) == path and same(sweeps.kept_task(out, wider, 2, 0), seen[1, 0])
    assert sweeps.task_path(out, sweep, 1, 1) != path
    for broken in (whole[:-1], whole.replace('"repeat": 0', '"repeat": 1'), "[]",
                   whole.replace(sweeps._fingerprint(sweep), "0" * 64)):
        with open(path, "w") as file:
            file.write(broken)
        assert sweeps.kept_task(out, sweep, 1, 0) is None, broken[-80:]
    run = sweeps.run_sweep(sweep, out)
    assert run.kept == [] and len(run.results) == 4
    assert table(out) == table(serial_out)


@pytest.mark.cluster
def test_a_sweep_stopped_on_a_cluster_runs_again_only_the_tasks_not_done(serial, cluster, tmp_path):
    """On the local cluster: stopped after three tasks ended, the rerun takes the result waiting
    (its own seconds and process: not run again), runs the others, and gives the serial table."""
    sweep, serial_out = serial
    out = tmp_path / "out"
    on_result, seen = stop_after(3)
    with pytest.raises(KeyboardInterrupt):
        sweeps.run_sweep(sweep, out, client=cluster, threads=1, on_result=on_result)
    with_row = {p for p in range(3) if all((p, r) in seen for r in range(2))}
    waiting = sorted(task for task in seen if task[0] not in with_row)
    assert len(with_row) == 1 and len(waiting) == 1
    run = sweeps.run_sweep(sweep, out, client=cluster, threads=1)
    assert run.kept == waiting and same(run.results[waiting[0]], seen[waiting[0]])
    assert len(run.results) == 4
    assert table(out) == table(serial_out)


def test_more_repeats_run_only_the_new_ones_and_rewrite_each_row(serial, tmp_path, capsys):
    """The tiny sweep done with two repeats, run again with four and a point added: only repeats
    2 and 3 of each point done run, and each row is written anew with all four, as a run of four
    repeats in one go gives (the means and standard errors to round-off, the rest exactly); the
    new point's row is appended after the rewritten ones, in the file's own line ends. Stopped
    after one new task, the rows of two repeats stay whole and the task waits in DIR/tasks/.
    Fewer repeats than the rows hold are refused before any work."""
    import shutil

    sweep, serial_out = serial
    out = tmp_path / "out"
    shutil.copytree(serial_out, out)
    four = sweeps.read_sweep(write(tmp_path, TINY.replace("repeats = 2", "repeats = 4")
                                   .replace("[0.1, 0.3, 0.5]", "[0.1, 0.3, 0.5, 0.4]"), "four.toml"))
    whole = tmp_path / "whole"
    sweeps.run_sweep(four, whole)
    on_result, seen = stop_after(1)
    with pytest.raises(KeyboardInterrupt):
        sweeps.run_sweep(four, out, on_result=on_result)
    assert table(out) == table(serial_out) and list(seen) == [(0, 2)]
    ran = []
    run = sweeps.run_sweep(four, out, on_result=lambda task, result: ran.append(task))
    assert run.kept == [(0, 2)] and run.ran == [0, 1, 2, 3]
    assert ran == [(0, 2), (0, 3), (1, 2), (1, 3), (2, 2), (2, 3), (3, 0), (3, 1), (3, 2), (3, 3)]
    grown, expect = table(out), table(whole)
    assert sorted(grown) == sorted(expect) and list(grown)[-1] == "0.4"
    assert (out / "results.csv").read_bytes().count(b"\n") == 5 and b"\r" not in (out / "results.csv").read_bytes()
    for phi, numbers in expect.items():
        assert_grown_row(phi, grown[phi], numbers)
    assert sweeps.run_sweep(four, out).ran == [] and not (out / sweeps.TASKS).exists()
    assert runs(out) == runs(whole)
    before = (out / "results.csv").read_bytes()
    assert sweeps.main(["sweep", str(write(tmp_path, TINY, "two.toml")), "--workers", "0", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert "4 repeats" in err and "repeats = 4" in err and "two.toml" in err and len(err.splitlines()) == 1
    assert (out / "results.csv").read_bytes() == before
    six = write(tmp_path, TINY.replace("repeats = 2", "repeats = 6").replace("[0.1, 0.3, 0.5]", "[0.1, 0.3, 0.5, 0.4]"),
                "six.toml")
    assert sweeps.main(["sweep", str(six), "--workers", "0", "--out", str(out)]) == 0
    assert f"done        4 points run (8 tasks), 0 already in {out / 'results.csv'}, " in capsys.readouterr().out


def test_one_point_grows_alone_from_a_file_that_lists_only_its_values(serial, tmp_path):
    """A copy of the tiny sweep whose [vary] lists only 0.3, with four repeats, run into the
    folder of the three points: only 0.3's repeats 2 and 3 run, its row is written anew in its
    place (as four repeats in one go give it) and the other rows stay as they were, byte for
    byte. The whole file with four repeats then runs only the other points' new repeats."""
    import shutil

    sweep, serial_out = serial
    out = tmp_path / "out"
    shutil.copytree(serial_out, out)
    before = (out / "results.csv").read_text().splitlines()
    alone = TINY.replace("repeats = 2", "repeats = 4").replace("[0.1, 0.3, 0.5]", "[0.3]")
    ran = []
    run = sweeps.run_sweep(sweeps.read_sweep(write(tmp_path, alone, "alone.toml")), out,
                           on_result=lambda task, result: ran.append(task))
    assert run.ran == [0] and ran == [(0, 2), (0, 3)]
    after = (out / "results.csv").read_text().splitlines()
    assert len(after) == 4 and after[0] == before[0] and after[1] == before[1] and after[3] == before[3]
    assert after[2] != before[2] and after[2].startswith("0.3,4,")
    whole = tmp_path / "whole"
    sweeps.run_sweep(sweeps.read_sweep(write(tmp_path, alone, "whole.toml")), whole)
    assert_grown_row("0.3", table(out)["0.3"], table(whole)["0.3"])
    ran.clear()
    four = sweeps.read_sweep(write(tmp_path, TINY.replace("repeats = 2", "repeats = 4"), "four.toml"))
    assert sweeps.run_sweep(four, out, on_result=lambda task, result: ran.append(task)).ran == [0, 2]
    assert ran == [(0, 2), (0, 3), (2, 2), (2, 3)]
    assert list(table(out)) == ["0.1", "0.3", "0.5"] and {row[1] for row in table(out).values()} == {"4"}


def test_pooled_parts_have_the_mean_and_standard_error_of_all_their_samples():
    rng = np.random.default_rng(5)
    for sizes in ((1, 4), (7, 3), (40, 1), (12, 12), (3, 5, 1, 9), (2, 3), (1, 1)):
        parts = [rng.normal(9.0 + 0.1 * i, 0.3, size) for i, size in enumerate(sizes)]
        mean, se = sweeps.pooled([(p.size, float(np.mean(p)), float(np.std(p, ddof=1) / math.sqrt(p.size))
                                   if p.size > 1 else math.nan) for p in parts])
        every = np.concatenate(parts)
        assert math.isclose(mean, float(np.mean(every)), rel_tol=1e-13)
        assert math.isclose(se, float(np.std(every, ddof=1) / math.sqrt(every.size)), rel_tol=1e-11)
    assert sweeps.pooled([(1, 2.5, math.nan)]) == (2.5, pytest.approx(math.nan, nan_ok=True))


def test_a_folder_whose_sweep_json_names_its_repeats_is_the_same_sweep(serial, tmp_path):
    """Folders written when the repeats were part of a sweep's identity (sweep.json holds them,
    and a fingerprint with them) are still this sweep's: a rerun skips their points."""
    import hashlib
    import shutil

    sweep, serial_out = serial
    out = tmp_path / "out"
    shutil.copytree(serial_out, out)
    old = {**sweep.identity(), "repeats": 2}
    digest = hashlib.sha256(json.dumps(old, sort_keys=True).encode()).hexdigest()
    (out / "sweep.json").write_text(json.dumps({"fingerprint": digest, **old}))
    assert sweeps.run_sweep(sweep, out).ran == [] and table(out) == table(serial_out)


def test_a_rerun_over_an_empty_results_csv_writes_its_header_and_every_point(serial, tmp_path):
    """results.csv of no bytes beside the sweep's sweep.json (a stop as the file was made): the
    rerun writes the header once and runs every point, and the table ends as the serial one."""
    import shutil

    sweep, serial_out = serial
    out = tmp_path / "out"
    shutil.copytree(serial_out, out)
    (out / "results.csv").write_bytes(b"")
    run = sweeps.run_sweep(sweep, out)
    assert run.ran == [0, 1, 2] and run.skipped == []
    lines = (out / "results.csv").read_text().splitlines()
    assert lines[0] == ",".join(sweeps.columns(sweep)) and len(lines) == 4
    assert table(out) == table(serial_out)


def test_a_points_mean_and_standard_error_over_every_block_of_every_repeat(serial):
    sweep, _ = serial
    blocks = {"compressibility": [[1.0, 2.0], [3.0, 4.0]], "collision_rate": [[5.0, 5.0], [5.0, 9.0]],
              "energy_change": [[0.0, 0.0], [0.0, 0.0]], "temperature": [[0.5, 0.5], [0.5, 0.5]]}
    results = [{"blocks": {k: v[r] for k, v in blocks.items()}, "pair_collisions": 10 + r, "seconds": 1.0}
               for r in range(2)]
    row = sweeps.point_row(sweep, 0, results)
    # Four blocks 1, 2, 3, 4: mean 2.5, sample variance 5/3, standard error sqrt(5/3) / 2.
    assert float(row["compressibility"]) == 2.5
    assert float(row["compressibility_se"]) == pytest.approx(math.sqrt(5 / 3) / 2, rel=1e-14)
    # 5, 5, 5, 9: mean 6, squared deviations 1 + 1 + 1 + 9 = 12, sample variance 4, standard
    # error 2 / 2 (with N in place of N - 1 it would be sqrt(3) / 2).
    assert float(row["collision_rate"]) == 6.0
    assert float(row["collision_rate_se"]) == pytest.approx(1.0, rel=1e-14)
    assert float(row["temperature_se"]) == 0.0 and row["pair_collisions"] == 21


def test_each_repeat_of_a_point_runs_its_own_seed(serial):
    """The seed of repeat r is numpy's SeedSequence of (base seed, r), worked out here, and the
    repeats' runs differ."""
    import numpy as np

    sweep, _ = serial
    expect = [int(np.random.SeedSequence([3, r]).generate_state(1, dtype=np.uint32)[0]) for r in range(3)]
    for point in range(len(sweep.points)):
        assert [sweep.point_scene(point, r)["seed"] for r in range(3)] == expect
    first, second = (sweeps.run_task(sweep.point_scene(0, r), 0.0, 0.5, 1) for r in range(2))
    assert first["pair_collisions"] != second["pair_collisions"] or \
        first["blocks"]["compressibility"] != second["blocks"]["compressibility"]


def test_a_sweep_keeps_the_reduced_pressure_and_the_hexatic_order_when_asked(tmp_path):
    text = TINY.replace('observables = ["compressibility", "collision_rate", "energy_change"]',
                        'observables = ["compressibility", "reduced_pressure", "hexatic_order"]')
    sweep = sweeps.read_sweep(write(tmp_path, text.replace("area_fraction = [0.1, 0.3, 0.5]", "area_fraction = [0.5]")))
    result = sweeps.run_task(sweep.point_scene(0, 0), 0.5, 2.0, 4, kept=sweep.observables)
    blocks = result["blocks"]
    # beta P d^2 = 4 eta Z / pi for each block (radius 0.05, area fraction 0.5).
    for z, reduced in zip(blocks["compressibility"], blocks["reduced_pressure"]):
        assert reduced == pytest.approx(4 * 0.5 * z / math.pi, rel=1e-9)
    assert len(blocks["hexatic_order"]) == 4 and all(0 <= q < 0.5 for q in blocks["hexatic_order"])  # a fluid
    plain = sweeps.run_task(sweep.point_scene(0, 0), 0.5, 2.0, 4)
    assert plain["blocks"]["hexatic_order"] == []  # not measured unless asked
    mixed = text.replace("radius = 0.05", "radius = [0.04, 0.05]")
    with pytest.raises(sweeps.SweepError, match="reduced_pressure .* equal disks"):
        sweeps.read_sweep(write(tmp_path, mixed, "mixed.toml"))


def test_the_reduced_pressures_plot_draws_each_start_beside_the_published_series(tmp_path):
    """A sweep of two starts (two groups of points) keeping the reduced pressure of Li et al.'s
    N = 870 box: the plot has a line of points per start and the published series once."""
    text = ('[scene]\ncrystal = [29, 30]\nradius = 0.5\nmass = "equal"\nboundary = "periodic"\n\n'
            '[vary]\narea_fraction = [0.670, 0.675]\nstart = ["fluid", "crystal"]\n\n'
            '[sweep]\nrepeats = 1\nequilibrate = 0.1\nmeasure = 0.2\nblocks = 2\nobservables = ["reduced_pressure"]\n')
    sweep = sweeps.read_sweep(write(tmp_path, text))
    sweeps.run_sweep(sweep, tmp_path / "out")
    (path,) = sweeps.plot_sweep(sweep, tmp_path / "out")
    assert path == str(tmp_path / "out" / "reduced_pressure.png") and os.path.getsize(path) > 10_000
    rows = sweeps.load_rows(tmp_path / "out", sweep)
    fig = sweeps.sweep_figure(sweep, rows, "reduced_pressure")
    (ax,) = fig.axes
    labels = ax.get_legend_handles_labels()[1]
    assert labels == ['start "fluid"', "Li2022 (ECMC), N = 870", 'start "crystal"']  # the published series once
    assert ax.get_yscale() == "linear" and ax.get_ylabel() == sweeps.LABELS["reduced_pressure"]


def test_the_sweep_command_is_described_in_the_command_lines_help(capsys):
    """`circles --help` lists the sweep command, and `circles sweep --help` its arguments."""
    from circles import cli

    import re

    assert cli.main(["--help"]) == 0
    assert re.search(r"^ +sweep +run many scenes on Dask and measure each$", capsys.readouterr().out, re.M)
    assert cli.main(["sweep", "--help"]) == 0
    shown = capsys.readouterr().out
    assert re.search(r"^usage: circles sweep \[-h\] .*\n +SWEEP\.toml\n", shown, re.M)  # the file named as one
    assert re.search(r"^  SWEEP\.toml +sweep file: \[scene\], \[vary\] and \[sweep\] tables$", shown, re.M)
    text = " ".join(shown.split())
    for words in ("sweep file: [scene], [vary] and [sweep] tables", sweeps.DESCRIPTION.split(".")[0],
                  "--workers N worker processes of the local cluster (default: one per core; 0 runs the tasks one by "
                  "one in this process, without Dask)", "--scheduler ADDRESS the address of a running Dask scheduler",
                  "--out DIR folder for results.csv and the plots (default outputs/SWEEP, after the file's name)"):
        assert " ".join(words.split()) in text, words


@pytest.mark.parametrize("cores, workers, threads, words", [
    (2, 2, 1, "a local cluster of 2 worker processes, 1 thread each"),
    (2, 1, 2, "a local cluster of 1 worker process, 2 threads each"),
    (16, 3, 5, "a local cluster of 3 worker processes, 5 threads each"),
    (1, 4, 1, "a local cluster of 4 worker processes, 1 thread each"),
    (1, 1, 1, "a local cluster of 1 worker process, 1 thread each"),
])
def test_a_local_cluster_shares_out_the_cores_and_says_so(cores, workers, threads, words):
    assert sweeps.worker_threads(cores, workers) == threads
    assert sweeps.cluster_words(workers, threads) == words


def test_a_local_cluster_has_the_workers_asked_for_each_a_process_of_one_thread():
    import logging

    cluster = sweeps.local_cluster(1)  # one thread by default; Dask alone would make a worker per core here
    try:
        client = distributed.Client(cluster)
        info = client.scheduler_info()
        (address, worker), = info["workers"].items()
        assert worker["nthreads"] == 1
        assert client.run(os.getpid)[address] != os.getpid()  # a process of its own
        assert cluster.dashboard_link and ":8787" not in cluster.dashboard_link  # a free port, not the default
        levels = client.run(lambda: [h.level for h in logging.getLogger("distributed").handlers])[address]
        assert levels and set(levels) == {logging.ERROR}  # quiet workers: no warnings of theirs on the terminal
        client.close()
    finally:
        cluster.close()


# ---- the command's words and the theory it compares with, exactly ----------------------------

def test_the_command_says_what_it_ran_line_by_line(serial, tmp_path, capsys):
    """Every line `circles sweep --workers 0` prints, word for word (numbers as the rows hold
    them), and the rerun's."""
    import re

    sweep, serial_out = serial
    path = write(tmp_path, TINY)
    out = tmp_path / "out"
    assert sweeps.main(["sweep", str(path), "--workers", "0", "--out", str(out)]) == 0
    lines = capsys.readouterr().out.splitlines()
    rows = sweeps.load_rows(out, sweep)
    points = [f"point       area_fraction {values['area_fraction']}: " + ", ".join(
        f"{n} {float(row[n]):.4g} +- {float(row[n + '_se']):.2g}" for n in sweep.observables) for values, row in rows]
    worst = max(sweeps.deviations(sweep, rows), key=lambda d: abs(d[3]))
    assert lines[0] == "sweep       3 points x 2 repeats on this process, task by task"
    assert lines[1:4] == points
    assert re.fullmatch(rf"done        3 points run \(6 tasks\), 0 already in {re.escape(str(out / 'results.csv'))}, \d+\.\d s",
                        lines[4])
    assert lines[5] == "plots       " + ", ".join(str(out / f"{n}.png") for n in sweep.observables)
    assert lines[6] == (f"liu         largest deviation of Z from Liu's: {100 * worst[3]:+.2f}% ({worst[4]:+.1f} "
                        f"standard errors) at area fraction {worst[0]:g}")
    assert len(lines) == 7
    assert sweeps.main(["sweep", str(path), "--workers", "0", "--out", str(out)]) == 0
    again = capsys.readouterr().out.splitlines()
    assert again[0] == lines[0] and again[2:] == lines[5:]
    assert re.fullmatch(rf"done        0 points run \(0 tasks\), 3 already in {re.escape(str(out / 'results.csv'))}, \d+\.\d s",
                        again[1])


def test_the_command_puts_results_under_outputs_by_default(serial, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    path = write(tmp_path, TINY, name="tiny.sweep.toml")
    assert sweeps.main(["sweep", str(path), "--workers", "0"]) == 0
    assert (tmp_path / "outputs" / "tiny.sweep" / "results.csv").exists()
    assert "already in outputs/tiny.sweep/results.csv" in capsys.readouterr().out


@pytest.mark.parametrize("args, words", [
    (["--workers", "-1"], "--workers -1 must be from 0 (no Dask: this process) to 4096"),
    (["--workers", "4097"], "--workers 4097 must be from 0 (no Dask: this process) to 4096"),
    (["--out", "FILE"], "--out FILE is a file: give a folder"),
    (["--workers", "4096", "--out", "FILE"], "--out FILE is a file: give a folder"),  # 4096 workers may be asked for
    (["--workers", "4097", "--out", "FILE"], "--workers 4097 must be from 0 (no Dask: this process) to 4096"),
])
def test_the_command_refuses_bad_arguments_in_one_line(tmp_path, capsys, args, words):
    path = write(tmp_path, TINY)
    (tmp_path / "file").write_text("x")
    args = [str(tmp_path / "file") if a == "FILE" else a for a in args]
    words = words.replace("FILE", str(tmp_path / "file"))
    assert sweeps.main(["sweep", str(path), *args]) == 2
    assert capsys.readouterr().err == f"circles: error: {words}\n"


@pytest.mark.parametrize("workers", [["--workers", "1"], ["--workers", "2"], []])
def test_the_command_without_dask_says_how_to_get_it(tmp_path, capsys, monkeypatch, workers):
    import builtins

    real = builtins.__import__

    def no_dask(name, *args, **kwargs):
        if name == "distributed":
            raise ImportError("no distributed")
        return real(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_dask)
    assert sweeps.main(["sweep", str(write(tmp_path, TINY)), *workers, "--out", str(tmp_path / "o")]) == 2
    assert capsys.readouterr().err == ("circles: error: circles sweep runs its tasks on Dask, which is not installed: "
                                       "pip install 'circles-sim[sweep]', or give --workers 0 to run them one by one "
                                       "here\n")
    assert sweeps.main(["sweep", "--help"]) == 0
    assert capsys.readouterr().out.startswith("usage: circles sweep ")


def test_theory_gives_liu_and_enskog_for_equal_disks_in_a_periodic_box():
    """Liu's Z and Enskog's rate at the point, with the density and mass worked out here; none
    for several radii, walls, or a varied box; the published pressure where one exists."""
    from circles.theory import enskog_rate, liu_z

    sweep = sweeps.sweep_from_dict(tomllib_loads(TINY))
    r, eta, kT = 0.05, 0.3, 0.7
    rho = eta / (math.pi * r * r)  # n circles of area pi r^2 fill eta of the box
    found = sweeps.theory(sweep, {"area_fraction": eta}, {"temperature": str(kT)})
    assert found["compressibility"] == pytest.approx(liu_z(eta), rel=1e-12)  # the box's area fraction, to round-off
    assert found["collision_rate"] == pytest.approx(enskog_rate(eta, rho, 2 * r, kT, 1.0), rel=1e-12)
    assert set(found) == {"compressibility", "collision_rate"}
    for mass, m in (("radius", r), ("area", math.pi * r * r)):
        other = sweeps.sweep_from_dict(tomllib_loads(TINY.replace('mass = "equal"', f'mass = "{mass}"')))
        rate = sweeps.theory(other, {"area_fraction": eta}, {"temperature": str(kT)})["collision_rate"]
        assert rate == pytest.approx(enskog_rate(eta, rho, 2 * r, kT, m), rel=1e-12)
    for change in (("radius = 0.05", "radius = [0.04, 0.05]"), ('boundary = "periodic"', 'boundary = "walls"')):
        assert sweeps.theory(sweeps.sweep_from_dict(tomllib_loads(TINY.replace(*change))), {"area_fraction": eta},
                             {"temperature": "1"}) == {}
    boxes = sweeps.sweep_from_dict(tomllib_loads(TINY.replace("area_fraction = [0.1, 0.3, 0.5]",
                                                              "box = [[2.0, 2.0], [3.0, 3.0]]")))
    assert sweeps.theory(boxes, {"box": [2.0, 2.0]}, {"temperature": "1"}) == {}
    # The melting sweep's system: Li et al.'s event-chain value at 0.698, N = 870 (circles/data).
    melting = sweeps.read_sweep("scenes/melting_sweep.toml")
    published = sweeps.theory(melting, {"area_fraction": 0.698, "start": "fluid"}, {"temperature": "1"})
    li = [p for p in __import__("circles.reference", fromlist=["x"]).pressures(n=870) if p.eta == 0.698]
    assert published["reduced_pressure"] == li[0].beta_p_d2 and published["reduced_pressure_se"] == li[0].se
    assert 9.0 < published["reduced_pressure"] < 9.3


def test_deviations_are_relative_and_in_standard_errors():
    sweep = sweeps.sweep_from_dict(tomllib_loads(TINY))
    from circles.theory import liu_z

    rows = [({"area_fraction": 0.3}, {"compressibility": "2.0", "compressibility_se": "0.05", "temperature": "1"}),
            ({"area_fraction": 0.5}, {"compressibility": "4.0", "compressibility_se": "0", "temperature": "1"})]
    (a, got, want, rel, sigmas), (b, *_, nan) = sweeps.deviations(sweep, rows)
    assert (a, got, b) == (0.3, 2.0, 0.5) and want == pytest.approx(liu_z(0.3), rel=1e-12)
    assert rel == 2.0 / want - 1.0 and sigmas == (2.0 - want) / 0.05 and math.isnan(nan)
    assert sweeps.deviations(sweep, rows, "pressure") == []
    # A row without the observable is passed over, and the rows after it are still compared.
    assert [d[0] for d in sweeps.deviations(sweep, [({"area_fraction": 0.1}, {"temperature": "1"}), *rows])] == \
        [0.3, 0.5]
    # No theory (a varied box): nothing to compare, whatever the rows hold.
    boxes = sweeps.sweep_from_dict(tomllib_loads(TINY.replace("area_fraction = [0.1, 0.3, 0.5]",
                                                              "box = [[2.0, 2.0], [3.0, 3.0]]")))
    assert sweeps.deviations(boxes, [({"box": [2.0, 2.0]}, rows[0][1])]) == []


def test_the_published_series_is_drawn_with_its_source(tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from circles import reference

    melting = sweeps.read_sweep("scenes/melting_sweep.toml")
    fig, ax = plt.subplots()
    sweeps._plot_published(ax, melting, {"area_fraction": 0.698, "start": "fluid"})
    li = reference.series(870, 29 / (30 * math.sqrt(3) / 2))
    (line,) = ax.get_lines()
    assert ax.get_legend_handles_labels()[1] == [f"{li[0].source} ({li[0].method}), N = 870"]
    assert list(line.get_xdata()) == [p.eta for p in li] and list(line.get_ydata()) == [p.beta_p_d2 for p in li]
    assert line.get_color() == "0.3" and line.get_linewidth() == 1 and line.get_linestyle() == "-"
    bars = ax.containers[0].lines[2][0].get_segments()
    assert [seg[1][1] - seg[0][1] for seg in bars] == pytest.approx([2 * p.se for p in li], rel=1e-12)
    plt.close(fig)
    # Two methods at one N (Engel et al.'s 256^2): a line each, by area fraction, told apart by style.
    fig, ax = plt.subplots()
    sweeps._plot_published(ax, sweeps.read_sweep("scenes/melting_65536.toml"), {"area_fraction": 0.698})
    edmd, mpmc = (reference.pressures("Engel2013", method, 65536) for method in ("EDMD", "MPMC"))
    assert ax.get_legend_handles_labels()[1] == ["Engel2013 (EDMD), N = 65536", "Engel2013 (MPMC), N = 65536"]
    for line, points, style in zip(ax.get_lines(), (edmd, mpmc), ("-", "--")):
        assert list(line.get_xdata()) == sorted(p.eta for p in points) and len(points) == 12
        assert list(line.get_ydata()) == [p.beta_p_d2 for p in sorted(points, key=lambda p: p.eta)]
        assert line.get_linestyle() == style
    plt.close(fig)


def tomllib_loads(text):
    import tomllib

    return tomllib.loads(textwrap.dedent(text))


def test_the_command_says_how_many_tasks_went_on_from_a_checkpoint(circles_cpu, tmp_path, capsys, monkeypatch):
    """A task stopped after its first checkpoint (an exception here, a dead worker on a
    cluster): the rerun of the command goes on from it and says so."""
    import re

    from circles import checkpoint

    path = write(tmp_path, CHECKPOINTED.replace("area_fraction = [0.1, 0.3, 0.5]", "area_fraction = [0.3]")
                 .replace("repeats = 2", "repeats = 1").replace("checkpoint_every = 1.4", "checkpoint_every = 0.7"))
    out = tmp_path / "out"
    real, calls = checkpoint.write, []

    def dies_after_the_first(*a, **k):  # at time 0.7: a task that went on from before time 1 counts too
        real(*a, **k)
        calls.append(1)
        if len(calls) == 1:
            raise KeyboardInterrupt

    monkeypatch.setattr(checkpoint, "write", dies_after_the_first)
    assert sweeps.main(["sweep", str(path), "--workers", "0", "--out", str(out)]) == 130
    assert (out / sweeps.CHECKPOINTS / "point-0-repeat-0.gsd").exists()
    monkeypatch.setattr(checkpoint, "write", real)
    capsys.readouterr()
    assert sweeps.main(["sweep", str(path), "--workers", "0", "--out", str(out)]) == 0
    done = [line for line in capsys.readouterr().out.splitlines() if line.startswith("done")]
    assert re.fullmatch(r"done        1 points run \(1 tasks\), 0 already in .*results.csv, \d+\.\d s; tasks that went on from a "
                        r"checkpoint: 1", done[0])
    assert not (out / sweeps.CHECKPOINTS).exists()


def test_the_command_says_how_many_tasks_an_earlier_run_did(serial, tmp_path, capsys, monkeypatch):
    """Stopped by Ctrl-C as its fourth task starts, the command has kept the third task's result;
    its rerun takes it and says so."""
    import re

    real, calls = sweeps.run_task, []

    def stopped_at_the_fourth(*args, **kwargs):
        calls.append(1)
        if len(calls) == 4:
            raise KeyboardInterrupt
        return real(*args, **kwargs)

    path, out = write(tmp_path, TINY), tmp_path / "out"
    monkeypatch.setattr(sweeps, "run_task", stopped_at_the_fourth)
    assert sweeps.main(["sweep", str(path), "--workers", "0", "--out", str(out)]) == 130
    assert len(os.listdir(out / sweeps.TASKS)) == 1
    capsys.readouterr()
    assert sweeps.main(["sweep", str(path), "--workers", "0", "--out", str(out)]) == 0
    done = [line for line in capsys.readouterr().out.splitlines() if line.startswith("done")]
    assert re.fullmatch(r"done        2 points run \(3 tasks\), 1 already in .*results.csv, \d+\.\d s; tasks done by an earlier "
                        r"run: 1", done[0])
    assert len(calls) == 4 + 3 and table(out) == table(serial[1])


def test_a_run_keeps_a_checkpoint_none_of_its_tasks_took_and_times_itself_and_its_tasks(circles_cpu, tmp_path):
    """A .gsd in DIR/checkpoints that no task of the run wrote (a point since dropped from the
    file) is kept, with its folder; the run's wall time and each task's seconds lie within the
    time measured around it; a sweep without checkpoint_every makes no checkpoint folder at all."""
    import time

    one = CHECKPOINTED.replace("area_fraction = [0.1, 0.3, 0.5]", "area_fraction = [0.3]").replace("repeats = 2",
                                                                                                   "repeats = 1")
    sweep = sweeps.read_sweep(write(tmp_path, one))
    out = tmp_path / "out"
    stale = out / sweeps.CHECKPOINTS / "point-5-repeat-0.gsd"
    stale.parent.mkdir(parents=True)
    stale.write_bytes(b"not this run's")
    before = time.perf_counter()
    run = sweeps.run_sweep(sweep, out)
    elapsed = time.perf_counter() - before
    assert os.listdir(stale.parent) == [stale.name] and stale.read_bytes() == b"not this run's"
    assert 0 < run.wall_s <= elapsed
    (result,) = run.results.values()
    assert 0 < result["seconds"] <= run.wall_s
    plain = sweeps.read_sweep(write(tmp_path, TINY.replace("area_fraction = [0.1, 0.3, 0.5]", "area_fraction = [0.3]"),
                                    "plain.toml"))
    seen = []
    ran = sweeps.run_sweep(plain, tmp_path / "plain", on_result=lambda task, result: seen.append(
        (task, result, os.path.exists(tmp_path / "plain" / sweeps.CHECKPOINTS))))
    assert seen == [((0, 0), ran.results[0, 0], False), ((0, 1), ran.results[0, 1], False)]
    assert all(isinstance(result, dict) for _, result, _ in seen)


def test_the_command_says_once_that_kernels_compile_and_names_each_varied_field(circles_cpu, tmp_path, capsys,
                                                                                monkeypatch):
    """With an empty kernel list (`circles.kernel_cache`), `circles sweep` says on stderr that
    kernels compile, once, and lists the kind of its first task's scene on the CPU with the
    threads it runs on (0: all, for tasks in this process). A point's line names each varied
    field; a sweep without compressibility or reduced pressure has no line comparing them."""
    import re

    from circles import kernel_cache
    from circles.scene import Scene

    monkeypatch.setenv("TI_OFFLINE_CACHE_FILE_PATH", str(tmp_path / "cache"))  # Taichi itself is started already
    text = (TINY.replace("area_fraction = [0.1, 0.3, 0.5]", 'area_fraction = [0.3]\nboundary = ["periodic"]')
            .replace('observables = ["compressibility", "collision_rate", "energy_change"]',
                     'observables = ["energy_change"]'))
    path = write(tmp_path, text)
    sweep = sweeps.read_sweep(path)
    assert sweeps.main(["sweep", str(path), "--workers", "0", "--out", str(tmp_path / "out")]) == 0
    said = capsys.readouterr()
    assert said.err == kernel_cache.MESSAGE + "\n"
    listed = (tmp_path / "cache" / kernel_cache.SEEN).read_text().split()
    assert listed == [kernel_cache.kind_of(Scene.from_dict(sweep.point_scene(0, 0)), "cpu", 0)]
    lines = said.out.splitlines()
    assert [line.split()[0] for line in lines] == ["sweep", "point", "done", "plots"]
    assert re.fullmatch(r'point       area_fraction 0\.3, boundary "periodic": energy_change \S+ \+- \S+', lines[1])


def test_a_figure_holds_the_points_their_errors_and_the_theory_curve(serial):
    """The compressibility figure of the tiny sweep: its points with one standard error, Liu's
    curve through their range (201 points, at the first point's temperature), labels, a log
    scale and the file's name as title; the energy change has no theory and a linear scale."""
    import matplotlib.pyplot as plt
    import numpy as np

    from circles.theory import liu_z

    sweep, out = serial
    rows = sweeps.load_rows(out, sweep)
    x = [float(values["area_fraction"]) for values, _ in rows]
    fig = sweeps.sweep_figure(sweep, rows, "compressibility")
    (ax,) = fig.axes
    assert tuple(fig.get_size_inches()) == (6.4, 4.2) and fig.dpi == 100
    points, curve = ax.get_lines()[0], ax.get_lines()[-1]
    assert list(points.get_xdata()) == x
    assert list(points.get_ydata()) == [float(row["compressibility"]) for _, row in rows]
    assert points.get_marker() == "o" and points.get_markersize() == 4 and points.get_linestyle() == "None"
    bars = ax.containers[0].lines[2][0].get_segments()
    assert [seg[1][1] - seg[0][1] for seg in bars] == pytest.approx(
        [2 * float(row["compressibility_se"]) for _, row in rows], rel=1e-12)
    assert len(ax.containers[0].lines[1]) == 2  # caps, below and above
    grid = curve.get_xdata()
    assert len(grid) == 201 and grid[0] == min(x) and grid[-1] == pytest.approx(max(x), rel=1e-15)
    np.testing.assert_allclose(curve.get_ydata(), [liu_z(g) for g in grid], rtol=1e-12)
    assert curve.get_color() == "0.3" and curve.get_linewidth() == 1
    assert ax.get_legend_handles_labels()[1] == ["Liu", "measured"]
    assert [t.get_fontsize() for t in ax.get_legend().get_texts()] == [8, 8]
    assert ax.get_xlabel() == "area_fraction" and ax.get_ylabel() == sweeps.LABELS["compressibility"]
    assert ax.get_yscale() == "log" and ax.get_title() == "sweep.toml" and ax.title.get_fontsize() == 10
    plt.close(fig)
    fig = sweeps.sweep_figure(sweep, rows, "collision_rate")
    assert fig.axes[0].get_legend_handles_labels()[1] == ["Enskog (Liu's g)", "measured"]
    assert fig.axes[0].get_yscale() == "linear"
    plt.close(fig)
    fig = sweeps.sweep_figure(sweep, rows, "energy_change")
    assert len(fig.axes[0].get_lines()) == 1 + 2  # the points and their caps: no curve
    plt.close(fig)


def test_sweep_json_records_what_fixes_the_rows(serial, tmp_path):
    """DIR/sweep.json: the base scene, the varied fields and the measurement (not the repeats), and the SHA-256 of
    them as sorted JSON, worked out here; checkpoint_every only when given."""
    import hashlib

    sweep, out = serial
    held = json.loads((out / "sweep.json").read_text())
    identity = {"scene": {"n": 40, "radius": 0.05, "speed": [1.0, 1.0], "mass": "equal", "boundary": "periodic",
                          "seed": 3},
                "varied": ["area_fraction"], "equilibrate": 0.5, "measure": 2.0, "blocks": 4,
                "observables": ["compressibility", "collision_rate", "energy_change"]}
    digest = hashlib.sha256(json.dumps(identity, sort_keys=True).encode()).hexdigest()
    assert held == {"fingerprint": digest, **identity}
    assert (out / "sweep.json").read_text().startswith('{\n "fingerprint": ')  # indented by one
    checkpointed = sweeps.read_sweep(write(tmp_path, CHECKPOINTED))
    assert checkpointed.identity()["checkpoint_every"] == 1.4
    assert checkpointed.identity()["equilibrate"] == 3.0 and checkpointed.identity()["measure"] == 60.0


def test_columns_keep_the_temperature_once():
    plain = sweeps.sweep_from_dict(tomllib_loads(TINY))
    assert sweeps.columns(plain) == ["area_fraction", "repeats", "blocks", "compressibility", "compressibility_se",
                                     "collision_rate", "collision_rate_se", "energy_change", "energy_change_se",
                                     "temperature", "temperature_se", "pair_collisions", "task_seconds"]
    hot = sweeps.sweep_from_dict(tomllib_loads(TINY.replace('"energy_change"]', '"temperature"]')))
    assert sweeps.columns(hot).count("temperature") == 1 and sweeps.columns(hot)[7] == "temperature"


def test_the_step_bound_is_the_dt_or_the_least_radius_over_the_largest_speed():
    from circles.scene import Scene

    assert sweeps._step_of(Scene(n=10, box=(5.0, 5.0), radius=(0.1, 0.3), speed=(0.5, 2.0))) == 0.1 / 2.0
    assert sweeps._step_of(Scene(n=10, box=(5.0, 5.0), radius=0.2, speed=(0.5, 2.0), dt=0.01)) == 0.01
    assert sweeps._step_of(Scene(n=10, box=(5.0, 5.0), radius=0.2, speed=(0.0, 0.0))) == math.inf
    assert sweeps._step_of(Scene(n=10, box=(5.0, 5.0), radius=0.2, speed=(0.5, 0.5))) == 0.2 / 0.5


def test_a_points_row_holds_its_counts_the_temperature_and_the_tasks_seconds():
    """point_row on results written here: repeats and blocks, the temperature kept though not
    asked for, the tasks' seconds summed to the millisecond, and no standard error of one block."""
    sweep = sweeps.sweep_from_dict(tomllib_loads(TINY.replace("repeats = 2", "repeats = 1")
                                                 .replace("blocks = 4", "blocks = 2")))
    blocks = {name: [1.0, 3.0] for name in sweeps.OBSERVABLES}
    blocks["temperature"] = [0.5, 0.7]
    row = sweeps.point_row(sweep, 1, [{"blocks": blocks, "pair_collisions": 12, "seconds": 1.23456}])
    assert (row["area_fraction"], row["repeats"], row["blocks"]) == ("0.3", 1, 2)
    assert float(row["temperature"]) == pytest.approx(0.6, rel=1e-15)
    assert float(row["temperature_se"]) == pytest.approx(0.1, rel=1e-12)  # sqrt(2 * 0.1^2 / 1) / sqrt(2)
    assert (row["compressibility"], row["compressibility_se"]) == ("2.0", "1.0")
    assert (row["pair_collisions"], row["task_seconds"]) == (12, "1.235")
    one = sweeps.point_row(sweep, 0, [{"blocks": {n: [2.0] for n in sweeps.OBSERVABLES}, "pair_collisions": 1,
                                       "seconds": 0.5}])
    assert one["compressibility"] == "2.0" and one["compressibility_se"] == "nan"


def test_results_csv_cut_short_by_a_stop_loses_only_its_last_line(serial, tmp_path):
    import shutil

    sweep, out = serial
    copy = tmp_path / "out"
    shutil.copytree(out, copy)
    whole = (copy / "results.csv").read_bytes()
    assert len(sweeps.read_results(copy, sweep)) == 3 and (copy / "results.csv").read_bytes() == whole
    (copy / "results.csv").write_bytes(whole + b"0.7,2,4,1.5")
    assert len(sweeps.read_results(copy, sweep)) == 3 and (copy / "results.csv").read_bytes() == whole
    (copy / "results.csv").write_bytes(whole.replace(b"pair_collisions", b"collisions", 1))  # a column renamed
    with pytest.raises(sweeps.SweepError) as refused:
        sweeps.read_results(copy, sweep)
    assert str(refused.value) == (f"{copy / 'results.csv'} has other columns than this sweep writes: give another "
                                  "--out, or remove it")
    (copy / "results.csv").write_bytes(whole)
    (copy / "sweep.json").unlink()
    with pytest.raises(sweeps.SweepError) as refused:
        sweeps.read_results(copy, sweep)
    assert str(refused.value) == (f"{copy / 'results.csv'} exists without sweep.json: give another --out, or remove "
                                  f"{copy / 'results.csv'}")
    (copy / "sweep.json").write_text("{}")
    unnamed = sweeps.sweep_from_dict(tomllib_loads(TINY))
    with pytest.raises(sweeps.SweepError, match=r"differ from this one's\): give another --out, or remove"):
        sweeps.read_results(copy, unnamed)


def test_a_rewritten_row_keeps_its_place_in_the_file(tmp_path):
    """A point grown with more repeats finishes in any order: its new row takes its old row's
    place, so results.csv keeps the order its points were first written in. A row whose old
    one is not in the file (changed under the run) is appended, not lost."""
    path = tmp_path / "results.csv"
    file = sweeps._CsvFile(str(path), ["x", "y"])
    for x in ("1", "2", "3"):
        file.write({"x": x, "y": "a"})
    file.write({"x": "1", "y": "b"}, replaces={"x": "1", "y": "a"})
    file.write({"x": "4", "y": "c"}, replaces={"x": "4", "y": "gone"})
    file.write({"x": "5", "y": "d"})
    file.close()
    assert path.read_text() == "x,y\n1,b\n2,a\n3,a\n4,c\n5,d\n"


def test_a_sweep_file_takes_species_in_its_scene_and_varies_them(circles_cpu, tmp_path):
    """[scene] species, and species in [vary]: each point's scene holds its mixture, and a task
    runs it (its rows keep the temperature, which every point measures)."""
    from circles.scene import Scene

    text = ('[scene]\nspecies = [{count = 20, radius = 0.05}, {count = 20, radius = 0.07}]\nboundary = "periodic"\n'
            'speed = [1.0, 1.0]\nmass = "equal"\n\n[vary]\narea_fraction = [0.2, 0.3]\n\n'
            '[sweep]\nequilibrate = 0.2\nmeasure = 0.5\nblocks = 2\n')
    sweep = sweeps.read_sweep(write(tmp_path, text))
    scene = Scene.from_dict(sweep.point_scene(1, 0))
    assert scene.species == ((20, 0.05), (20, 0.07)) and scene.area_fraction == pytest.approx(0.3, rel=1e-12)
    varied = text.replace("area_fraction = [0.2, 0.3]", "species = [[{count = 40, radius = 0.05}], "
                          "[{count = 20, radius = 0.05}, {count = 20, radius = 0.07}]]").replace(
        "[scene]\nspecies = [{count = 20, radius = 0.05}, {count = 20, radius = 0.07}]\n", "[scene]\nbox = [1.0, 1.0]\n")
    sweep = sweeps.read_sweep(write(tmp_path, varied))
    assert [Scene.from_dict(sweep.point_scene(k, 0)).n for k in range(2)] == [40, 40]
    assert Scene.from_dict(sweep.point_scene(1, 0)).radius == (0.05, 0.07)
    run = sweeps.run_sweep(sweep, tmp_path / "out")
    assert len(run.rows) == 2 and all(float(row["temperature"]) > 0 for row in run.rows)
    # The same sweep with each species written radius first: its rows are found on a rerun.
    reordered = varied.replace("{count = 40, radius = 0.05}", "{radius = 0.05, count = 40}")
    sweep = sweeps.read_sweep(write(tmp_path, reordered, "reordered.toml"))
    assert sweeps.run_sweep(sweep, tmp_path / "again").ran == [0, 1]
    rerun = sweeps.run_sweep(sweep, tmp_path / "again")
    assert rerun.ran == [] and rerun.skipped == [0, 1]
    # ... and in the folder of the sweep as first written: a species is the same whatever its keys' order.
    rerun = sweeps.run_sweep(sweep, tmp_path / "out")
    assert rerun.ran == [] and rerun.skipped == [0, 1]


def test_a_tasks_blocks_are_the_identities_of_the_same_run_worked_out_here(circles_cpu, tmp_path):
    """run_task's blocks against a Simulation of the same scene advanced to the same instants,
    each value written out here from its definition: in a walled box P = (N kT + virial / 2t)
    / ((W - 2r)(H - 2r)) and the walls' impulse over t (2 (W - 2r) + 2 (H - 2r)), r the mean
    radius; kT = K / N; the energy change over the first kinetic energy (none without one);
    no reduced pressure where the radii differ. In a periodic box, |psi_6| at each block's end
    from freud."""
    import freud

    from circles.scene import Scene
    from circles.simulation import Simulation

    fields = {"n": 60, "radius": [0.1, 0.2], "box": [6.0, 4.0], "speed": [1.0, 1.0], "mass": "area",
              "boundary": "walls", "seed": 2}
    for blocks, every, ends in ((2, None, (1.5, 2.5)), (1, 0.2, (2.5,)), (1, None, (2.5,))):
        # with checkpoints the equilibration goes in pieces (0.2, 0.4, 0.5): measuring starts at 0.5 all the same
        result = sweeps.run_task(fields, 0.5, 2.0, blocks, kept=("pressure", "wall_pressure", "temperature"),
                                 checkpoint=None if every is None else str(tmp_path / "task.gsd"), every=every)
        check_blocks(result, fields, ends)

    assert all(math.isnan(v) for v in result["blocks"]["reduced_pressure"])  # no diameter: radii differ

    # In float32 the energy changes by round-off: a change to see, its ratio to the first energy.
    stepped = {**fields, "scheme": "discrete", "dt": 0.01, "precision": "f32", "speed": [0.5, 0.5]}  # K < 1
    result = sweeps.run_task(stepped, 0.5, 2.0, 1)
    sim = Simulation(Scene.from_dict(stepped))
    e0 = sim.stats()["kinetic_energy"]
    sim.advance(0.5)
    before = sim.stats()["kinetic_energy"]
    sim.advance(2.0)
    change = (sim.stats()["kinetic_energy"] - before) / e0
    assert e0 < 1 and abs(change) > 1e-9 and result["blocks"]["energy_change"] == [pytest.approx(change, rel=1e-9)]
    still = {"n": 10, "radius": 0.1, "box": [4.0, 4.0], "speed": [0.0, 0.0], "boundary": "walls", "seed": 2}
    assert sweeps.run_task(still, 0.0, 1.0, 1)["blocks"]["energy_change"] == [0.0]  # no energy to compare with

    fields = {"n": 200, "radius": 0.1, "area_fraction": 0.6, "speed": [1.0, 1.0], "mass": "equal",
              "boundary": "periodic", "seed": 2}
    result = sweeps.run_task(fields, 0.0, 1.0, 2, kept=("hexatic_order",))
    sim = Simulation(Scene.from_dict(fields))
    box = freud.box.Box.from_box([sim.box[0], sim.box[1]], dimensions=2)
    for block, end in enumerate((0.5, 1.0)):
        sim.advance(end - sim.time)
        pos = np.zeros((200, 3))
        pos[:, :2] = sim.state().pos - np.asarray(sim.box) / 2
        hexatic = freud.order.Hexatic(k=6)
        hexatic.compute((box, pos), neighbors={"num_neighbors": 6, "exclude_ii": True})
        assert result["blocks"]["hexatic_order"][block] == pytest.approx(abs(np.mean(hexatic.particle_order)),
                                                                         abs=1e-6)


def test_a_task_keeps_a_checkpoint_every_so_often_and_none_after_its_last_piece(circles_cpu, tmp_path, monkeypatch):
    """Pieces 1.4, 2.8, 3.0 (equilibration) and 5, 7, 9 (blocks), every = 1.4: a checkpoint at
    the end of each piece 1.4 or more after the last one (1.4, 2.8, 5, 7), none after the task's
    last piece, and none left when the task ends."""
    from circles import checkpoint

    written, real = [], checkpoint.write

    def counted(path, sim, progress):
        written.append((sim.time, progress["piece"]))
        return real(path, sim, progress)

    monkeypatch.setattr(checkpoint, "write", counted)
    fields = {"n": 40, "radius": 0.05, "box": [2.0, 2.0], "speed": [1.0, 1.0], "boundary": "periodic", "seed": 2}
    path = tmp_path / "task.gsd"
    sweeps.run_task(fields, 3.0, 6.0, 3, checkpoint=str(path), every=1.4)
    assert [t for t, _ in written] == pytest.approx([1.4, 2.8, 5.0, 7.0], abs=1e-12)
    assert [piece for _, piece in written] == [1, 2, 4, 5]  # the piece to go on from
    assert not path.exists()


def check_blocks(result, fields, ends):
    """Each block of `result` against the identities of a Simulation of `fields` equilibrated
    for 0.5 and measured to each of `ends` (see the test above)."""
    from circles.scene import Scene
    from circles.simulation import Simulation

    sim = Simulation(Scene.from_dict(fields))
    e0 = sim.stats()["kinetic_energy"]
    sim.advance(0.5)
    before = sim.stats()
    start_pairs = before["pair_collisions"]
    r = 0.5 * (0.1 + 0.2)
    w, h = 6.0 - 2 * r, 4.0 - 2 * r
    assert len(result["blocks"]["pressure"]) == len(ends)
    for block, end in enumerate(ends):
        sim.advance(end - sim.time)
        after = sim.stats()
        t = after["time"] - before["time"]
        kt = after["kinetic_energy"] / 60
        p = (60 * kt + (after["virial"] - before["virial"]) / (2 * t)) / (w * h)
        wall = (after["wall_impulse"] - before["wall_impulse"]) / (t * 2 * (w + h))
        assert result["blocks"]["pressure"][block] == pytest.approx(p, rel=1e-12)
        assert result["blocks"]["wall_pressure"][block] == pytest.approx(wall, rel=1e-12)
        assert result["blocks"]["temperature"][block] == pytest.approx(kt, rel=1e-12)
        assert result["blocks"]["energy_change"][block] == pytest.approx(
            (after["kinetic_energy"] - before["kinetic_energy"]) / e0, rel=1e-9, abs=1e-15)
        before = after
    assert result["pair_collisions"] == before["pair_collisions"] - start_pairs > 0  # while measuring only


def test_a_figure_labels_each_group_by_its_other_fields_and_draws_theory_through_two_points_or_more():
    """A group of points is labelled by the values of the fields varied besides the x axis, a
    comma between; Liu's curve goes through two points or more, not one; caps 2 points wide (a
    cap's marker is twice that); 100 dots an inch, a title of 10 points and a solid curve
    whatever matplotlib's defaults; a sweep made without a file is titled "sweep"."""
    import matplotlib
    import matplotlib.pyplot as plt

    text = TINY.replace("area_fraction = [0.1, 0.3, 0.5]", 'area_fraction = [0.1, 0.3]\nmass = ["equal"]\n'
                                                           'speed = [[1.0, 1.0], [0.5, 1.0]]')
    sweep = sweeps.sweep_from_dict(tomllib_loads(text))
    row = {"compressibility": "1.2", "compressibility_se": "0.01", "temperature": "0.5"}
    rows = [({"area_fraction": 0.1, "mass": "equal", "speed": [1.0, 1.0]}, row),
            ({"area_fraction": 0.3, "mass": "equal", "speed": [1.0, 1.0]}, row),
            ({"area_fraction": 0.1, "mass": "equal", "speed": [0.5, 1.0]}, row)]
    with matplotlib.rc_context({"figure.dpi": 72, "font.size": 8, "lines.linestyle": "--"}):
        fig = sweeps.sweep_figure(sweep, rows, "compressibility")
    (ax,) = fig.axes
    assert fig.dpi == 100 and ax.get_title() == "sweep" and ax.title.get_fontsize() == 10
    (curve,) = [line for line in ax.get_lines() if line.get_label() == "Liu"]
    assert curve.get_linestyle() == "-"  # solid, whatever the default
    assert ax.get_legend_handles_labels()[1] == ["Liu", 'mass "equal", speed [1.0, 1.0]',
                                                 'mass "equal", speed [0.5, 1.0]']  # one curve: the group of two
    assert ax.containers[0].lines[1][0].get_markersize() == 4
    plt.close(fig)


def test_a_figure_places_ranges_at_their_low_end_and_words_as_categories(tmp_path):
    """The x axis of a sweep's figure: a varied range ([low, high]) at its low end, a number as it
    is; a varied word (the boundary) as a category named by it."""
    import matplotlib.pyplot as plt

    text = TINY.replace("area_fraction = [0.1, 0.3, 0.5]", "radius = [[0.04, 0.05], 0.03]")
    sweep = sweeps.read_sweep(write(tmp_path, text))
    rows = [({"radius": [0.04, 0.05]}, {"energy_change": "1e-12", "energy_change_se": "1e-13"}),
            ({"radius": 0.03}, {"energy_change": "2e-12", "energy_change_se": "1e-13"})]
    fig = sweeps.sweep_figure(sweep, rows, "energy_change")
    assert list(fig.axes[0].get_lines()[0].get_xdata()) == [0.04, 0.03]
    plt.close(fig)
    text = TINY.replace("area_fraction = [0.1, 0.3, 0.5]", 'boundary = ["walls", "periodic"]')
    sweep = sweeps.read_sweep(write(tmp_path, text, "words.toml"))
    rows = [({"boundary": b}, {"energy_change": "1e-12", "energy_change_se": "1e-13"}) for b in ("walls", "periodic")]
    fig = sweeps.sweep_figure(sweep, rows, "energy_change")
    assert list(fig.axes[0].get_lines()[0].get_xdata()) == ["walls", "periodic"]
    assert [t.get_text() for t in fig.axes[0].get_xticklabels()] == ["walls", "periodic"]
    plt.close(fig)
    mixtures = [[{"count": 40, "radius": 0.05}], [{"count": 20, "radius": 0.05}, {"count": 20, "radius": 0.07}]]
    text = TINY.replace("radius = 0.05\n", "").replace(
        "area_fraction = [0.1, 0.3, 0.5]", "species = [[{count = 40, radius = 0.05}], "
        "[{count = 20, radius = 0.05}, {count = 20, radius = 0.07}]]").replace("n = 40", "box = [1.0, 1.0]")
    sweep = sweeps.read_sweep(write(tmp_path, text, "mixtures.toml"))
    rows = [({"species": m}, {"energy_change": "1e-12", "energy_change_se": "1e-13"}) for m in mixtures]
    fig = sweeps.sweep_figure(sweep, rows, "energy_change")
    assert list(fig.axes[0].get_lines()[0].get_xdata()) == [str(m) for m in mixtures]  # a list of species by its text
    plt.close(fig)


def test_a_sweep_files_limits_are_reached_and_kept(tmp_path):
    """Each limit of [sweep] is allowed at its edge: repeats = MOST_REPEATS and blocks =
    MOST_BLOCKS, equilibrate = 0; a measure of MOST_DURATION passes its own check and is refused
    by the step count; a missing file is named as a sweep file; a stray key beside [scene] is
    unknown, not a scene file."""
    text = TINY.replace("area_fraction = [0.1, 0.3, 0.5]", "area_fraction = [0.3]")
    edge = text.replace("repeats = 2", f"repeats = {sweeps.MOST_REPEATS}").replace(
        "blocks = 4", f"blocks = {sweeps.MOST_BLOCKS}").replace("equilibrate = 0.5", "equilibrate = 0.0")
    sweep = sweeps.read_sweep(write(tmp_path, edge))
    assert (sweep.repeats, sweep.blocks, sweep.equilibrate) == (sweeps.MOST_REPEATS, sweeps.MOST_BLOCKS, 0.0)
    longest = text.replace("measure = 2.0", f"measure = {sweeps.MOST_DURATION:.0f}.0")
    with pytest.raises(sweeps.SweepError, match=r"equilibrate \+ measure = 1e\+12 s is .* steps of the point's scene, "
                       r"more than 1e10"):
        sweeps.read_sweep(write(tmp_path, longest, "longest.toml"))
    missing = tmp_path / "missing.toml"
    with pytest.raises(sweeps.SweepError) as refused:
        sweeps.read_sweep(missing)
    assert str(refused.value) == f"sweep file {missing} not found"
    with pytest.raises(ValueError) as refused:
        sweeps.sweep_from_dict({"scene": {"n": 40}, "n": 40})
    assert str(refused.value) == "unknown key(s) n: a sweep file has the tables [scene], [vary], [sweep]"


def test_a_square_box_sweep_is_compared_with_the_published_pressures_of_its_own_n(tmp_path):
    """224 disks in a square box ([scene] aspect = 1.0) at 0.700: Li et al.'s 224-disk value
    (8.6876 +- 0.0012), not those of the square boxes of 65536 disks and more that Engel et al.
    give at the same area fraction; none at an area fraction the series lacks."""
    text = ('[scene]\nn = 224\nradius = 0.5\nmass = "equal"\nboundary = "periodic"\naspect = 1.0\n\n'
            '[vary]\narea_fraction = [0.700, 0.701]\n\n'
            '[sweep]\nrepeats = 1\nequilibrate = 0.1\nmeasure = 0.2\nblocks = 2\nobservables = ["reduced_pressure"]\n')
    sweep = sweeps.read_sweep(write(tmp_path, text))
    found = sweeps.theory(sweep, {"area_fraction": 0.700}, {"temperature": "0.5"})
    assert (found["reduced_pressure"], found["reduced_pressure_se"]) == (8.6876, 0.0012)
    assert "reduced_pressure" not in sweeps.theory(sweep, {"area_fraction": 0.701}, {"temperature": "0.5"})
    import matplotlib.pyplot as plt

    rows = [({"area_fraction": eta}, {"reduced_pressure": "8.7", "reduced_pressure_se": "0.01"}) for eta in (0.7, 0.701)]
    fig = sweeps.sweep_figure(sweep, rows, "reduced_pressure")
    assert fig.axes[0].get_legend_handles_labels()[1] == ["measured", "Li2022 (ECMC), N = 224"]  # no Engel et al.
    plt.close(fig)


def test_a_points_fields_put_its_values_over_the_base_and_its_seed(tmp_path):
    """A varied box takes the place of the base's area_fraction, a varied area_fraction that of
    its box, another field leaves both; the seed is the repeat's, from the base seed (0 when the
    base gives none, as Scene's default)."""
    assert sweeps.scene_fields({"n": 40, "area_fraction": 0.3}, {"box": [2.0, 2.0]}, 7) == {
        "n": 40, "box": [2.0, 2.0], "seed": 7}
    assert sweeps.scene_fields({"n": 40, "box": [2.0, 2.0]}, {"area_fraction": 0.3}, 7) == {
        "n": 40, "area_fraction": 0.3, "seed": 7}
    assert sweeps.scene_fields({"n": 40, "box": [2.0, 2.0], "seed": 1}, {"n": 50}, 7) == {
        "n": 50, "box": [2.0, 2.0], "seed": 7}
    unseeded = sweeps.read_sweep(write(tmp_path, TINY.replace("seed = 3\n", "")))
    zero = sweeps.read_sweep(write(tmp_path, TINY.replace("seed = 3\n", "seed = 0\n"), "zero.toml"))
    assert [unseeded.point_scene(0, r)["seed"] for r in range(3)] == [zero.point_scene(0, r)["seed"] for r in range(3)]
    assert len({zero.point_scene(0, r)["seed"] for r in range(3)} | {0}) == 4  # each repeat its own, none the base's


def test_a_sweeps_step_count_is_allowed_up_to_1e10(tmp_path):
    """equilibrate + measure = 2.5 s over dt: 1e10 steps are allowed, 1e10 + 0.5 are not."""
    at = TINY.replace("speed = [1.0, 1.0]", "speed = [1.0, 1.0]\ndt = 2.5e-10")
    assert sweeps.read_sweep(write(tmp_path, at)).points
    over = TINY.replace("speed = [1.0, 1.0]", f"speed = [1.0, 1.0]\ndt = {2.5 / 1.00000000005e10!r}")
    with pytest.raises(sweeps.SweepError, match=r"is 1e\+10 steps of the point's scene, more than 1e10"):
        sweeps.read_sweep(write(tmp_path, over, "over.toml"))


#: Li et al.'s N = 224 in its square box at two of its published area fractions, briefly.
PUBLISHED = """
[scene]
n = 224
radius = 0.5
aspect = 1.0
speed = [1.0, 1.0]
mass = "equal"
boundary = "periodic"
seed = 5

[vary]
area_fraction = [0.670, 0.700]

[sweep]
repeats = 1
equilibrate = 1.0
measure = 4.0
blocks = 4
observables = ["reduced_pressure", "compressibility"]
"""


def test_the_command_says_the_largest_deviations_from_liu_and_from_the_published_pressures(circles_cpu, tmp_path,
                                                                                              capsys):
    """The last two lines, from results.csv and the reference table read here: the largest
    relative deviation of Z from Liu's, and the deviation of beta P d^2 from Li et al.'s at N = 224
    that is largest in standard errors."""
    from circles import reference, theory as hard_disks

    out = tmp_path / "out"
    assert sweeps.main(["sweep", str(write(tmp_path, PUBLISHED)), "--workers", "0", "--out", str(out)]) == 0
    lines = capsys.readouterr().out.splitlines()
    with open(out / "results.csv", newline="") as file:
        rows = list(csv.DictReader(file))
    published = {p.eta: p for p in reference.series(224, 1.0)}
    liu, li = [], []
    for row in rows:
        eta = float(row["area_fraction"])
        z, z_se = float(row["compressibility"]), float(row["compressibility_se"])
        liu.append((abs(z / hard_disks.liu_z(eta) - 1), eta, z / hard_disks.liu_z(eta) - 1,
                    (z - hard_disks.liu_z(eta)) / z_se))
        p, p_se = float(row["reduced_pressure"]), float(row["reduced_pressure_se"])
        ref = published[eta].beta_p_d2
        li.append((abs(p - ref) / p_se, eta, p - ref, (p - ref) / p_se))
    _, eta, relative, in_se = max(liu)
    assert lines[-2] == (f"liu         largest deviation of Z from Liu's: {100 * relative:+.2f}% ({in_se:+.1f} standard "
                         f"errors) at area fraction {eta:g}")
    _, eta, difference, in_se = max(li)
    assert lines[-1] == (f"published   largest deviation of beta P d^2 from the published one at this N: "
                         f"{difference:+.4f} ({in_se:+.1f} standard errors) at area fraction {eta:g}")


def test_the_command_picks_liu_s_largest_by_percent_and_the_published_largest_by_standard_errors(
        serial, tmp_path, capsys, monkeypatch):
    """Deviations given by hand where the two orders differ: Liu's line takes the largest
    relative deviation, the published line the largest in standard errors."""
    given = [(0.1, 1.0, 1.1, -0.09, -9.0), (0.2, 1.0, 1.2, -0.17, -1.7), (0.3, 2.0, 1.9, +0.05, +4.0)]
    monkeypatch.setattr(sweeps, "deviations", lambda sweep, rows, name="compressibility": given)
    assert sweeps.main(["sweep", str(write(tmp_path, TINY)), "--workers", "0", "--out", str(tmp_path / "o")]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[-2:] == ["liu         largest deviation of Z from Liu's: -17.00% (-1.7 standard errors) at area "
                          "fraction 0.2",
                          "published   largest deviation of beta P d^2 from the published one at this N: -0.1000 "
                          "(-9.0 standard errors) at area fraction 0.1"]


def test_the_command_without_matplotlib_says_the_plots_were_skipped(serial, tmp_path, capsys, monkeypatch):
    def no_matplotlib(*args):
        raise ImportError("no matplotlib")

    monkeypatch.setattr(sweeps, "plot_sweep", no_matplotlib)
    assert sweeps.main(["sweep", str(write(tmp_path, TINY)), "--workers", "0", "--out", str(tmp_path / "o")]) == 0
    assert "\nplots       skipped: matplotlib is not installed (pip install 'circles-sim[plot]')\n" in \
        capsys.readouterr().out


def test_the_command_stopped_by_ctrl_c_says_a_rerun_goes_on(serial, tmp_path, capsys, monkeypatch):
    def stopped(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(sweeps, "run_sweep", stopped)
    assert sweeps.main(["sweep", str(write(tmp_path, TINY)), "--workers", "0", "--out", str(tmp_path / "o")]) == 130
    err = capsys.readouterr().err  # after the line that kernels compile, where this process has not built them
    assert err.splitlines()[-1] == ("circles: stopped by Ctrl-C; the points done are in results.csv, and a rerun "
                                    "runs the others (the tasks done of those are kept)")
    assert err.endswith("\n") and err.count("circles:") == 1


@pytest.mark.parametrize("fail_at, where", [(0, "no point was done"), (2, "the points done are in OUT")])
def test_a_failed_task_says_what_failed_and_where_the_points_done_are(serial, tmp_path, capsys, monkeypatch,
                                                                      fail_at, where):
    """A task's error ends the command with 1 and one line on stderr naming it; the points done
    before it stay in results.csv (the first point's two repeats, when the third task fails)."""
    real, calls = sweeps.run_task, []

    def failing(*args, **kwargs):
        calls.append(1)
        if len(calls) > fail_at:
            raise RuntimeError("a task's own error")
        return real(*args, **kwargs)

    monkeypatch.setattr(sweeps, "run_task", failing)
    out = tmp_path / "o"
    assert sweeps.main(["sweep", str(write(tmp_path, TINY)), "--workers", "0", "--out", str(out)]) == 1
    where = where.replace("OUT", str(out / "results.csv"))
    assert capsys.readouterr().err == f"circles: the sweep failed: RuntimeError: a task's own error; {where}\n"
    assert len(sweeps.load_rows(out, sweeps.read_sweep(write(tmp_path, TINY)))) == fail_at // 2


def test_a_failed_sweep_whose_results_cannot_be_read_says_so(serial, tmp_path, capsys, monkeypatch):
    """A task fails after sweep.json was removed under the run: what was done cannot be told,
    and the line says why rather than claiming points were done or not."""
    out = tmp_path / "o"
    real = sweeps.run_task

    def failing(*args, **kwargs):
        if (out / "results.csv").read_text().count("\n") > 1:  # a point done
            (out / "sweep.json").unlink()
            raise RuntimeError("a task's own error")
        return real(*args, **kwargs)

    monkeypatch.setattr(sweeps, "run_task", failing)
    assert sweeps.main(["sweep", str(write(tmp_path, TINY)), "--workers", "0", "--out", str(out)]) == 1
    assert capsys.readouterr().err == (f"circles: the sweep failed: RuntimeError: a task's own error; the points done "
                                       f"cannot be told: {out / 'results.csv'} exists without sweep.json: give another "
                                       f"--out, or remove {out / 'results.csv'}\n")


def test_the_coexistence_sweep_runs_points_of_the_melting_sweep_five_times_longer():
    melting = sweeps.read_sweep("scenes/melting_sweep.toml")
    longer = sweeps.read_sweep("scenes/melting_coexistence.toml")
    assert {k: v for k, v in longer.scene.items() if k != "seed"} == {k: v for k, v in melting.scene.items()
                                                                       if k != "seed"}
    assert longer.scene["seed"] != melting.scene["seed"]  # runs of their own, not the sweep's again
    assert all(point in melting.points for point in longer.points) and len(longer.points) == 4
    assert longer.repeats * longer.measure == 5 * melting.repeats * melting.measure
    assert (longer.equilibrate, longer.observables) == (melting.equilibrate, melting.observables)
    more = sweeps.read_sweep("scenes/melting_coexistence_more.toml")  # 0.710 again, alike but for the seed
    assert {k: v for k, v in more.scene.items() if k != "seed"} == {k: v for k, v in longer.scene.items()
                                                                     if k != "seed"}
    assert more.scene["seed"] not in (longer.scene["seed"], melting.scene["seed"])
    assert more.points == [p for p in longer.points if p["area_fraction"] == 0.710] and len(more.points) == 2
    assert more.identity() == {**longer.identity(), "scene": more.scene}
    at_0714 = sweeps.read_sweep("scenes/melting_0714.toml")  # a melting sweep point, each repeat one block
    assert {k: v for k, v in at_0714.scene.items() if k != "seed"} == {k: v for k, v in melting.scene.items()
                                                                        if k != "seed"}
    assert at_0714.scene["seed"] not in (more.scene["seed"], longer.scene["seed"], melting.scene["seed"])
    assert at_0714.points == [p for p in melting.points if p["area_fraction"] == 0.714] and len(at_0714.points) == 2
    assert (at_0714.blocks, at_0714.equilibrate, at_0714.observables) == (1, melting.equilibrate, melting.observables)
    at_0718 = sweeps.read_sweep("scenes/melting_0718.toml")  # the same at 0.718, with a seed of its own
    assert at_0718.scene["seed"] not in (at_0714.scene["seed"], more.scene["seed"], longer.scene["seed"],
                                         melting.scene["seed"])
    assert at_0718.points == [p for p in melting.points if p["area_fraction"] == 0.718] and len(at_0718.points) == 2
    assert at_0718.identity() == {**at_0714.identity(), "scene": at_0718.scene} and at_0718.repeats == 8
    long = sweeps.read_sweep("scenes/melting_0718_long.toml")  # 0.718 for a cluster: runs of many switches
    seeds = (at_0718.scene["seed"], at_0714.scene["seed"], more.scene["seed"], longer.scene["seed"],
             melting.scene["seed"])
    assert {k: v for k, v in long.scene.items() if k != "seed"} == {k: v for k, v in at_0718.scene.items()
                                                                     if k != "seed"} and long.scene["seed"] not in seeds
    assert long.points == at_0718.points and (long.blocks, long.observables) == (1, at_0718.observables)
    lifetime = 400000 / 6  # of a state at 0.718: six switches in the long run of the Validation page
    assert long.equilibrate >= 3 * lifetime and long.measure >= 6 * lifetime and long.repeats * long.measure >= 12.8e6
    assert 0 < long.checkpoint_every < long.equilibrate


def test_the_large_melting_sweep_is_engel_s_square_box_compared_with_engel_s_molecular_dynamics():
    """scenes/melting_65536.toml: 256^2 equal disks in a square periodic box, whose published
    pressure at 0.698 is Engel et al.'s event-driven MD (first of the two methods at that N),
    measured from the compressed fluid with checkpoints."""
    from circles.reference import pressures
    from circles.scene import Scene

    large = sweeps.read_sweep("scenes/melting_65536.toml")
    scene = Scene.from_dict(large.point_scene(0, 0))
    assert scene.n == 256 ** 2 and scene.box[0] == scene.box[1] and scene.start == "compressed"
    assert math.isclose(scene.n * math.pi * 0.25 / (scene.box[0] * scene.box[1]), 0.698, rel_tol=1e-12)
    (edmd,) = [p for p in pressures("Engel2013", "EDMD", 65536) if p.eta == 0.698]
    known = sweeps.theory(large, large.points[0], {"temperature": "0.5"})
    assert (known["reduced_pressure"], known["reduced_pressure_se"]) == (edmd.beta_p_d2, edmd.se) == (9.17059, 0.00018)
    assert large.checkpoint_every is not None and "reduced_pressure" in large.observables


def test_the_melting_table_joins_a_points_rows_measured_alike_into_one_of_their_whole_time(tmp_path):
    """bench/melting_table.py: two sweeps of one point measured alike (seeds apart) give one row:
    the mean and standard error of all their blocks in one (2 x 4 blocks of mean 2.0 and 6 x 4
    of mean 3.0: their spreads and the difference of their means, worked out here); a point
    measured otherwise keeps its own row."""
    import importlib.util
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    sys.path.insert(0, str(root / "bench"))
    spec = importlib.util.spec_from_file_location("melting_table", root / "bench" / "melting_table.py")
    table_ = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(table_)
    text = (TINY.replace('observables = ["compressibility", "collision_rate", "energy_change"]',
                         'observables = ["compressibility"]'))
    a = sweeps.read_sweep(write(tmp_path, text, "a.toml"))
    b = sweeps.read_sweep(write(tmp_path, text.replace("seed = 3", "seed = 4").replace("repeats = 2", "repeats = 6"),
                                "b.toml"))
    shorter = sweeps.read_sweep(write(tmp_path, text.replace("measure = 2.0", "measure = 1.0"), "c.toml"))
    row = lambda z, se, s, n: {"compressibility": str(z), "compressibility_se": str(se), "task_seconds": str(s),  # noqa: E731
                               "repeats": str(n)}
    values = {"area_fraction": 0.3}
    points = [(0.3, "", 4.0, a, values, row(2.0, 0.3, 10.0, 2)), (0.3, "", 12.0, b, values, row(3.0, 0.1, 30.0, 6)),
              (0.3, "", 2.0, shorter, values, row(9.0, 1.0, 5.0, 2))]
    (eta, start, measured, _, _, joined), alone = table_.join(points)
    assert (eta, start, measured) == (0.3, "", 16.0)
    assert float(joined["compressibility"]) == pytest.approx((8 * 2.0 + 24 * 3.0) / 32, rel=1e-15)
    squares = 0.3 ** 2 * 8 * 7 + 0.1 ** 2 * 24 * 23 + (3.0 - 2.0) ** 2 * 8 * 24 / 32
    assert float(joined["compressibility_se"]) == pytest.approx(math.sqrt(squares / 31 / 32), rel=1e-14)
    assert float(joined["task_seconds"]) == 40.0
    assert alone == points[2]
