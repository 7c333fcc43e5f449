"""Side-by-side speed of this tree's engine against an earlier commit, in one run.

    python bench/diagnostics/versus.py --base 0686cb3 [--n 100000 1000000] [--scheme discrete event] [--rounds 3]
                           [--arch cpu|gpu] [--steps K] [--warm W] [--scene bench|spread] [--interleave]
                           [--batch B]

The earlier commit is exported with `git archive` into a temporary folder. Each row runs the
same scene (bench.py's throughput scene: area fraction 0.3, 16:9 walls, f32, radius 0.5, speeds
in (0.5, 1.0), default dt; seed 1; or with `--scene spread` the radius-spread mixture of
bench.py's spread rows, or with `--scene dense` bench/dense.py's scene) in fresh processes, alternating base and this tree `--rounds` times (base first in even
rounds, this tree first in odd ones), so that the load of a shared machine falls on both alike; each process times single steps after `--warm` warm-up steps
(16 by default, which compile every kernel, the periodic reorder's included; more to time a
relaxed scene, whose speeds have spread out).
Reported: median circle-steps/s of each engine with [min, max] over all its timed steps, the
ratio this / base, and the pair collisions and energy change of each (the same scene and the
same physics must give the same counts: a speed-up that changes them is not one). The ratio is
a median of paired ratios, not the ratio of the two medians (the two can differ: 1.009 with
9.55 M against 9.58 M): without `--interleave`, each round's two processes (one per engine, run
back to back) give one ratio, this process's median speed over the base's, and the column
gives the median over the rounds with [min, max].

With `--interleave`, each round is one process that holds both engines (the base's package
imported as `circles_base`) and steps them in turn, one step each, the first of each pair
alternating: the machine's load, which on a shared machine changes by tens of percent within
minutes, then falls on both within a fraction of a second. The ratio column is then the median
over the pairs of steps of base step time / this step time, with the quartiles, and the speeds
are the medians of each engine's steps. `--batch B` (with `--interleave`) times calls of
`step(B)` in turn instead of single steps, each reported per step: bench.py's throughput rows
call `step(k)` with k in the tens to thousands, and a call's end checks the state once, which
single steps pay every step.
"""
import argparse
import json
import os
import shutil
import subprocess
import sys
import tarfile
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
DIAGNOSTICS = Path(__file__).resolve().parent
sys.path.insert(0, str(ROOT / "bench"))
from bench import engine_revision  # noqa: E402  (the name bench.py gives the engine in its tables)

#: One engine's run: the scene and the step timing of kernel_profile.py (from this tree's bench/diagnostics/,
#: whichever engine `circles` is imported from).
CHILD = """
import json, sys
import numpy as np
import circles
n, scheme, steps = int(sys.argv[1]), sys.argv[2], int(sys.argv[3])
sys.path.insert(0, sys.argv[4])
from kernel_profile import bench_scene, time_steps
circles.init(arch=sys.argv[5])
if sys.argv[6] == "spread":
    from bench import spread_start
    pos, vel, radius, box = spread_start(n, "f32")
    sim = circles.Simulation.from_arrays(pos, vel, radius, mass="radius", box=box, scheme=scheme, precision="f32")
else:
    sim = circles.Simulation(bench_scene(n, scheme, seed=1))
sim.step(int(sys.argv[7]))  # compiles every kernel of a step, the reorder of every 16th step included
times, pairs, energy_change, _ = time_steps(sim, steps)
print(json.dumps({"times": times.tolist(), "pairs": int(pairs), "energy_change": energy_change}))
"""


#: Both engines in one process, stepped in turn (`--interleave`).
PAIRED = """
import json, os, sys, time
import taichi as ti
n, scheme, steps = int(sys.argv[1]), sys.argv[2], int(sys.argv[3])
sys.path.insert(0, sys.argv[4])
sys.path.insert(0, sys.argv[6])
import circles, circles_base
from kernel_profile import bench_scene
circles.init(arch=sys.argv[5])
circles_base.backend._state.update(initialized=True, arch=circles.backend.current_arch())  # one runtime for both
sims = {}
for name, pkg in (("base", circles_base), ("this", circles)):
    if sys.argv[9] == "dense":  # bench/dense.py's scene: equal disks from a crystal near melting
        sys.path.insert(0, os.path.dirname(sys.argv[4]))
        from dense import scene as dense_scene
        sims[name] = pkg.Simulation(dense_scene(pkg, n, 0.698 if n == 870 else 0.70, scheme=scheme))
        sims[name].step(int(sys.argv[7]))
        continue
    scene = bench_scene(n, scheme, seed=1)
    # The fields both engines' Scene take (an older one may lack some, such as area_fraction).
    sims[name] = pkg.Simulation(pkg.Scene(**{f: getattr(scene, f) for f in scene.__dataclass_fields__
                                             if f in pkg.Scene.__dataclass_fields__}))
    sims[name].step(int(sys.argv[7]))  # compiles every kernel of a step, the reorder of every 16th step included
start = {k: s.stats() for k, s in sims.items()}
times = {"base": [], "this": []}
batch = int(sys.argv[8])
for k in range(steps):
    for name in (("base", "this") if k % 2 == 0 else ("this", "base")):
        ti.sync()
        t0 = time.perf_counter()
        sims[name].step(batch)
        ti.sync()
        times[name].append((time.perf_counter() - t0) / batch)
out = {}
for name, sim in sims.items():
    end = sim.stats()
    out[name] = {"times": times[name], "pairs": end["pair_collisions"] - start[name]["pair_collisions"],
                 "energy_change": end["kinetic_energy"] / start[name]["kinetic_energy"] - 1}
print(json.dumps(out))
"""


