"""Scene files that list their circles one by one, for exact set-ups (Newton's cradle, ...).

Such a file has, instead of the random-scene fields ``n``, ``radius``, ``speed`` and
``seed``, an array of tables ``[[circle]]``::

    box = [16.0, 9.0]          # top level as in a random scene: box, boundary, scheme,
    scheme = "event"           # precision, dt, and mass (the default mass model)

    [[circle]]
    pos = [2.0, 4.5]
    vel = [2.0, 0.0]
    radius = 0.5
    mass = 1.0                 # optional: default by the top-level mass model
    color = [220, 60, 40]      # optional: 0-255 RGB

    [run]                      # run options, as in any scene file
    duration = 5.0

`read_circle_list` reads such a file and `circle_list_from_dict` checks its contents; both
return a `CircleList` whose fields are the arguments of ``circles.Simulation.from_arrays``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from numbers import Real

import numpy as np

from .scene import (BOUNDARIES, DEFAULT_BOX, MASS_MODELS, PRECISIONS, SCHEMES, Scene, _choice, check_box,
                    check_dt, read_scene_toml)

#: The table name of one circle in a scene file: ``[[circle]]``.
CIRCLE_KEY = "circle"
#: Top-level keys of a random scene that make no sense when the circles are listed.
RANDOM_SCENE_KEYS = ("n", "radius", "speed", "seed", "area_fraction")
#: Top-level keys a file with ``[[circle]]`` entries may hold (``[run]`` is taken off before).
TOP_LEVEL_KEYS = (CIRCLE_KEY, "box", "boundary", "scheme", "precision", "dt", "mass")
CIRCLE_KEYS = ("pos", "vel", "radius", "mass", "color")
REQUIRED_CIRCLE_KEYS = ("pos", "vel", "radius")


def lists_circles(data: dict) -> bool:
    """Whether the contents of a scene file list their circles (hold ``[[circle]]`` entries)."""
    return CIRCLE_KEY in data


@dataclass(frozen=True)
class CircleList:
    """Circles given one by one, checked, in file order (circle i is the (i+1)-th entry).

    pos (n, 2), vel (n, 2), radius (n,), mass (n,): float64. color: (n, 3) uint8, or None
    when no entry gives one (from_arrays then picks colours). box, boundary, scheme,
    precision, dt: as in `circles.Scene`. These are the arguments of
    ``circles.Simulation.from_arrays(pos, vel, radius, mass=, box=, boundary=, scheme=,
    precision=, dt=, color=)``.
    """

    pos: np.ndarray
    vel: np.ndarray
    radius: np.ndarray
    mass: np.ndarray
    color: np.ndarray | None
    box: tuple
    boundary: str
    scheme: str
    precision: str
    dt: float | None

    @property
    def n(self) -> int:
        return int(self.radius.shape[0])


def read_circle_list(path) -> CircleList:
    """Read a scene file that lists its circles (``[[circle]]`` entries), ignoring ``[run]``.

    Raises ValueError, with one line that names the file, the circle and the fix, for
    invalid TOML, a file without ``[[circle]]`` entries, and anything
    `circle_list_from_dict` refuses.
    """
    data = read_scene_toml(path)
    if not lists_circles(data):
        raise ValueError(f"{path}: no [[circle]] entries: it describes a random scene, read it "
                         "with circles.Scene.from_toml")
    try:
        return circle_list_from_dict(data)
    except ValueError as error:
        raise ValueError(f"{path}: {error}") from None


def circle_list_from_dict(data: dict) -> CircleList:
    """Check the contents of a scene file with ``[[circle]]`` entries and return the circles.

    ``data`` is the file's top level without its ``[run]`` table: ``circle``, a list of
    tables, each with ``pos = [x, y]``, ``vel = [vx, vy]``, ``radius = r`` and optionally
    ``mass = m`` (default: the top-level ``mass`` model, "radius" when absent, as in
    `circles.Scene`) and ``color = [r, g, b]`` (0-255); and optionally ``box``,
    ``boundary``, ``scheme``, ``precision``, ``dt`` (defaults as in `circles.Scene`).

    Refused with a ValueError of one line: random-scene keys (n, radius, speed, seed) next
    to the circles, unknown keys, a missing ``pos``/``vel``/``radius``, values of the wrong
    length, type or sign, non-finite numbers, a circle not inside the walls (or too large
    for a periodic box), and two circles that overlap. Circles are named by their index in
    the file, from 0 (the order of ``Simulation.state()``).
    """
    mixed = [key for key in RANDOM_SCENE_KEYS if key in data]
    if mixed:
        raise ValueError(f"{', '.join(mixed)} describe a random scene, but the file lists its "
                         "circles with [[circle]] entries: remove "
                         f"{'it' if len(mixed) == 1 else 'them'} or the [[circle]] entries")
    unknown = sorted(set(data) - set(TOP_LEVEL_KEYS))
    if unknown:
        raise ValueError(f"unknown key(s) {', '.join(unknown)} next to [[circle]] entries: known "
                         f"keys are {', '.join(TOP_LEVEL_KEYS)} and the [run] table")
    entries = data[CIRCLE_KEY]
    if not isinstance(entries, list) or not entries:
        raise ValueError(f"circle = {entries!r} must be a non-empty array of tables: give each "
                         "circle as a [[circle]] table with pos, vel and radius")
    box = check_box(data.get("box", DEFAULT_BOX))
    boundary = _choice("boundary", data.get("boundary", Scene.boundary), BOUNDARIES)
    scheme = _choice("scheme", data.get("scheme", Scene.scheme), SCHEMES)
    precision = _choice("precision", data.get("precision", Scene.precision), PRECISIONS)
    dt = check_dt(data.get("dt", Scene.dt))
    model = _choice("mass model", data.get("mass", Scene.mass), MASS_MODELS)

    n = len(entries)
    pos, vel = np.empty((n, 2)), np.empty((n, 2))
    radius = np.empty(n)
    mass = np.full(n, np.nan)
    color = np.zeros((n, 3), dtype=np.uint8)
    has_color = np.zeros(n, dtype=bool)
    for i, entry in enumerate(entries):
        name = _circle_name(i)
        if not isinstance(entry, dict):
            raise ValueError(f"{name} = {entry!r} must be a table: write it as [[circle]] with "
                             "pos, vel and radius")
        unknown = sorted(set(entry) - set(CIRCLE_KEYS))
        if unknown:
            raise ValueError(f"{name}: unknown key(s) {', '.join(unknown)}: a circle has "
                             f"{', '.join(CIRCLE_KEYS)}")
        for key in REQUIRED_CIRCLE_KEYS:
            if key not in entry:
                example = {"pos": "pos = [x, y]", "vel": "vel = [vx, vy]",
                           "radius": "radius = r"}[key]
                raise ValueError(f"{name}: {key} is missing: give {example}")
        pos[i] = _pair(name, "pos", entry["pos"], "[x, y]")
        vel[i] = _pair(name, "vel", entry["vel"], "[vx, vy]")
        radius[i] = _positive(name, "radius", entry["radius"])
        if "mass" in entry:
            mass[i] = _positive(name, "mass", entry["mass"],
                                f"or leave it out for the mass model {model!r}")
        if "color" in entry:
            color[i] = _color(name, entry["color"])
            has_color[i] = True

    from .inputs import masses_for, place_slack, random_colors

    _check_inside(pos, radius, box, boundary, place_slack(precision, box))
    _check_no_overlap(pos, radius, box, boundary)

    default_mass = masses_for(model, radius)
    mass = np.where(np.isnan(mass), default_mass, mass)
    if not has_color.any():
        colors = None
    else:
        # Circles without a colour get the one from_arrays would have given them.
        colors = np.where(has_color[:, None], color, random_colors(n, np.random.default_rng(0)))
    return CircleList(pos=pos, vel=vel, radius=radius, mass=mass, color=colors, box=box,
                      boundary=boundary, scheme=scheme, precision=precision, dt=dt)


def _circle_name(i):
    ordinal = {1: "st", 2: "nd", 3: "rd"}.get((i + 1) % 10 if (i + 1) % 100 not in (11, 12, 13)
                                              else 0, "th")
    return f"circle {i} (the {i + 1}{ordinal} [[circle]])"


def _number(value):
    return isinstance(value, Real) and not isinstance(value, bool)


def _pair(name, key, value, shape):
    if not isinstance(value, list) or len(value) != 2 or not all(map(_number, value)):
        raise ValueError(f"{name}: {key} = {value!r} must be two numbers {shape}")
    if not all(math.isfinite(v) for v in value):
        raise ValueError(f"{name}: {key} = {value!r} is not finite: give finite numbers {shape}")
    return [float(v) for v in value]


def _positive(name, key, value, alternative=""):
    fix = f"give a finite number > 0{' ' + alternative if alternative else ''}"
    if not _number(value):
        raise ValueError(f"{name}: {key} = {value!r} is not a number: {fix}")
    if not math.isfinite(value) or value <= 0:
        raise ValueError(f"{name}: {key} = {value!r} must be finite and > 0: {fix}")
    return float(value)


def _color(name, value):
    if not isinstance(value, list) or len(value) != 3 or not all(
            isinstance(c, int) and not isinstance(c, bool) and 0 <= c <= 255 for c in value):
        raise ValueError(f"{name}: color = {value!r} must be three whole numbers [r, g, b] "
                         "from 0 to 255")
    return value


def _check_inside(pos, radius, box, boundary, slack):
    """Every circle inside the walls, or across one by at most `slack` (the rounding of a place),
    tested as `Simulation.from_arrays` tests it (`simulation.outside_walls`)."""
    w, h = box
    if boundary == "periodic":
        # Positions wrap around the torus; a circle must not meet two images of one neighbour.
        too_big = np.flatnonzero(4.0 * radius >= min(w, h))
        if too_big.size:
            i = int(too_big[0])
            r = float(radius[i])
            raise ValueError(f"{_circle_name(i)}: radius = {r!r} is too large for the "
                             f"periodic box {w} x {h}: each side must exceed two diameters "
                             f"({4.0 * r:.6g}); use a smaller circle or a bigger box")
        return
    from .inputs import outside_walls

    outside = outside_walls(pos, radius, box, slack)
    if outside.any():
        i = int(np.flatnonzero(outside)[0])
        r = float(radius[i])
        if 2 * r > min(w, h):  # no place inside: the box, not the place, is the fix
            raise ValueError(f"{_circle_name(i)}: radius = {r!r} is too large for the box {w} x {h} (diameter "
                             f"{2 * r:.6g} > side {min(w, h)}): use a smaller circle or a bigger box")
        raise ValueError(f"{_circle_name(i)}: pos = {pos[i].tolist()!r} with radius = {r!r} is "
                         f"not inside the walls [0, {w}] x [0, {h}]: move it to x in "
                         f"[{r:.6g}, {w - r:.6g}] and y in [{r:.6g}, {h - r:.6g}]")


def _check_no_overlap(pos, radius, box, boundary):
    """Refuse the first overlapping pair (lowest i, then j) beyond from_arrays' tolerance."""
    pair = first_overlap(pos, radius, box, boundary)
    if pair is not None:
        i, j, distance = pair
        contact = float(radius[i] + radius[j])
        raise ValueError(f"{_circle_name(i)} and circle {j} overlap: their centres are "
                         f"{distance:.6g} apart, less than the sum of their radii {contact:.6g}: "
                         "move them apart (touching is allowed)")


