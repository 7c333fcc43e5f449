"""The observables and trajectories against physics: the pressure two independent ways, the
wall pressure against the virial, and diffusion against Enskog's theory.

    python bench/data_validation.py [--n 4000] [--frames 40] [--out outputs/data/validation.md]

1. A periodic box of N disks (diameter 1, equal masses) at area fraction 0.45: after an
   equilibration of `--equilibrate` time units (about 4 collisions a disk per unit), a GSD
   frame and a stats row every unit of time. Z from the virial (the rows' compressibility)
   against Z = 1 + 2 eta g(sigma+) from freud's RDF of the frames (`analysis.contact_values`).
   The mean squared displacement from the frames' image flags against 4 D_E t.
2. A walled box at area fraction 0.3: the wall pressure against the virial pressure over the
   same intervals.

Errors are standard errors of the mean over frames or intervals (one time unit apart, a few
collisions a disk: close to independent).
"""
import argparse
import datetime
import math
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import circles  # noqa: E402
from circles import analysis  # noqa: E402
from circles.trajectory import GSDWriter, ImageTracker  # noqa: E402
from circles.writers import Run, StatsWriter, read_stats  # noqa: E402


def box_for(n, eta, radius):
    side = math.sqrt(n * math.pi * radius * radius / eta)
    return side, side


def bulk(n, eta, frames, equilibrate, folder, seed=1):
    """Pressure two ways and diffusion, in a periodic box at area fraction eta."""
    import gsd.hoomd

    radius = 0.5
    box = box_for(n, eta, radius)
    sim = circles.Simulation(circles.Scene(n=n, box=box, radius=radius, speed=(1.0, 1.0), mass="equal",
                                           boundary="periodic", seed=seed))
    sim.advance(equilibrate)
    path, table_path = folder / "bulk.gsd", folder / "bulk.csv"
    with GSDWriter(path, tracker=ImageTracker(sim)) as trajectory, StatsWriter(table_path) as table:
        for _ in Run(sim, float(frames), 1.0, at_frame=[trajectory], at_interval=[table]):
            pass
    rows = read_stats(table_path)
    z_virial, z_virial_err = analysis.mean_error(rows["compressibility"])
    with gsd.hoomd.open(str(path)) as traj:
        snaps = list(traj)
    g = analysis.contact_values(snaps, 2 * radius)
    g_mean, g_err = analysis.mean_error(g)
    g_fine = analysis.mean_error(analysis.contact_values(snaps, 2 * radius, width=0.01, bins=12))
    z_rdf, z_rdf_err = 1 + 2 * eta * g_mean, 2 * eta * g_err
    state = sim.state()
    mass = float(state.mass[0])
    kT = float(np.mean(rows["temperature"]))
    density = n / (box[0] * box[1])
    lags, msd = analysis.squared_displacements(snaps)
    rate, rate_err = analysis.mean_error(rows["collision_rate"])
    d_enskog = analysis.enskog_diffusion(density, 2 * radius, g_mean, kT, mass)
    omega_enskog = analysis.enskog_collision_rate(density, 2 * radius, g_mean, kT, mass)
    mean_free_time = 1.0 / rate
    return {
        "n": n, "eta": eta, "box": box, "frames": frames, "equilibrate": equilibrate,
        "z_virial": (z_virial, z_virial_err), "z_rdf": (z_rdf, z_rdf_err), "contact": (g_mean, g_err), "contact_fine": g_fine,
        "z_henderson": analysis.henderson_compressibility(eta), "kT": kT, "mass": mass,
        "collision_rate": (rate, rate_err), "omega_enskog": omega_enskog, "d_enskog": d_enskog,
        "mean_free_time": mean_free_time, "lags": lags, "msd": msd,
    }


def walled(n, eta, intervals, equilibrate, seed=2):
    """Wall and virial pressures over the same intervals, in a walled box at area fraction eta
    of the area open to the centres."""
    radius = 0.5
    side = box_for(n, eta, radius)[0] + 2 * radius
    sim = circles.Simulation(circles.Scene(n=n, box=(side, side), radius=radius, speed=(1.0, 1.0), mass="equal",
                                           boundary="walls", seed=seed))
    sim.advance(equilibrate)
    rows = []

    class Rows:
        def write(self, row):
            rows.append(row)

    for _ in Run(sim, float(intervals), 1.0, at_interval=[Rows()]):
        pass
    wall = np.array([row["wall_pressure"] for row in rows])
    virial = np.array([row["pressure"] for row in rows])
    return {"n": n, "eta": eta, "box": side, "intervals": intervals, "wall": analysis.mean_error(wall),
            "virial": analysis.mean_error(virial), "difference": analysis.mean_error(wall - virial)}


def msd_slopes(result):
    """D from the MSD's slope between lags: (lag range, D / D_E)."""
    lags, msd = result["lags"], result["msd"]
    out = []
    for lo, hi in ((1, 5), (5, 10), (10, 20)):
        if hi <= len(msd):
            slope = (msd[hi - 1] - msd[lo - 1]) / (lags[hi - 1] - lags[lo - 1])
            out.append(((lo, hi), slope / 4 / result["d_enskog"]))
    return out