def check_base(parser, base):
    """`base` as a folder holding an exported tree, or else as a git revision that names a commit
    (`git rev-parse --verify`); anything else is a command-line error, before any work."""
    if os.path.isdir(base):
        if not os.path.isdir(os.path.join(base, "circles")):
            parser.error(f"--base {base} is a folder without circles/: give a folder holding an exported tree "
                         "of the engine, or a git revision")
        return
    out = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--verify", f"{base}^{{commit}}"], capture_output=True,
                         text=True)
    if out.returncode != 0:
        message = " ".join((out.stderr or out.stdout).split()) or f"exit status {out.returncode}"
        parser.error(f"--base {base} names no commit of {ROOT} (git: {message}): give a commit, a branch or a tag, "
                     "or a folder holding an exported tree")


def child(args, **kwargs):
    """stdout of a child process; its failure ends this run with one line, the child's last error line."""
    out = subprocess.run(args, capture_output=True, text=True, **kwargs)
    if out.returncode != 0:
        lines = (out.stderr or out.stdout).strip().splitlines()
        sys.exit(f"versus.py: a child process failed (exit status {out.returncode}): "
                 f"{lines[-1] if lines else 'no message'}")
    return out.stdout


def export(ref, into):
    """The tree of commit `ref` written into the folder `into`."""
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", "--format=tar", ref], capture_output=True,
                             check=True).stdout
    tar_path = Path(into) / "tree.tar"
    tar_path.write_bytes(archive)
    with tarfile.open(tar_path) as tar:
        tar.extractall(into, filter="data")
    tar_path.unlink()


def run(tree, n, scheme, steps, arch, scene, warm):
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(tree)] + [p for p in [os.environ.get("PYTHONPATH")] if p]))
    out = child([sys.executable, "-c", CHILD, str(n), scheme, str(steps), str(DIAGNOSTICS), arch, scene, str(warm)],
                env=env, cwd=str(tree))
    return json.loads(out.strip().splitlines()[-1])


def run_paired(base_tree, scratch, n, scheme, steps, arch, warm, batch=1, scene="bench"):
    """Both engines in one process (`PAIRED`): the base tree's package copied as `circles_base` into
    the folder `scratch` (a temporary one: a folder given as --base is only read)."""
    pkg_dir = Path(scratch) / "paired"
    if not (pkg_dir / "circles_base").is_dir():
        shutil.copytree(Path(base_tree) / "circles", pkg_dir / "circles_base")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT)] + [p for p in [os.environ.get("PYTHONPATH")] if p]))
    out = child([sys.executable, "-c", PAIRED, str(n), scheme, str(steps), str(DIAGNOSTICS), arch, str(pkg_dir),
                 str(warm), str(batch), scene], env=env, cwd=str(ROOT))
    return json.loads(out.strip().splitlines()[-1])


