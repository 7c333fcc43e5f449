"""How long the first step of a scene takes to compile with and without Taichi's CFG
optimisation, whether the two compilations give the same state, and how fast their kernels
run at the sizes below `backend.OPTIMIZE_FROM_N`, where circles compiles without the pass.

    python bench/diagnostics/compile_options.py [--scheme event discrete] [--precision f32 f64] [--steps 20]
                                                [--speed-rounds 3]

Each (scheme, precision, option) runs in a fresh process with an empty Taichi cache of its
own, so every kernel compiles: a small scene (400 mixed radii, walls) is set up, its first
step timed (compilation and all), then `--steps` more steps run and the state is hashed.
Prints a Markdown table: first-step seconds with the pass and without, and whether the hashes
agree.

Then the speed table: event-scheme collisions per second on one thread, with the pass and
without, each in a process of its own with a warm cache, the two alternating for
`--speed-rounds` rounds; the ratio without / with is given as the median [min, max] of the
rounds' ratios. Scenes: equal disks in a periodic box at area fraction 0.70 (N = 870 and
16384), and 10 000 mixed radii at area fraction 0.3 in a walled box.
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

CHILD = """
import hashlib, json, sys, time
import numpy as np
import circles
scheme, precision, steps, options = sys.argv[1], sys.argv[2], int(sys.argv[3]), json.loads(sys.argv[4])
circles.init(arch="cpu", **options)
sim = circles.Simulation(circles.Scene(n=400, box=(1.0, 1.0), radius=(0.006, 0.012), speed=(0.5, 1.0),
                                       scheme=scheme, precision=precision, seed=5))
t0 = time.perf_counter()
sim.step(1)
first = time.perf_counter() - t0
sim.step(steps)
s = sim.state()
digest = hashlib.sha256(np.ascontiguousarray(s.pos).tobytes() + np.ascontiguousarray(s.vel).tobytes()).hexdigest()
print(json.dumps({"first_s": first, "hash": digest, "pairs": sim.stats()["pair_collisions"]}))
"""


SPEED = """
import json, math, sys, time
import circles
n, eta, mixed, seconds, on = int(sys.argv[1]), float(sys.argv[2]), sys.argv[3] == "mixed", float(sys.argv[4]), \
    sys.argv[5] == "on"
circles.init(arch="cpu", cpu_max_num_threads=1, cfg_optimization=on)
radius = (0.3, 0.7) if mixed else 0.5
mean_area = math.pi * (0.7 ** 3 - 0.3 ** 3) / (3 * 0.4) if mixed else math.pi * 0.25
side = math.sqrt(n * mean_area / eta)
sim = circles.Simulation(circles.Scene(n=n, box=(side, side), radius=radius, speed=1.0, mass="equal",
                                       boundary="walls" if mixed else "periodic", seed=3))
sim.advance(2.0)  # compiled, and the lattice of a dense start melting
before, t0 = sim.stats()["pair_collisions"], time.perf_counter()
end = t0 + seconds
while time.perf_counter() < end:
    sim.advance(1.0)
print(json.dumps({"rate": (sim.stats()["pair_collisions"] - before) / (time.perf_counter() - t0)}))
"""
SPEED_SCENES = ((870, 0.70, "equal"), (16384, 0.70, "equal"), (10_000, 0.30, "mixed"))


def speed(n, eta, radii, on, seconds=4.0):
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    done = subprocess.run([sys.executable, "-c", SPEED, str(n), str(eta), radii, str(seconds), "on" if on else "off"],
                          env=env, capture_output=True, text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])["rate"]


def run(scheme, precision, steps, options):
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, TI_OFFLINE_CACHE_FILE_PATH=cache)
        env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")])
        done = subprocess.run([sys.executable, "-c", CHILD, scheme, precision, str(steps), json.dumps(options)],
                              env=env, capture_output=True, text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scheme", nargs="+", default=["event", "discrete"], choices=["event", "discrete"])
    parser.add_argument("--precision", nargs="+", default=["f64"], choices=["f32", "f64"])
    parser.add_argument("--steps", type=int, default=20)
    parser.add_argument("--speed-rounds", type=int, default=3, help="rounds of the speed table (0: none)")
    args = parser.parse_args()
    print("| scheme | precision | first step, with the pass (s) | without (s) | same state | pair collisions |")
    print("|---|---|---|---|---|---|")
    for scheme in args.scheme:
        for precision in args.precision:
            on = run(scheme, precision, args.steps, {"cfg_optimization": True})
            off = run(scheme, precision, args.steps, {"cfg_optimization": False})
            print(f"| {scheme} | {precision} | {on['first_s']:.1f} | {off['first_s']:.1f} | "
                  f"{'yes' if on['hash'] == off['hash'] else 'NO'} | {on['pairs']} |", flush=True)
    if args.speed_rounds <= 0:
        return
    import statistics
    print()
    print("| scene | with the pass, collisions/s | without | without / with, median [min, max] |")
    print("|---|---|---|---|")
    for n, eta, radii in SPEED_SCENES:
        with_pass, without = [], []
        for _ in range(args.speed_rounds):
            with_pass.append(speed(n, eta, radii, True))
            without.append(speed(n, eta, radii, False))
        ratios = [b / a for a, b in zip(with_pass, without)]
        print(f"| N = {n}, area fraction {eta}, {radii} radii | {statistics.median(with_pass) / 1e6:.3g} M | "
              f"{statistics.median(without) / 1e6:.3g} M | {statistics.median(ratios):.3f} "
              f"[{min(ratios):.3f}, {max(ratios):.3f}] |", flush=True)


if __name__ == "__main__":
    main()
