"""The flags that shape a scene, shared by `circles run` and `circles compress`: the showcase
scene, the scene flags and their checks, the box sized by --area-fraction, and a start from a
GSD frame (--from, a scene file's ``from``).
"""
import argparse
import math
import os

from .command import UsageError, sweep_or_scene
from .scene import STARTS

SHOWCASE_SCENE = {
    "n": 1500,
    "box": [16.0, 9.0],
    "radius": [0.03, 0.08],
    "speed": [0.5, 1.5],
    "mass": "radius",
    "seed": 1,
}
def add_scene_flags(parser):
    """The flags that shape a random scene (over a scene file's fields), for `run` and `compress`."""
    scene = parser.add_argument_group("scene", scene_defaults_text())
    scene.add_argument("--n", type=circle_count, help="number of circles (1000000, 1_000_000 or 1e6); "
                       "alone, the showcase's box grows with it, keeping its area fraction")
    scene.add_argument("--box", type=float, nargs=2, metavar=("W", "H"), help="box size")
    scene.add_argument("--area-fraction", type=float, metavar="PHI",
                       help="size the box for the circles to fill this fraction of it, with the aspect "
                            "of --box (16:9 without it)")
    scene.add_argument("--radius", type=float, nargs="+", metavar="R",
                       help="radius R, or a range RMIN RMAX")
    scene.add_argument("--speed", type=float, nargs="+", metavar="V",
                       help="speed range VMIN VMAX (or one speed V)")
    scene.add_argument("--mass", choices=("radius", "area", "equal"),
                       help="mass proportional to the radius, to the area, or equal")
    scene.add_argument("--boundary", choices=("walls", "periodic"))
    scene.add_argument("--scheme", choices=("event", "discrete"),
                       help="event: exact collisions; discrete: fast, approximate")
    scene.add_argument("--precision", choices=("f32", "f64"))
    scene.add_argument("--dt", type=float, help="step length in simulated seconds")
    scene.add_argument("--seed", type=int)
    scene.add_argument("--crystal", type=int, nargs=2, metavar=("NX", "NY"),
                       help="a triangular crystal's columns and rows (NY even): n = NX NY equal circles in the "
                            "periodic box of aspect NX : NY sqrt(3)/2 that it fits, sized by --area-fraction")
    scene.add_argument("--species", type=species_entry, nargs="+", metavar="COUNT:R",
                       help="circles of several sizes, in place of --radius: COUNT circles (or a FRACTION of --n) of "
                            "radius R each, e.g. --species 500:0.5 500:0.7")
    scene.add_argument("--start", choices=STARTS,
                       help="fluid: circles placed at random (the default); crystal: on the perfect crystal of "
                            "--crystal; compressed: placed at half the area fraction and compressed to it (a fluid "
                            "above freezing too)")


def species_entry(text):
    """COUNT:RADIUS or FRACTION:RADIUS, as a Scene's species entry."""
    amount, _, radius = text.partition(":")
    try:
        size = float(radius)
        if amount.strip().isdigit():
            return {"count": int(amount), "radius": size}
        return {"fraction": float(amount), "radius": size}
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not COUNT:RADIUS or FRACTION:RADIUS (e.g. 500:0.5 or "
                                         "0.5:0.5)") from None


def circle_count(text):
    """A number of circles as written on the command line: 1000000, 1_000_000 or 1e6."""
    try:
        return int(text)
    except ValueError:
        pass
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number of circles: write it as 1000000, "
                                         "1_000_000 or 1e6") from None
    if not math.isfinite(value) or value != int(value):
        raise argparse.ArgumentTypeError(f"{text} is not a whole number of circles: give a whole number "
                                         "such as 1000000, 1_000_000 or 1e6")
    return int(value)


def scene_defaults_text():
    """What the scene flags default to, for --help."""
    from .scene import DEFAULT_BOX, Scene

    def text(fields):
        return ", ".join(f"{name} {' '.join(f'{x:g}' for x in value) if isinstance(value, (list, tuple)) else value}"
                         for name, value in fields.items())

    fields = {name: getattr(Scene, name) for name in Scene.__dataclass_fields__}
    fields["box"] = DEFAULT_BOX
    del fields["area_fraction"], fields["aspect"]
    fields["dt"] = "chosen from the scene"
    return (f"Without SCENE.toml, the showcase: {text(SHOWCASE_SCENE)}. A field that the showcase or "
            f"the file leaves out, and no flag sets, takes Scene's default: {text(fields)}.")


def scene_overrides(args):
    overrides = {}
    for key in ("n", "mass", "boundary", "scheme", "precision", "dt", "seed", "start"):
        value = getattr(args, key)
        if value is not None:
            overrides[key] = value
    if args.box is not None:
        overrides["box"] = list(args.box)
    if args.crystal is not None:
        overrides["crystal"] = list(args.crystal)
    if args.species is not None:
        overrides["species"] = list(args.species)
    for key in ("radius", "speed"):
        values = getattr(args, key)
        if values is not None:
            if len(values) > 2:
                raise UsageError(f"argument --{key}: give one value or a range MIN MAX, "
                                 f"not {len(values)} values")
            overrides[key] = values[0] if len(values) == 1 else list(values)
    return overrides


RANDOM_SCENE_FLAGS = ("n", "radius", "speed", "seed", "area_fraction", "crystal", "start", "species")


