"""The melting sweeps' results against the published pressures of the same N and box.

    python bench/melting_table.py [--sweep SWEEP.toml RESULTS_DIR]... [--date YYYY-MM-DD] [--out FILE.md]
                                  [--plot FILE.png]

Default: the committed sweeps (`DEFAULT`: scenes/melting_sweep.toml with outputs/melting_sweep,
and each of the other melting sweeps with its folder in outputs/ where that has results), each
with the machine and date it was measured on; `--sweep`: sweeps run here, on `--date`. Rows of
one point measured alike in several sweeps are joined (`join`). Prints a Markdown table: each
point's beta P d^2 with its standard error, the simulated time measured per start and the
tasks' wall time, the published value at that area fraction
(`circles.reference`), their difference in combined standard errors, the hexatic order; then
whether the loop is resolved (the pressure at 0.698 above that at 0.710 by more than 3 combined
standard errors, for each start, from the longest measurement of each point). `--plot` draws
every row with Li et al.'s series: the longest measurement of each point filled, shorter ones
open.
"""
import argparse
import json
import math
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from circles import sweep as sweeps  # noqa: E402

#: The committed sweeps: file, results folder, and the machine and date its results were measured on.
FAST = "AMD EPYC (family 26, model 2, L2 1024K, L3 32768K), 2 CPUs"
SLOW = "AMD EPYC (family 25, model 1, L2 512K, L3 32768K), 2 CPUs"
XEON = "Intel Xeon (family 6, model 167, L2 2048K, L3 491520K), 2 CPUs"
DEFAULT = [("scenes/melting_sweep.toml", "outputs/melting_sweep", f"{FAST}, 2026-12-06"),
           ("scenes/melting_coexistence.toml", "outputs/melting_coexistence", f"{FAST}, 2026-12-07"),
           ("scenes/melting_coexistence_more.toml", "outputs/melting_coexistence_more", f"{FAST}, 2026-12-07"),
           ("scenes/melting_0714.toml", "outputs/melting_0714",
            f"{SLOW}, 2026-12-07; the compressed start's repeats 26 to 43 on an {XEON}, 2026-12-08"),
           ("scenes/melting_0718.toml", "outputs/melting_0718", f"{SLOW}, 2026-12-07")]


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sweep", nargs=2, action="append", metavar=("SWEEP.toml", "RESULTS_DIR"),
                        help="a sweep file and its results folder (repeatable)")
    parser.add_argument("--date", default=time.strftime("%Y-%m-%d"), help="the date the sweeps given ran")
    parser.add_argument("--out")
    parser.add_argument("--plot", help="a PNG of beta P d^2 against the area fraction")
    args = parser.parse_args()
    from bench import cpu_details, cpu_model

    here = f"{cpu_model()}{cpu_details()}, {os.cpu_count()} CPUs, {args.date}"
    pairs = ([(path, results, here) for path, results in args.sweep] if args.sweep else
             [(ROOT / s, ROOT / r, where) for s, r, where in DEFAULT if (ROOT / r / sweeps.RESULTS).is_file()])
    runs, points = [], []
    for path, results, where in pairs:
        sweep = sweeps.read_sweep(path)
        name = os.path.relpath(path, ROOT)
        rows = list(sweeps.load_rows(results, sweep))
        repeats = " or ".join(str(r) for r in sorted({int(row["repeats"]) for _, row in rows}))  # a point grown alone
        runs.append((name, f"`{name}` ({where}): {repeats} repeats of {sweep.equilibrate:g} time units of "
                           f"equilibration and {sweep.measure:g} of measurement in {sweep.blocks} "
                           f"block{'s' if sweep.blocks > 1 else ''} per point"))
        for values, row in rows:
            points.append((float(values["area_fraction"]), values.get("start", ""), int(row["repeats"]) * sweep.measure,
                           sweep, values, row))
    points = join(points)
    lines = ["A task a core: " + ", ".join(f"`circles sweep {name}`" for name, _ in runs) + ", then `python bench/melting_table.py --out outputs/melting_sweep.md --plot outputs/melting_sweep.png`. "
             + "; ".join(words for _, words in runs) + ". Measured: the simulated time measured per start, all "
             "repeats together; the rows of one point measured alike in two sweeps are joined into one.", "",
             "| area fraction | start | measured | beta P d^2 | published (Li et al. 2022) | "
             "difference / combined SE | hexatic order | wall s (tasks) |", "|---|---|---|---|---|---|---|---|"]
    longest = {}
    for eta, start, measured, sweep, values, row in sorted(points, key=lambda p: p[:3]):
        got, se = float(row["reduced_pressure"]), float(row["reduced_pressure_se"])
        known = sweeps.theory(sweep, values, row)
        if "reduced_pressure" in known:
            ref, ref_se = known["reduced_pressure"], known["reduced_pressure_se"]
            published = f"{ref:.5f} ± {ref_se:.2g}"
            z = f"{(got - ref) / math.hypot(se, ref_se):+.1f}"
        else:
            published, z = "", ""
        order = f"{float(row['hexatic_order']):.3f}" if "hexatic_order" in row else ""
        lines.append(f"| {eta:.3f} | {start} | {measured:.0f} | {got:.4f} ± {se:.4f} | {published} | {z} | {order} | "
                     f"{float(row['task_seconds']):.0f} |")
        longest[(start, round(eta, 6))] = (got, se, measured)  # sorted by the time measured: the longest last
    lines.append("")
    for start in dict.fromkeys(start for start, _ in longest):
        if (start, 0.698) in longest and (start, 0.71) in longest:
            (a, ea, _), (b, eb, _) = longest[(start, 0.698)], longest[(start, 0.71)]
            lines.append(f"Loop, start {start}: beta P d^2 at 0.698 minus at 0.710 = {a - b:+.4f}, "
                         f"{(a - b) / math.hypot(ea, eb):+.1f} combined standard errors.")
    if args.plot:
        plot(points, {key: measured for key, (_, _, measured) in longest.items()}, args.plot)
    text = "\n".join(lines) + "\n"
    print(text)
    if args.out:
        Path(args.out).write_text(text)