def first_overlap(pos, radius, box, boundary):
    """(i, j, distance of the centres) of the overlapping pair with the lowest i, then j, beyond
    from_arrays' tolerance (`inputs.INPUT_OVERLAP_TOLERANCE` of the contact distance); None
    when no pair overlaps.

    Sweep along x: circles sorted by x are compared with the k-th next one, k = 1, 2, ...,
    until every such gap in x exceeds the largest contact distance. On a torus the sweep
    wraps around and gaps are minimum images.
    """
    from .inputs import INPUT_OVERLAP_TOLERANCE

    n = radius.shape[0]
    w, h = box
    periodic = boundary == "periodic"
    wrapped = pos % np.array([w, h]) if periodic else pos
    order = np.argsort(wrapped[:, 0], kind="stable")
    x, y, r = wrapped[order, 0], wrapped[order, 1], radius[order]
    reach = 2.0 * float(radius.max())
    bad = []
    for k in range(1, n):
        a = np.arange(n if periodic else n - k)
        b = (a + k) % n
        dx = x[b] - x[a]
        if periodic:
            dx = np.where(b < a, dx + w, dx)  # the forward gap across the seam
        if dx.min() > reach:
            break
        dy = y[b] - y[a]
        if periodic:
            dx = np.minimum(dx, w - dx)
            dy = dy - h * np.round(dy / h)
        contact = r[a] + r[b]
        overlap = (contact - np.sqrt(dx * dx + dy * dy)) / contact
        for m in np.flatnonzero(overlap > INPUT_OVERLAP_TOLERANCE):
            i, j = sorted((int(order[a[m]]), int(order[b[m]])))
            bad.append((i, j))
    if not bad:
        return None
    i, j = min(bad)
    return i, j, float(np.hypot(*_image(pos[j] - pos[i], box, periodic)))


def _image(d, box, periodic):
    if not periodic:
        return d
    return d - np.array(box) * np.round(d / np.array(box))
