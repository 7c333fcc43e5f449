"""The benchmark's dense section: equal hard disks near melting, where collisions are many.

    python bench/dense.py [--out FOLDER] [--quick] [--ecmc PATH [--ecmc-length 8]]

Writes FOLDER/<machine>/dense.md, dense.csv and dense.png (default FOLDER: outputs/bench):
- pair collisions per second of the event scheme at area fraction 0.70 (0.698 at N = 870, the
  melting sweep's box) for N = 870, 16384 and 1e6, on one thread and on two;
- the same on one thread at 0.45 and 0.70 for N from 1024 to 1e6 (the plot);
- the figure of merit of the pressure at N = 870, 0.698, one thread: the standard error of
  beta P d^2 times the square root of the CPU seconds of the measurement, and the CPU seconds
  that a standard error of 0.01 takes, pooled over independent runs;
- with `--ecmc PATH`, the same for event-chain Monte Carlo on the same disks in the same box,
  in the same run: Li et al.'s program, built by the user (bench/peer_ecmc.py).

Every scene: radius 0.5, mass 1, all speeds 1 at the start, a periodic box that fits a
triangular crystal of nx columns and ny rows, started from that crystal, f64, default dt. Each
row runs in a process of its own (Taichi's threads are set when it starts); a row warms up for
a number of collisions a circle, then measures. `--quick`: shorter runs and no 1e6 rows.
"""
import argparse
import csv
import json
import math
import os
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

#: N = 870: the melting sweep's crystal of 29 columns and 30 rows; other N: square crystals.
MELTING_N, MELTING_CRYSTAL = 870, (29, 30)
#: The rows of the thread table: (N, area fraction).
THREAD_ROWS = ((870, 0.698), (16384, 0.70), (1_000_000, 0.70))
#: The plot's sizes, at each of its area fractions, on one thread.
CURVE_SIZES = (1024, 16384, 262144, 1_000_000)
CURVE_FRACTIONS = (0.45, 0.70)
#: Collisions a circle takes part in before the measurement, and during it; and pair
#: collisions at least in each, so that a small N is measured over many steps.
WARM_COLLISIONS = 20.0
MEASURE_COLLISIONS = 10.0
LEAST_WARM_PAIRS = 2e6
LEAST_MEASURED_PAIRS = 5e6
#: The figure of merit's runs: equilibration and measurement in time units, in blocks, and
#: independent repeats (seeds 1, 2, ...), whose standard errors are pooled: one run's estimate
#: from its blocks is itself uncertain by about a quarter.
MERIT = dict(n=870, fraction=0.698, equilibrate=2000.0, measure=20000.0, block=2000.0, repeats=4)
QUICK_MERIT = dict(n=870, fraction=0.698, equilibrate=500.0, measure=4000.0, block=500.0, repeats=2)


def crystal_of(n):
    """(columns, rows) of the crystal of n disks: the melting sweep's for 870, else nx by nx,
    for n the square of an even nx (a periodic triangular crystal has an even number of rows)."""
    if n == MELTING_N:
        return MELTING_CRYSTAL
    nx = math.isqrt(n)
    if nx * nx != n or nx % 2:
        raise ValueError(f"n = {n}: give {MELTING_N} or the square of an even number (a crystal of nx by nx rows)")
    return nx, nx


def scene(circles, n, fraction, seed=1, scheme="event"):
    """The dense section's scene in the package `circles` (an older engine's, for versus.py):
    n equal disks from their crystal, in the periodic box that fits it, speeds 1, f64."""
    nx, ny = crystal_of(n)
    return circles.Scene(n=n, crystal=[nx, ny], area_fraction=fraction, radius=0.5, speed=[1.0, 1.0],
                         mass="equal", boundary="periodic", start="crystal", precision="f64", seed=seed,
                         scheme=scheme)


