"""Compression to jamming and to a density, measured: the numbers of the docs' Compression page.

    python bench/compress_packings.py [--out FILE.md]
    python bench/compress_packings.py --speed N [--rate R] [--out FILE.md]

- Jamming: the 50:50 mixture of diameters 1 and 1.4 (equal masses, periodic box), from area
  fraction 0.3 until Z > 1e6, at rates 0.01 (fast) and 0.001 (the default to jamming), several
  seeds at N = 256 and 1024: the jamming fraction, the disks left once rattlers (fewer than 3
  contacts) are taken away, their mean contact number (gaps below 1e-4 of the contact
  distance) against the isostatic 4 - 2/N', the events and the wall time.
- The free-volume law: each N = 256 packing of the default rate with every radius shrunk by
  1 - delta, run at fixed radii (the growth engine with no growth) for 200 collisions a disk:
  Z (1 - phi/phi_J), which tends to 2 (the dimension) near jamming.
- Crystallisation: 256 equal disks compressed slowly (rate 1e-3) to area fraction 0.80: the
  global hexatic order and the mean of the local |psi_6|.
- With --speed N, only the speed (to compress_speed_N.md, or _rR.md with --rate): N disks of
  the mixture from 0.3, to jamming for N = 1e5 (or below), to 0.80 above, at the command's
  default rate or R.
"""
import argparse
import math
import sys
import time
from datetime import date
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))
from bench import cpu_model  # noqa: E402


