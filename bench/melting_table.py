"""The melting sweep's results against the published pressures of the same N and box.

    python bench/melting_table.py [SWEEP.toml] [RESULTS_DIR] [--out FILE.md]

Defaults: scenes/melting_sweep.toml and outputs/melting_sweep. Prints a Markdown table: each
point's beta P d^2 with its standard error and the tasks' wall time, the published value at
that area fraction (`circles.reference`), their difference in combined standard errors, the
hexatic order; then whether the loop is resolved (the pressure at 0.698 above that at 0.710 by
more than 3 combined standard errors, for each start).
"""
import argparse
import math
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from circles import sweep as sweeps  # noqa: E402


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("sweep", nargs="?", default=str(ROOT / "scenes" / "melting_sweep.toml"))
    parser.add_argument("results", nargs="?", default=str(ROOT / "outputs" / "melting_sweep"))
    parser.add_argument("--out")
    args = parser.parse_args()
    from bench import cpu_details, cpu_model

    sweep = sweeps.read_sweep(args.sweep)
    rows = sweeps.load_rows(args.results, sweep)
    lines = [f"`{os.path.relpath(args.sweep, ROOT)}` on {cpu_model()}{cpu_details()}, {os.cpu_count()} CPUs, "
             f"{time.strftime('%Y-%m-%d')}: `circles sweep {os.path.relpath(args.sweep, ROOT)} --workers 2`, then "
             f"`python bench/melting_table.py`. {sweep.repeats} repeats of {sweep.equilibrate:g} time units of "
             f"equilibration and {sweep.measure:g} of measurement in {sweep.blocks} blocks per point.", "",
             "| area fraction | start | beta P d^2 | published (Li et al. 2022) | difference / combined SE | "
             "hexatic order | wall s (tasks) |", "|---|---|---|---|---|---|---|"]
    by_start = {}
    for values, row in rows:
        eta, start = float(values["area_fraction"]), values.get("start", "")
        got, se = float(row["reduced_pressure"]), float(row["reduced_pressure_se"])
        known = sweeps.theory(sweep, values, row)
        if "reduced_pressure" in known:
            ref, ref_se = known["reduced_pressure"], known["reduced_pressure_se"]
            published = f"{ref:.5f} ± {ref_se:.2g}"
            z = f"{(got - ref) / math.hypot(se, ref_se):+.1f}"
        else:
            published, z = "", ""
        order = f"{float(row['hexatic_order']):.3f}" if "hexatic_order" in row else ""
        lines.append(f"| {eta:.3f} | {start} | {got:.4f} ± {se:.4f} | {published} | {z} | {order} | "
                     f"{float(row['task_seconds']):.0f} |")
        by_start.setdefault(start, {})[round(eta, 6)] = (got, se)
    lines.append("")
    for start, points in by_start.items():
        if 0.698 in points and 0.71 in points:
            (a, ea), (b, eb) = points[0.698], points[0.71]
            lines.append(f"Loop, start {start}: beta P d^2 at 0.698 minus at 0.710 = {a - b:+.4f}, "
                         f"{(a - b) / math.hypot(ea, eb):+.1f} combined standard errors.")
    text = "\n".join(lines) + "\n"
    print(text)
    if args.out:
        Path(args.out).write_text(text)


if __name__ == "__main__":
    main()
