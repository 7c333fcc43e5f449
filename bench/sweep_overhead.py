"""The cost of running sweep tasks on a local Dask cluster, against running them in this process.

Runs TASKS tasks of a scene so small that a task's own work is about a millisecond, once in this
process and once on a LocalCluster of WORKERS worker processes (started, warmed with one task
per worker, then timed). Prints the cluster's start, the wall time per task both ways, and the
overhead per task: the cluster's wall time times its workers, less the tasks' own time, over
the tasks.

    python bench/sweep_overhead.py [--tasks 200] [--workers 2]
"""
import argparse
import os
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from circles import sweep as sweeps  # noqa: E402

TINY = """
[scene]
n = 20
box = [2.0, 2.0]
radius = 0.05
speed = [1.0, 1.0]
mass = "equal"
boundary = "periodic"
seed = 1
[vary]
speed = [{speeds}]
[sweep]
repeats = 1
equilibrate = 0.0
measure = 0.05
blocks = 1
"""


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--tasks", type=int, default=200)
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    import distributed

    import circles

    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "tiny.toml")
        with open(path, "w") as f:
            f.write(TINY.format(speeds=", ".join(f"{1 + k / 1000:.3f}" for k in range(args.tasks))))
        sweep = sweeps.read_sweep(path)
        circles.init("cpu")
        sweeps.run_sweep(sweep, os.path.join(tmp, "warm"))  # compiles in this process
        serial = sweeps.run_sweep(sweep, os.path.join(tmp, "serial"))
        own = sum(r["seconds"] for r in serial.results.values())
        start = time.perf_counter()
        cluster = sweeps.local_cluster(args.workers)
        client = distributed.Client(cluster)
        started = time.perf_counter() - start
        threads = max(1, (os.cpu_count() or 1) // args.workers)
        sweeps.run_sweep(sweep, os.path.join(tmp, "warm-cluster"), client=client, threads=threads)
        run = sweeps.run_sweep(sweep, os.path.join(tmp, "cluster"), client=client, threads=threads)
        own_cluster = sum(r["seconds"] for r in run.results.values())
        start = time.perf_counter()
        client.close()
        cluster.close()
        stopped = time.perf_counter() - start
    n = args.tasks
    print(f"tasks {n}, workers {args.workers}, cpu cores {os.cpu_count()}")
    print(f"in this process: {serial.wall_s / n * 1e3:.2f} ms a task (its own work {own / n * 1e3:.2f} ms)")
    print(f"local cluster:   {run.wall_s / n * 1e3:.2f} ms a task (its own work {own_cluster / n * 1e3:.2f} ms); "
          f"overhead {(run.wall_s * args.workers - own_cluster) / n * 1e3:.2f} ms a task per worker")
    print(f"cluster start {started:.2f} s, stop {stopped:.2f} s (warm-up task per worker not counted)")


if __name__ == "__main__":
    main()