def mixture(n, seed):
    from circles.scene import Scene

    return Scene(species=[{"count": n // 2, "radius": 0.5}, {"count": n - n // 2, "radius": 0.7}], n=n,
                 area_fraction=0.3, boundary="periodic", mass="equal", speed=1.0, seed=seed)


def free_volume(done, delta, collisions=200):
    """Z (1 - phi/phi_J) of the packing of `done` with radii shrunk by 1 - delta, at fixed radii."""
    from circles import compress, growth

    state = done.simulation.state()
    box = tuple(done.simulation.box)
    radius = state.radius * (1 - delta)
    engine = compress._Engine(state.pos, state.vel, radius, state.mass, box, True)
    n = len(radius)
    kt = float(np.sum(state.mass * np.sum(state.vel ** 2, axis=1))) / (2 * (n - 1))
    engine.layout(0.0, 0.0, 1.0)
    engine.run(math.inf, 20 * n)  # settle
    engine.synchronise(float(engine.totals[growth.TIME]))
    start, virial = float(engine.totals[growth.TIME]), float(engine.totals[growth.VIRIAL])
    engine.tau[:] = start
    engine.layout(start, 0.0, 1.0)
    engine.run(math.inf, collisions * n)
    span = float(engine.totals[growth.TIME]) - start
    z = 1 + (float(engine.totals[growth.VIRIAL]) - virial) / (2 * span * n * kt)
    phi = float(np.sum(np.pi * radius ** 2)) / (box[0] * box[1])
    return phi, z, z * (1 - phi / done.area_fraction)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--speed", type=float, metavar="N", help="only the speed of N disks: to jamming up to 1e5, "
                                                                  "to 0.80 above")
    parser.add_argument("--rate", type=float, help="with --speed: the growth rate (default: the command's)")
    parser.add_argument("--out", help="the table (default outputs/bench/amd-epyc/compress.md, or compress_speed.md "
                                      "with --speed)")
    args = parser.parse_args()
    folder = ROOT / "outputs" / "bench" / "amd-epyc"
    size = f"1e{round(math.log10(args.speed))}" if args.speed else None  # 1e5, 1e6
    tail = f"_r{args.rate:g}" if args.rate else ""
    args.out = args.out or str(folder / (f"compress_speed_{size}{tail}.md" if args.speed else "compress.md"))
    import circles
    from circles import compress
    from circles.order import hexatic_order, psi6
    from circles.scene import Scene

    circles.init("cpu")
    compress.compress(mixture(64, 0), 0.5)  # the kernels compiled before any timing
    if args.speed:
        lines = [f"# Compression: speed ({cpu_model()}, one thread, {date.today()})", "",
                 f"Made by `python bench/compress_packings.py --speed {size}"
                 f"{f' --rate {args.rate:g}' if args.rate else ''}`: the 50:50 mixture of diameters 1 and 1.4, "
                 "periodic box.", "",
                 "| N | from | to | rate | phi reached | Z | contacts a disk (isostatic) | events | events/s | wall s |",
                 "|---|---|---|---|---|---|---|---|---|---|"]
        n = int(args.speed)
        for to in ("jammed" if n <= 100_000 else 0.80,):
            rate = args.rate or compress.default_rate(to)
            tick = time.perf_counter()
            done = compress.compress(mixture(n, 1), to, rate=rate)
            wall = time.perf_counter() - tick
            contacts = "-"
            if to == "jammed":
                z, kept = compress.contact_number(done.simulation)
                contacts = f"{z:.3f} ({4 - 2 / kept:.3f})"
            lines.append(f"| {n:.0e} | 0.3 | {to} | {rate:g} | {done.area_fraction:.4f} | {done.compressibility:.3g} | "
                         f"{contacts} | {done.events} | {done.events / done.wall_s:.3g} | {wall:.0f} |")
            print(lines[-1], flush=True)
        Path(args.out).write_text("\n".join(lines) + "\n")
        print(f"wrote {args.out}")
        return
    lines = [f"# Compression: jamming, the free-volume law, crystallisation ({cpu_model()}, one thread, "
             f"{date.today()})", "", "Made by `python bench/compress_packings.py`.", "", "## Jamming of the 50:50 mixture of diameters 1 and 1.4 (Z > 1e6)", "",
             "| rate | N | seed | phi_J | Z | disks kept (no rattlers) | contacts a disk | isostatic 4 - 2/N' | events | "
             "wall s |", "|---|---|---|---|---|---|---|---|---|---|"]
    packings = []
    for rate in (0.01, compress.JAMMING_RATE):
        fractions = []
        for n, seeds in ((256, range(1, 6)), (1024, range(1, 4))):
            for seed in seeds:
                done = compress.compress(mixture(n, seed), "jammed", rate=rate)
                z, kept = compress.contact_number(done.simulation)
                lines.append(f"| {rate:g} | {n} | {seed} | {done.area_fraction:.4f} | {done.compressibility:.3g} | "
                             f"{kept} | {z:.3f} | {4 - 2 / kept:.3f} | {done.events} | {done.wall_s:.1f} |")
                print(lines[-1], flush=True)
                if n == 256:
                    fractions.append(done.area_fraction)
                    if rate == compress.JAMMING_RATE:
                        packings.append(done)
        lines.append(f"| {rate:g} | 256 | mean and spread | {np.mean(fractions):.4f} +- {np.std(fractions, ddof=1):.4f} "
                     "| | | | | | |")
    lines += ["", "O'Hern et al. (2003): 0.842 for large N, from fast quenches.", "",
              f"## The free-volume law near jamming (the packings of rate {compress.JAMMING_RATE:g}, N = 256, radii shrunk by 1 - delta, 200 collisions a disk)", "",
              "| seed | delta | phi | Z | Z (1 - phi/phi_J) |", "|---|---|---|---|---|"]
    for seed, done in enumerate(packings, 1):
        for delta in (1e-3, 1e-4):
            phi, z, law = free_volume(done, delta)
            lines.append(f"| {seed} | {delta:g} | {phi:.6f} | {z:.4g} | {law:.3f} |")
            print(lines[-1], flush=True)
    lines += ["", "## Equal disks compressed slowly (N = 256, rate 1e-3, to 0.80)", "",
              "| seed | hexatic order abs(psi_6) | mean local abs(psi_6) | events | wall s |", "|---|---|---|---|---|"]
    for seed in (1, 2):
        scene = Scene(n=256, radius=0.5, area_fraction=0.3, boundary="periodic", mass="equal", speed=1.0, seed=seed)
        done = compress.compress(scene, 0.80, rate=1e-3)
        local = psi6(done.simulation.state().pos, done.simulation.box, True)
        lines.append(f"| {seed} | {hexatic_order(local):.3f} | {np.mean(np.abs(local)):.3f} | {done.events} | "
                     f"{done.wall_s:.1f} |")
        print(lines[-1], flush=True)
    Path(args.out).write_text("\n".join(lines) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
