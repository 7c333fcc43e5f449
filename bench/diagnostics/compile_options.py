"""How long the first step of a scene takes to compile with and without Taichi's CFG
optimisation, and whether the two compilations give the same state.

    python bench/diagnostics/compile_options.py [--scheme event discrete] [--precision f32 f64] [--steps 20]

Each (scheme, precision, option) runs in a fresh process with an empty Taichi cache of its
own, so every kernel compiles: a small scene (400 mixed radii, walls) is set up, its first
step timed (compilation and all), then `--steps` more steps run and the state is hashed.
Prints a Markdown table: first-step seconds with the pass (Taichi's default, what circles
uses) and without (what the test suite uses), and whether the hashes agree.
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
    args = parser.parse_args()
    print("| scheme | precision | first step, with the pass (s) | without (s) | same state | pair collisions |")
    print("|---|---|---|---|---|---|")
    for scheme in args.scheme:
        for precision in args.precision:
            on = run(scheme, precision, args.steps, {})
            off = run(scheme, precision, args.steps, {"cfg_optimization": False})
            print(f"| {scheme} | {precision} | {on['first_s']:.1f} | {off['first_s']:.1f} | "
                  f"{'yes' if on['hash'] == off['hash'] else 'NO'} | {on['pairs']} |", flush=True)


if __name__ == "__main__":
    main()