def parse_args():
    """The command line, checked (the base revision included) before any work."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--base", required=True,
                        help="the earlier commit (any git revision), or a folder holding its exported tree")
    parser.add_argument("--n", type=int, nargs="+", default=[100_000, 1_000_000],
                        help="circles of each row (default: 100000 1000000)")
    parser.add_argument("--scheme", nargs="+", default=["discrete", "event"], choices=["discrete", "event"],
                        help="(default: discrete event)")
    parser.add_argument("--rounds", type=int, default=3,
                        help="processes per engine and row, alternating (default: 3)")
    parser.add_argument("--arch", choices=("cpu", "gpu"), default="cpu", help="(default: cpu)")
    parser.add_argument("--steps", type=int, default=0,
                        help="timed steps (calls of step(B) with --batch) per process (default 0: 2e7 / N discrete, "
                             "2e6 / N event, 3 to 20)")
    parser.add_argument("--warm", type=int, default=16,
                        help="warm-up steps before the timed ones (at least 16; default: 16)")
    parser.add_argument("--scene", choices=("bench", "spread", "dense"), default="bench",
                        help="spread: bench.py's radius-spread mixture (1%% of the circles 50 times larger; "
                             "dense: bench/dense.py's equal disks from a crystal at 0.70, 0.698 for --n 870, "
                             "with --interleave; default: bench)")
    parser.add_argument("--interleave", action="store_true",
                        help="both engines in one process, stepped in turn (see above); the bench scene only")
    parser.add_argument("--batch", type=int, default=1,
                        help="with --interleave: steps per timed call (step(B)), reported per step (default: 1)")
    args = parser.parse_args()
    small = [n for n in args.n if n < 1]
    if small:
        parser.error(f"--n {' '.join(map(str, small))}: give 1 or more circles per row")
    if args.rounds < 1:
        parser.error(f"--rounds {args.rounds}: give 1 or more rounds")
    if args.steps < 0:
        parser.error(f"--steps {args.steps}: give 1 or more timed steps per process, or 0 for the default")
    if args.batch < 1:
        parser.error(f"--batch {args.batch}: give 1 or more steps per timed call")
    if args.batch > 1 and not args.interleave:
        parser.error(f"--batch {args.batch} needs --interleave: leave out --batch or add --interleave")
    if args.warm < 16:
        parser.error(f"--warm {args.warm} is below 16: the timed steps would include the first reorder's "
                     "compilation; give 16 or more")
    if args.interleave and args.scene == "spread":
        parser.error("--interleave runs the bench and dense scenes, not --scene spread: leave out one of the two")
    if args.scene == "dense" and not args.interleave:
        parser.error("--scene dense runs with --interleave only: add it")
    check_base(parser, args.base)
    return args


def measure_row(args, base_tree, scratch, n, scheme, steps):
    """Speeds (circle-steps/s of every timed step) of each engine, the ratios this / base of the
    pairs (see the module's docstring), and each engine's last result (pairs, energy change)."""
    speeds = {"base": [], "this": []}
    ratios, last = [], {}
    for r in range(args.rounds):
        if args.interleave:
            result = run_paired(base_tree, scratch, n, scheme, steps, args.arch, args.warm, args.batch, args.scene)
            ratios += [b / t for b, t in zip(result["base"]["times"], result["this"]["times"])]
        else:
            # Which tree runs first alternates too: on a loaded machine the first of two
            # back-to-back processes measured 10 to 20% faster, whichever tree it ran.
            pair = (("base", base_tree), ("this", ROOT))
            result = {name: run(tree, n, scheme, steps, args.arch, args.scene, args.warm)
                      for name, tree in (pair if r % 2 == 0 else pair[::-1])}
            median = {name: np.median([n / t for t in result[name]["times"]]) for name in result}
            ratios.append(float(median["this"] / median["base"]))
        for name in speeds:
            speeds[name] += [n / t for t in result[name]["times"]]
            last[name] = result[name]
    return speeds, ratios, last


def main():
    args = parse_args()
    what = "radius-spread mixture, " if args.scene == "spread" else ""
    how = (", stepped in turn in one process" if args.interleave else "") + f", {args.warm} warm-up steps"
    if args.batch > 1:
        how += f", timed in calls of step({args.batch})"
    scene = ("equal disks from a triangular crystal, area fraction 0.70 (0.698 at N = 870), periodic, f64, "
             "default dt") if args.scene == "dense" else f"{what}area fraction 0.3, walls, f32, default dt"
    print(f"base {args.base} against this tree ({engine_revision()}) on the {args.arch}{how}; {scene}")
    if args.interleave:
        print("Ratio this / base: the median over all pairs of steps of base step time / this step time, with its "
              "quartiles; a median of paired ratios, not the ratio of the two speed columns' medians.\n")
        ratio = "ratio this / base, paired steps median [q25, q75]"
    else:
        print(f"Ratio this / base: one per round (two processes back to back), this process's median speed over "
              f"the base's; the median over the {args.rounds} rounds with [min, max]: a median of paired ratios, not "
              "the ratio of the two speed columns' medians.\n")
        ratio = "ratio this / base, rounds median [min, max]"
    print(f"| N | scheme | base circle-steps/s median [min, max] | this circle-steps/s median [min, max] | {ratio} "
          "| base pairs, energy change | this pairs, energy change |")
    print("|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        if os.path.isdir(args.base):
            base_tree = args.base
        else:
            base_tree = os.path.join(tmp, "base")
            os.makedirs(base_tree)
            export(args.base, base_tree)
        for n in args.n:
            for scheme in args.scheme:
                steps = args.steps or max(3, min(20, int(2e6 // n) if scheme == "event" else int(2e7 // n)))
                speeds, ratios, last = measure_row(args, base_tree, tmp, n, scheme, steps)
                med = {k: float(np.median(v)) for k, v in speeds.items()}
                if args.interleave:
                    q25, q50, q75 = np.percentile(ratios, [25, 50, 75])
                    ratio = f"{q50:.3f} [{q25:.3f}, {q75:.3f}]"
                else:
                    ratio = f"{np.median(ratios):.3f} [{min(ratios):.3f}, {max(ratios):.3f}]"
                cells = [f"{med[k] / 1e6:.3g} M [{min(speeds[k]) / 1e6:.3g}, {max(speeds[k]) / 1e6:.3g}]"
                         for k in ("base", "this")]
                facts = [f"{last[k]['pairs']}, {last[k]['energy_change']:.2g}" for k in ("base", "this")]
                print(f"| {n} | {scheme} | {cells[0]} | {cells[1]} | {ratio} | {facts[0]} | {facts[1]} |", flush=True)


if __name__ == "__main__":
    main()