def run_rate(n, fraction, threads, scale):
    """One row: pair collisions per second and per CPU second over the measurement."""
    import circles
    circles.init(arch="cpu", cpu_max_num_threads=threads)
    t0 = time.perf_counter()
    sim = circles.Simulation(scene(circles, n, fraction))
    place_s = time.perf_counter() - t0
    # Enskog's estimate of the collisions a circle takes part in per unit time sets the lengths.
    from circles.schemes import collision_rate
    st = sim.state()
    omega = collision_rate(st.radius, st.vel, sim.box)
    # Pair collisions per unit time: n omega / 2.
    sim.advance(scale * max(WARM_COLLISIONS * n / 2, LEAST_WARM_PAIRS) / (n * omega / 2))
    before = sim.stats()["pair_collisions"]
    wall, cpu = time.perf_counter(), time.process_time()
    sim.advance(scale * max(MEASURE_COLLISIONS * n / 2, LEAST_MEASURED_PAIRS) / (n * omega / 2))
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    pairs = sim.stats()["pair_collisions"] - before
    return dict(n=n, area_fraction=fraction, threads=threads, dt=sim.dt, steps=sim.steps, place_s=place_s,
                collisions=pairs, wall_s=wall, cpu_s=cpu, collisions_per_s=pairs / wall,
                collisions_per_cpu_s=pairs / cpu)


def run_merit(cfg, seed):
    """One run of the pressure's error against CPU seconds at N = 870, 0.698, one thread: the
    block means of beta P d^2 over the measurement and its CPU seconds."""
    import circles
    from circles import observables
    circles.init(arch="cpu", cpu_max_num_threads=1)
    sim = circles.Simulation(scene(circles, cfg["n"], cfg["fraction"], seed))
    sim.advance(cfg["equilibrate"])
    blocks = int(round(cfg["measure"] / cfg["block"]))
    values, cpu, first = [], 0.0, sim.stats()
    start = first
    for _ in range(blocks):
        t = time.process_time()
        sim.advance(cfg["block"])
        cpu += time.process_time() - t
        now = sim.stats()
        values.append(observables.interval(start, now, sim.n, sim.box, sim.boundary, 0.5, 1.0)["reduced_pressure"])
        start = now
    return dict(seed=seed, cpu_s=cpu, collisions=now["pair_collisions"] - first["pair_collisions"], blocks=values)


def merit_row(cfg, runs):
    """The repeats pooled: the standard error of one run's mean from its blocks, as the root mean
    square over the repeats, beside the scatter of the repeats' means (the two agree when the
    blocks are longer than the pressure's correlation time); the figure of merit SE x sqrt(CPU
    s) of one run, and the CPU seconds to a standard error of 0.01."""
    import numpy as np
    means = np.array([np.mean(r["blocks"]) for r in runs])
    ses = np.array([np.std(r["blocks"], ddof=1) / math.sqrt(len(r["blocks"])) for r in runs])
    cpu = float(np.mean([r["cpu_s"] for r in runs]))
    se = float(np.sqrt(np.mean(ses ** 2)))
    return dict(n=cfg["n"], area_fraction=cfg["fraction"], threads=1, equilibrate=cfg["equilibrate"],
                measure=cfg["measure"], block=cfg["block"], repeats=len(runs), cpu_s=cpu,
                collisions=float(np.mean([r["collisions"] for r in runs])), mean=float(means.mean()),
                se_of_mean=float(means.std(ddof=1) / math.sqrt(len(runs))), se=se,
                se_each=" ".join(f"{x:.4f}" for x in ses), scatter_of_means=float(means.std(ddof=1)),
                merit=se * math.sqrt(cpu), cpu_s_to_se_0_01=cpu * (se / 0.01) ** 2)


def child(args):
    """Run one row in this process and print it as JSON (the parent's subprocess)."""
    kind = args[0]
    if kind == "rate":
        n, fraction, threads, scale = int(args[1]), float(args[2]), int(args[3]), float(args[4])
        print(json.dumps(run_rate(n, fraction, threads, scale)))
    else:
        print(json.dumps(run_merit(json.loads(args[1]), int(args[2]))))