def sized_scene_fields(fields, overrides, args):
    """The scene's fields, flags over the file's, with the box made by --area-fraction (the
    aspect of the box given, 16:9 without one) or, for the showcase given --n alone, grown
    with n so that the showcase's area fraction is kept. A --box flag takes the place of the
    file's area_fraction and aspect, and --area-fraction that of its box (of the file's aspect
    where it gives one)."""
    from .scene import DEFAULT_BOX, Scene, box_for_area_fraction, check_box

    merged = {**fields, **overrides}
    if "box" in overrides:
        merged.pop("area_fraction", None)
        merged.pop("aspect", None)
    if "species" in overrides:  # a flag's sizes over the file's; counts fix n
        merged.pop("radius", None)
        if "n" not in overrides and all("count" in entry for entry in overrides["species"]):
            merged.pop("n", None)
    elif "radius" in overrides:
        merged.pop("species", None)
    if merged.get("crystal") is not None:
        # The crystal fixes n and the box's aspect; Scene makes the box from the area fraction.
        if "crystal" in overrides and "n" not in overrides:
            merged.pop("n", None)
        if args.area_fraction is not None:
            merged.pop("box", None)
            merged["area_fraction"] = args.area_fraction
        return merged
    phi = args.area_fraction
    if phi is None and not args.scene and "n" in overrides and not {"box", "radius"} & set(overrides):
        phi = Scene.from_dict(SHOWCASE_SCENE).area_fraction
    if phi is not None:
        if merged.get("aspect") is not None and merged.get("box") is None:
            merged["area_fraction"] = phi  # Scene makes the box, of the file's aspect
            return merged
        width, height = check_box(merged.pop("box", None) or DEFAULT_BOX)
        merged.pop("area_fraction", None)
        if merged.get("species") is not None:  # Scene makes the box, of this aspect, from the species' radii
            species = Scene.from_dict({**merged, "area_fraction": phi}).species
            merged["box"] = list(box_for_area_fraction(sum(c for c, _ in species), (min(r for _, r in species),
                                                       max(r for _, r in species)), phi, width / height,
                                                       species=species))
        else:
            merged["box"] = list(box_for_area_fraction(merged.get("n", Scene.n), merged.get("radius", Scene.radius),
                                                       phi, width / height))
    return merged


#: What a scene file may give beside ``from``: what a frame leaves open.
FRAME_KEYS = ("from", "speed", "seed", "mass", "scheme", "precision", "dt")


def frame_source(args, fields):
    """The GSD frame a run starts from: --from, or a scene file's ``from`` (a path from the
    file's folder); None for a scene of its own."""
    if getattr(args, "from_", None) is not None:
        return args.from_
    if args.scene and "from" in fields:
        source = fields["from"]
        if not isinstance(source, str):
            raise UsageError(f"{args.scene}: from = {source!r} must be a string: \"FILE.gsd\" or \"FILE.gsd:FRAME\"")
        return source if os.path.isabs(source) else os.path.join(os.path.dirname(args.scene) or ".", source)
    return None


def scene_from_frame(source, fields, args):
    """The `CircleList` of the GSD frame `source`, with the speeds, seed, mass model, scheme,
    precision and dt of the scene file's `fields` and the flags over them (`circles.frames`);
    a flag or key that would shape another scene is refused."""
    from .frames import circle_list_from_gsd
    from .scene import Scene

    where = f"{args.scene}: " if args.scene else ""
    given = [f"--{key.replace('_', '-')}" for key in ("n", "radius", "area_fraction", "box", "crystal", "start",
                                                     "species") if getattr(args, key, None) is not None]
    given += [key for key in fields if key not in FRAME_KEYS]
    if given:
        raise UsageError(f"{where}{', '.join(given)} shape{'s' if len(given) == 1 else ''} a scene of its own, and the "
                         f"run starts from {source}: drop {'it' if len(given) == 1 else 'them'}, or drop the frame")
    values = {**{k: v for k, v in fields.items() if k != "from"}, **scene_overrides(args)}
    try:
        speed = Scene(n=1, box=(1.0, 1.0), radius=0.1, speed=values.get("speed", Scene.speed)).speed
        return circle_list_from_gsd(source, speed=speed, seed=values.get("seed", 0), mass=values.get("mass", "radius"),
                                    scheme=values.get("scheme"), precision=values.get("precision"),
                                    dt=values.get("dt"))
    except (ValueError, TypeError) as error:
        raise UsageError(f"{where}{error}") from None


def random_scene(fields, args):
    """The `Scene` of a scene file's fields (or the showcase's) with the scene flags of `args`
    over them; a UsageError naming the file when it is refused."""
    from .scene import Scene

    try:
        return Scene.from_dict(sized_scene_fields(fields, scene_overrides(args), args))
    except (ValueError, TypeError) as error:
        where = f"{args.scene}: " if args.scene else ""
        raise UsageError(f"{where}{error}") from None


def read_scene_file(path, run_keys=()):
    """(fields, the [run] table) of a scene file; a UsageError for a sweep file, a [run] that is
    no table, or [run] keys not in `run_keys`."""
    from .scene import read_toml

    try:
        data = read_toml(path)
    except ValueError as error:
        raise UsageError(str(error)) from None
    if sweep_or_scene(data) == "sweep":
        raise UsageError(f"{path} is a sweep file (tables [scene], [vary], [sweep]), not a scene file: run it with "
                         f"circles sweep {path}")
    run = data.pop("run", {})
    if not isinstance(run, dict):
        raise UsageError(f"{path}: run must be a table [run], not {run!r}")
    unknown = sorted(set(run) - set(run_keys))
    if unknown:
        raise UsageError(f"{path}: unknown [run] key(s) {', '.join(unknown)}: known keys "
                         f"are {', '.join(run_keys)}")
    return data, run
