"""What a new user waits for: the wall time of the first commands on an empty Taichi cache.

    python bench/diagnostics/first_run.py [--repeats 2] [--out FILE.md]

Each command runs in a fresh process with an empty cache folder of its own
(TI_OFFLINE_CACHE_FILE_PATH), in a scratch folder holding a copy of `scenes/`, then once more on
that now full cache. The commands: the showcase (`circles run`), the Newton's cradle scene, and a
small sweep on a local cluster of two workers (the time its tasks took, placement and compiling
included, as the command reports it, and the whole command). Prints a Markdown table, the
median over `--repeats` of each.
"""
import argparse
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "bench"))
from bench import cpu_details, cpu_model  # noqa: E402

SWEEP = """
[scene]
n = 1000
radius = 0.5
speed = [1.0, 1.0]
mass = "equal"
boundary = "periodic"
seed = 1

[vary]
area_fraction = [0.3, 0.6]

[sweep]
repeats = 1
equilibrate = 1.0
measure = 4.0
blocks = 4
observables = ["compressibility"]
"""

COMMANDS = {
    "showcase: circles run": ["run", "--out", "showcase.mp4"],
    "cradle: circles run scenes/newtons_cradle.toml": ["run", "scenes/newtons_cradle.toml", "--out", "cradle.mp4"],
    "sweep: 2 points of 1000 disks, 2 workers": ["sweep", "small_sweep.toml", "--workers", "2", "--out", "sweep"],
}


def timed(args, where, cache):
    env = dict(os.environ, TI_OFFLINE_CACHE_FILE_PATH=str(cache),
               PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "circles.cli", *args], cwd=where, env=env, capture_output=True,
                          text=True, check=True)
    seconds = time.perf_counter() - start
    tasks = re.search(r"points run, .*?, ([0-9.]+) s", done.stdout)
    return seconds, float(tasks.group(1)) if tasks else None


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--out", help="also write the table to this Markdown file")
    args = parser.parse_args()
    results = {name: {"cold": [], "warm": [], "tasks": []} for name in COMMANDS}
    for _ in range(args.repeats):
        for name, command in COMMANDS.items():
            with tempfile.TemporaryDirectory() as scratch:
                where = Path(scratch)
                shutil.copytree(ROOT / "scenes", where / "scenes")
                (where / "small_sweep.toml").write_text(SWEEP)
                cold, tasks = timed(command, where, where / "cache")
                shutil.rmtree(where / "sweep", ignore_errors=True)
                warm, _ = timed(command, where, where / "cache")
            results[name]["cold"].append(cold)
            results[name]["warm"].append(warm)
            if tasks is not None:
                results[name]["tasks"].append(tasks)
    lines = [f"First runs on {cpu_model()}{cpu_details()}, {os.cpu_count()} CPUs, "
             f"{time.strftime('%Y-%m-%d')}; `python bench/diagnostics/first_run.py --repeats {args.repeats}`, "
             "medians.", "",
             "| command | empty cache, s | full cache, s | sweep's tasks on an empty cache, s |", "|---|---|---|---|"]
    for name, got in results.items():
        tasks = f"{statistics.median(got['tasks']):.1f}" if got["tasks"] else ""
        lines.append(f"| {name} | {statistics.median(got['cold']):.1f} | {statistics.median(got['warm']):.1f} | "
                     f"{tasks} |")
    text = "\n".join(lines) + "\n"
    print(text)
    if args.out:
        Path(args.out).write_text(text)


if __name__ == "__main__":
    main()