def join(points):
    """Rows of one point measured alike in several sweeps (the same scene but for its seed, the
    same equilibration, blocks and block length) as one row of their whole measured time: the
    mean and standard error of all their blocks in one (`circles.sweep.pooled`); their tasks'
    seconds added. Other rows as they are."""
    groups = {}
    for point in points:
        eta, start, _, sweep, _, _ = point
        scene = json.dumps({k: v for k, v in sweep.scene.items() if k != "seed"}, sort_keys=True)
        key = (round(eta, 6), start, scene, sweep.equilibrate, sweep.measure, sweep.blocks, sweep.observables)
        groups.setdefault(key, []).append(point)
    joined = []
    for members in groups.values():
        eta, start, _, sweep, values, first = members[0]
        total = sum(m[2] for m in members)
        row = dict(first)
        for name in sweep.observables:
            mean, se = sweeps.pooled([(int(m[5]["repeats"]) * sweep.blocks, float(m[5][name]),
                                       float(m[5][f"{name}_se"])) for m in members])
            row[name], row[f"{name}_se"] = repr(mean), repr(se)
        row["task_seconds"] = repr(sum(float(m[5]["task_seconds"]) for m in members))
        joined.append((eta, start, total, sweep, values, row) if len(members) > 1 else members[0])
    return joined


def plot(points, longest, path):
    """beta P d^2 against the area fraction: each start's rows, filled where the row is the
    point's longest measurement (`longest`: {(start, area fraction): time measured}), and the
    published series of the sweeps' N and box."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from circles import reference
    from circles.scene import Scene

    fig, axes = plt.subplots(1, 2, figsize=(10, 4.2), dpi=100)
    scene = Scene.from_dict(sweeps.scene_fields(points[0][3].scene, points[0][4], 0))
    published = reference.series(scene.n, scene.box[0] / scene.box[1])
    for ax in axes:  # all points, and the loop close up
        ax.errorbar([p.eta for p in published], [p.beta_p_d2 for p in published], yerr=[p.se for p in published],
                    color="0.3", lw=1, label=f"Li et al. 2022 (ECMC), N = {scene.n}")
        for k, start in enumerate(dict.fromkeys(p[1] for p in points)):
            shift = (k - 0.5) * 0.0006  # the starts side by side at each area fraction
            for best in (True, False):
                rows = [(eta, float(row["reduced_pressure"]), float(row["reduced_pressure_se"]))
                        for eta, s, measured, _, _, row in points
                        if s == start and (measured == longest[(s, round(eta, 6))]) == best]
                if rows:
                    ax.errorbar([r[0] + shift for r in rows], [r[1] for r in rows], yerr=[r[2] for r in rows],
                                fmt="o", ms=4, capsize=2, color=f"C{k}", mfc=f"C{k}" if best else "white",
                                label=f"{start} start" + ("" if best else ", shorter runs"))
        ax.set_xlabel("area fraction")
        ax.set_ylabel("reduced pressure beta P d^2")
    axes[0].set_xlim(min(p[0] for p in points) - 0.003, max(p[0] for p in points) + 0.003)
    loop_from = 0.6925  # the loop's panel: from here on, holding every point it shows, error bars and all
    axes[1].set_xlim(loop_from, max(p[0] for p in points) + 0.002)
    near = [(float(row["reduced_pressure"]), float(row["reduced_pressure_se"])) for eta, *_, row in points
            if eta > loop_from]
    axes[1].set_ylim(min(8.9, min(p - e for p, e in near) - 0.01), max(9.17, max(p + e for p, e in near) + 0.01))
    axes[1].set_title("the loop", fontsize=10)
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


if __name__ == "__main__":
    main()
