"""A large run killed with SIGKILL and resumed: what the stop costs, and that the bits hold.

    python bench/diagnostics/resume_run.py [--n 1e6] [--out FILE.md]

Three `circles run` commands in a scratch folder, each a fresh process: the run straight
through; the same run killed once its stats table holds half its rows; then that run with
--resume. The run writes --stats and a checkpoint every two frames (no trajectory: a frame of a
million circles is 80 MB). Prints a Markdown table: each command's wall time, the resume's
time to its first new row, the checkpoint's size and the time to write one, and whether the
resumed table and final checkpoint equal the straight run's, bit for bit.
"""
import argparse
import os
import signal
import subprocess
import sys
import tempfile
import time
from datetime import date
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "bench"))
from bench import cpu_model  # noqa: E402


def rows(path):
    try:
        return max(path.read_bytes().count(b"\n") - 1, 0)
    except FileNotFoundError:
        return 0


def run(args, cwd, stop_at=None):
    """(wall seconds, stderr, seconds to the first row written after start) of a command;
    with stop_at, killed once the table holds that many rows."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    tick = time.perf_counter()
    start_rows = rows(cwd / "run.csv")
    process = subprocess.Popen([sys.executable, "-m", "circles.cli", *args], cwd=cwd, env=env,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    first_row = None
    while process.poll() is None:
        now = rows(cwd / "run.csv")
        if first_row is None and now > start_rows:
            first_row = time.perf_counter() - tick
        if stop_at is not None and now >= stop_at:
            process.send_signal(signal.SIGKILL)
            break
        time.sleep(0.05)
    _, err = process.communicate()
    if stop_at is None and process.returncode != 0:
        raise SystemExit(f"circles {' '.join(args)} failed: {err[-2000:]}")
    return time.perf_counter() - tick, err, first_row


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--n", default="1e6")
    parser.add_argument("--frames", type=int, default=8)
    parser.add_argument("--out", type=Path)
    args = parser.parse_args()
    sys.path.insert(0, str(ROOT))
    import numpy as np

    from circles import checkpoint

    flags = ["run", "--n", args.n, "--area-fraction", "0.45", "--radius", "0.5", "--speed", "1", "1",
             "--boundary", "periodic", "--mass", "equal", "--duration", str(args.frames * 0.25), "--fps", "4",
             "--out", "none", "--stats", "run.csv", "--checkpoint-every", "0.5"]
    with tempfile.TemporaryDirectory() as scratch:
        straight, stopped = Path(scratch, "straight"), Path(scratch, "stopped")
        straight.mkdir()
        stopped.mkdir()
        run(flags, straight)  # compiles the kernels into the cache, so the timed runs below do not
        (straight / "run.csv").unlink()
        (straight / "run.checkpoint.gsd").unlink()
        whole_s, _, _ = run(flags, straight)
        killed_s, _, _ = run(flags, stopped, stop_at=args.frames // 2 + 1)
        killed_rows = rows(stopped / "run.csv")
        resume_s, err, first_row_s = run([*flags, "--resume"], stopped)
        source = next(line for line in err.splitlines() if "continuing from frame" in line)
        same_table = (straight / "run.csv").read_bytes() == (stopped / "run.csv").read_bytes()
        a, _ = checkpoint.read(straight / "run.checkpoint.gsd")
        b, _ = checkpoint.read(stopped / "run.checkpoint.gsd")
        fa, fb = a._fields(), b._fields()
        same_state = all(np.array_equal(fa[k], fb[k]) for k in ("pos", "vel", "pair_count", "virial", "time", "steps"))
        size_mb = (straight / "run.checkpoint.gsd").stat().st_size / 1e6
        tick = time.perf_counter()
        checkpoint.write(Path(scratch, "timing.gsd"), a, {"frame": 0})
        write_s = time.perf_counter() - tick
        tick = time.perf_counter()
        checkpoint.read(Path(scratch, "timing.gsd"))
        read_s = time.perf_counter() - tick
    lines = [
        f"# A run of {float(args.n):.0e} circles killed and resumed",
        "",
        f"{cpu_model()}, {date.today().isoformat()}. `python bench/diagnostics/resume_run.py --n {args.n}`: "
        f"{float(args.n):.0e} equal disks at area fraction 0.45, periodic, event scheme, {args.frames} frames with "
        "`--stats` and `--checkpoint-every 0.5` (every 2 frames); the kernels cached.",
        "",
        "| what | figure |",
        "|---|---|",
        f"| run straight through | {whole_s:.1f} s |",
        f"| killed (SIGKILL) with {killed_rows} of {args.frames} rows written | after {killed_s:.1f} s |",
        f"| resumed, whole command | {resume_s:.1f} s |",
        f"| resumed, to its first new row | {first_row_s:.1f} s |",
        f"| where it went on | {source.split(': ', 1)[1]} |",
        f"| checkpoint: size, write, read into a simulation | {size_mb:.0f} MB, {write_s:.2f} s, {read_s:.2f} s |",
        f"| table after the resume equals the straight run's | {'yes, byte for byte' if same_table else 'NO'} |",
        f"| final state (positions, velocities, counts, virial) equals it | {'yes, bit for bit' if same_state else 'NO'} |",
    ]
    text = "\n".join(lines) + "\n"
    print(text)
    if args.out:
        args.out.write_text(text)


if __name__ == "__main__":
    main()