def in_process(*args):
    out = subprocess.run([sys.executable, os.path.abspath(__file__), "--child", *map(str, args)], check=True,
                         capture_output=True, text=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def log(*a):
    print(time.strftime("%H:%M:%S"), *a, flush=True)


def si(v):
    return f"{v / 1e6:.3g} M"


def write(outdir, meta, threads, curve, merit, peer=None):
    rows = [dict(table="threads", **r) for r in threads] + [dict(table="curve", **r) for r in curve]
    if merit:
        rows.append(dict(table="merit", **merit))
    if peer:
        rows.append(dict(table="peer", **peer))
    keys = []
    for r in rows:
        keys += [k for k in r if k not in keys]
    with open(os.path.join(outdir, "dense.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, keys)
        w.writeheader()
        w.writerows(rows)
    lines = [f"# Dense hard disks: {meta['machine']}", "",
             f"Command: `{meta['command']}`  ", f"Date: {meta['date']}  ", f"Machine: {meta['machine']}  ",
             f"Wall time of the run: {meta['wall_s']:.0f} s.", "",
             "Equal disks (radius 0.5, mass 1, speeds 1 at the start) in a periodic box that fits a triangular "
             f"crystal, started from it, f64, default dt; each row warms up for {WARM_COLLISIONS:g} collisions a "
             f"circle and measures {MEASURE_COLLISIONS:g}, and at least {LEAST_WARM_PAIRS:.0e} and "
             f"{LEAST_MEASURED_PAIRS:.0e} pair collisions (Enskog's rate sets the times).", "",
             "## Collisions per second, 1 and 2 threads", "",
             "| N | area fraction | threads | dt | pair collisions/s | per CPU s | measured s |",
             "|---|---|---|---|---|---|---|"]
    for r in threads:
        lines.append(f"| {r['n']} | {r['area_fraction']} | {r['threads']} | {r['dt']:.4g} | "
                     f"{si(r['collisions_per_s'])} | {si(r['collisions_per_cpu_s'])} | {r['wall_s']:.1f} |")
    by = {(r["n"], r["area_fraction"], r["threads"]): r for r in threads}
    for n, fraction in THREAD_ROWS:
        one, two = by.get((n, fraction, 1)), by.get((n, fraction, 2))
        if one and two:
            lines.append("")
            lines.append(f"N = {n}: two threads make {two['collisions_per_s'] / one['collisions_per_s']:.2f} times "
                         "the collisions per second of one.")
    lines += ["", "## Collisions per second against N, one thread", "",
              "| N | area fraction | dt | pair collisions/s |", "|---|---|---|---|"]
    for r in curve:
        lines.append(f"| {r['n']} | {r['area_fraction']} | {r['dt']:.4g} | {si(r['collisions_per_s'])} |")
    if merit:
        m = merit
        lines += ["", "## The pressure's error against CPU time", "",
                  f"N = {m['n']}, area fraction {m['area_fraction']}, one thread, from the crystal: {m['repeats']} "
                  f"runs (seeds 1 to {m['repeats']}) of {m['equilibrate']:g} time units of equilibration, then "
                  f"{m['measure']:g} measured in blocks of {m['block']:g}; a run made {m['collisions']:.3g} pair "
                  f"collisions in {m['cpu_s']:.1f} CPU s of measurement (the mean over the runs).", "",
                  f"- beta P d^2 = {m['mean']:.4f} +- {m['se_of_mean']:.4f} over the runs",
                  f"- one run's standard error from its blocks: {m['se_each']}; pooled (root mean square) "
                  f"{m['se']:.4f}; the scatter of the runs' means {m['scatter_of_means']:.4f}",
                  f"- figure of merit SE x sqrt(CPU s) = {m['merit']:.3f}",
                  f"- CPU seconds to a standard error of 0.01: {m['cpu_s_to_se_0_01']:.0f}"]
    if merit and peer:
        p, m = peer, merit
        lines += ["", "## Event-chain Monte Carlo, side by side", "",
                  f"{p['peer']}, the same {p['n']} disks at {p['area_fraction']} in the same box, from the crystal, "
                  f"one thread, length factor {p['length']}: {p['events']:.3g} chain events in {p['cpu_s']:.1f} CPU s "
                  f"({p['events_per_cpu_s'] / 1e6:.3g} M a second); its pressure sampled 1000 times, the first 20% "
                  "dropped, the standard error from 10 blocks of the rest (bench/peer_ecmc.py).", "",
                  "| program | beta P d^2 | standard error | CPU s measured | SE x sqrt(CPU s) | CPU s to SE 0.01 |",
                  "|---|---|---|---|---|---|",
                  f"| circles (event-driven MD) | {m['mean']:.4f} | {m['se']:.4f} | {m['cpu_s']:.1f} | {m['merit']:.3f} | "
                  f"{m['cpu_s_to_se_0_01']:.0f} |",
                  f"| event-chain Monte Carlo | {p['mean']:.4f} | {p['se']:.4f} | {p['cpu_s_measured']:.1f} | "
                  f"{p['merit']:.3f} | {p['cpu_s_to_se_0_01']:.0f} |", "",
                  f"circles takes {m['cpu_s_to_se_0_01'] / p['cpu_s_to_se_0_01']:.2f} times the CPU seconds of "
                  "event-chain Monte Carlo to the same standard error."]
    with open(os.path.join(outdir, "dense.md"), "w") as f:
        f.write("\n".join(lines) + "\n")


def plot(outdir, curve):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6, 4))
    for fraction in CURVE_FRACTIONS:
        rows = sorted((r for r in curve if r["area_fraction"] == fraction), key=lambda r: r["n"])
        if rows:
            ax.plot([r["n"] for r in rows], [r["collisions_per_s"] / 1e6 for r in rows], "o-",
                    label=f"area fraction {fraction}")
    ax.set_xscale("log")
    ax.set_xlabel("N")
    ax.set_ylabel("pair collisions per second (millions)")
    ax.set_title("event scheme, one thread")
    ax.set_ylim(bottom=0)
    ax.legend()
    fig.tight_layout()
    fig.savefig(os.path.join(outdir, "dense.png"), dpi=100)


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["--child"]:
        return child(argv[1:])
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=os.path.join("outputs", "bench"), help="folder of the results")
    ap.add_argument("--quick", action="store_true", help="shorter runs, no 1e6 rows")
    ap.add_argument("--ecmc", default=None, help="the StraightEcmc program of Li et al. 2022, built by you "
                    "(bench/peer_ecmc.py), run side by side at N = 870, 0.698")
    ap.add_argument("--ecmc-length", type=int, default=8, help="its length factor (default 8: about 1.6e9 events)")
    args = ap.parse_args(argv)
    if args.ecmc is not None:
        import peer_ecmc
        if peer_ecmc.missing(args.ecmc):
            ap.error(peer_ecmc.missing(args.ecmc))
        try:
            import h5py  # noqa: F401  (reads the peer's output)
        except ImportError:
            ap.error("--ecmc needs h5py to read the program's output: pip install h5py")
    from bench import cpu_model, slug
    machine = cpu_model()
    outdir = os.path.join(args.out, slug(machine))
    os.makedirs(outdir, exist_ok=True)
    start = time.perf_counter()
    scale = 0.25 if args.quick else 1.0
    big = (lambda n: n < 1_000_000) if args.quick else (lambda n: True)
    threads, curve, merit = [], [], None
    meta = dict(machine=machine, command="python " + " ".join([os.path.relpath(__file__)] + argv),
                date=time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()))
    for n, fraction in THREAD_ROWS:
        if big(n):
            for k in (1, 2):
                r = in_process("rate", n, fraction, k, scale)
                threads.append(r)
                log(f"N={n} eta={fraction} threads={k}: {si(r['collisions_per_s'])} collisions/s, dt {r['dt']:.4g}")
    for fraction in CURVE_FRACTIONS:
        for n in CURVE_SIZES:
            if big(n):
                r = in_process("rate", n, fraction, 1, scale)
                curve.append(r)
                log(f"N={n} eta={fraction}: {si(r['collisions_per_s'])} collisions/s, dt {r['dt']:.4g}")
    cfg = QUICK_MERIT if args.quick else MERIT
    merit = merit_row(cfg, [in_process("merit", json.dumps(cfg), seed) for seed in range(1, cfg["repeats"] + 1)])
    log(f"merit: SE {merit['se']:.4f} in {merit['cpu_s']:.1f} CPU s: {merit['merit']:.3f}; "
        f"{merit['cpu_s_to_se_0_01']:.0f} CPU s to SE 0.01")
    peer = None
    if args.ecmc:
        import peer_ecmc
        peer = peer_ecmc.run(args.ecmc, *crystal_of(cfg["n"]), cfg["fraction"], args.ecmc_length)
        log(f"event-chain Monte Carlo: SE {peer['se']:.4f} in {peer['cpu_s_measured']:.1f} CPU s: "
            f"{peer['merit']:.3f}; {peer['cpu_s_to_se_0_01']:.0f} CPU s to SE 0.01")
    meta["wall_s"] = time.perf_counter() - start
    write(outdir, meta, threads, curve, merit, peer)
    plot(outdir, curve)
    log(f"wrote {outdir}/dense.md, dense.csv, dense.png")


if __name__ == "__main__":
    main()