def machine():
    """The processor's model name (Linux), else what platform knows."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as file:
            for line in file:
                if line.startswith("model name"):
                    return f"{line.split(':', 1)[1].strip()}, {os.cpu_count()} logical CPUs"
    except OSError:
        pass
    return platform.processor() or platform.machine()


def report(bulk_result, wall_result, seconds, command):
    b, w = bulk_result, wall_result
    pm = lambda pair, digits=4: f"{pair[0]:.{digits}f} ± {pair[1]:.{digits}f}"  # noqa: E731
    diff = b["z_rdf"][0] - b["z_virial"][0]
    sigma = math.hypot(b["z_rdf"][1], b["z_virial"][1])
    lines = [
        "# Observables and trajectories against physics",
        "",
        f"Machine: {machine()}, {datetime.date.today().isoformat()}, "
        f"circles on the CPU. Command: `{command}` ({seconds:.0f} s).",
        "",
        f"## Pressure two ways (periodic, N = {b['n']}, area fraction {b['eta']})",
        "",
        f"Box {b['box'][0]:.3f} x {b['box'][1]:.3f}, disks of diameter 1 and equal mass, "
        f"{b['equilibrate']:g} time units of equilibration, then {b['frames']} frames one time unit apart "
        f"(kT = {b['kT']:.4f}, {b['collision_rate'][0] / 1:.3f} collisions a disk per unit time).",
        "",
        "| quantity | value |",
        "|---|---|",
        f"| Z from the virial (mean of {b['frames']} intervals) | {pm(b['z_virial'])} |",
        f"| g(sigma+) from freud's RDF, extrapolated | {pm(b['contact'])} |",
        f"| the same from bins half as wide (12 of 0.01) | {pm(b['contact_fine'])} |",
        f"| g(sigma+) that the virial's Z implies, (Z - 1) / (2 eta) | "
        f"{(b['z_virial'][0] - 1) / (2 * b['eta']):.4f} |",
        f"| Z = 1 + 2 eta g(sigma+) | {pm(b['z_rdf'])} |",
        f"| difference | {diff:+.4f} ({abs(diff) / sigma:.2f} standard errors) |",
        f"| Henderson's equation of state (reference) | {b['z_henderson']:.4f} |",
        "",
        "## Wall pressure against the virial (walled box)",
        "",
        f"N = {w['n']}, box {w['box']:.3f} x {w['box']:.3f}, area fraction {w['eta']} of the area open to "
        f"the centres, {w['intervals']} intervals of one time unit.",
        "",
        "| quantity | value |",
        "|---|---|",
        f"| wall pressure | {pm(w['wall'], 5)} |",
        f"| virial pressure | {pm(w['virial'], 5)} |",
        f"| wall - virial, interval by interval | {pm(w['difference'], 5)} |",
        "",
        "## Collisions and diffusion against Enskog (periodic run above)",
        "",
        "| quantity | value |",
        "|---|---|",
        f"| collision rate measured | {pm(b['collision_rate'])} |",
        f"| Enskog's 2 n sigma g(sigma+) sqrt(pi kT / m) | {b['omega_enskog']:.4f} |",
        f"| mean free time 1 / rate | {b['mean_free_time']:.4f} |",
        f"| D_E = sqrt(kT / (pi m)) / (2 n sigma g(sigma+)) (Gass 1971) | {b['d_enskog']:.4f} |",
    ]
    for (lo, hi), ratio in msd_slopes(b):
        lines.append(f"| D / D_E from the MSD's slope over lags {lo} to {hi} | {ratio:.3f} |")
    lines += ["", "MSD by lag (time units): " + ", ".join(f"{lag}: {value:.3f}" for lag, value in
                                                          zip(b["lags"][:20], b["msd"][:20])), ""]
    return "\n".join(lines)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--n", type=int, default=4000)
    parser.add_argument("--eta", type=float, default=0.45)
    parser.add_argument("--frames", type=int, default=40)
    parser.add_argument("--equilibrate", type=float, default=20.0)
    parser.add_argument("--wall-n", type=int, default=1000)
    parser.add_argument("--wall-intervals", type=int, default=40)
    parser.add_argument("--out", default="outputs/data/validation.md")
    args = parser.parse_args()
    circles.init("cpu")
    started = time.perf_counter()
    with tempfile.TemporaryDirectory() as folder:
        b = bulk(args.n, args.eta, args.frames, args.equilibrate, Path(folder))
    w = walled(args.wall_n, 0.3, args.wall_intervals, args.equilibrate)
    seconds = time.perf_counter() - started
    command = "python bench/data_validation.py " + " ".join(sys.argv[1:])
    text = report(b, w, seconds, command.strip())
    print(text)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(text)


if __name__ == "__main__":
    main()
