"""Bad input is refused with a ValueError that names the offending value and
the limit it breaks, before any work is done.

Messages are matched loosely: the offending value must appear (as Python
prints it, or a short form of it) and, where the limit is a number or a list
of choices, the limit too; wording is free.
"""

import math
import os
import re

import numpy as np
import pytest

DENSEST = math.pi / math.sqrt(12.0)  # 0.9069, hexagonal packing of equal disks
ZERO = r"(?<![\d.])0(\.0*)?(?![\d.])"  # 0 or 0.0 standing alone (not 0.01, not 10)


def number(x):
    """Regex for the number x standing alone, as Python prints it or as an
    integer-valued float (-1 or -1.0)."""
    text = re.escape(repr(float(x)) if not float(x).is_integer() else str(int(x)))
    return rf"(?<![\d.]){text}(\.0*)?(?![\d])"


def refused(fn, value=None, limit=None):
    """``fn()`` raises ValueError whose message matches ``value`` and ``limit``
    (regexes, when given); returns the message."""
    with pytest.raises(ValueError, match=value) as info:
        fn()
    message = str(info.value)
    if limit is not None:
        assert re.search(limit, message), f"limit {limit!r} not named in: {message}"
    return message


def scene(circles, **kw):
    """A valid small scene with ``kw`` changed; made into a Simulation so that
    a check done at either stage counts."""
    base = dict(n=100, box=(2.0, 1.0), radius=(0.01, 0.02), speed=(0.5, 1.0), mass="radius",
                boundary="walls", scheme="event", precision="f64", dt=None, seed=0)
    base.update(kw)
    return lambda: circles.Simulation(circles.Scene(**base))


@pytest.mark.parametrize("n", [0, -3])
def test_n_not_positive(circles_cpu, n):
    refused(scene(circles_cpu, n=n), number(n), r"(?<![\d.])[01](?![\d.])")


@pytest.mark.parametrize("radius, shown", [(0.0, ZERO), (-0.01, number(-0.01)),
                                           ((-0.01, 0.02), number(-0.01)), ((0.0, 0.02), ZERO)],
                         ids=["zero", "negative", "range_negative", "range_zero"])
def test_radius_not_positive(circles_cpu, radius, shown):
    refused(scene(circles_cpu, radius=radius), shown, ZERO)


@pytest.mark.parametrize("boundary", ["walls", "periodic"])
def test_radius_larger_than_box(circles_cpu, boundary):
    """Diameter 1.2 in a box whose short side is 1."""
    refused(scene(circles_cpu, n=1, radius=0.6, boundary=boundary), r"0\.6|1\.2", number(1))


@pytest.mark.parametrize("box, shown", [((0.0, 1.0), ZERO), ((2.0, -1.0), number(-1))],
                         ids=["zero_width", "negative_height"])
def test_box_side_not_positive(circles_cpu, box, shown):
    refused(scene(circles_cpu, box=box), shown, ZERO)


@pytest.mark.parametrize("field, value", [
    ("radius", float("nan")),
    ("radius", (0.01, float("inf"))),
    ("box", (float("inf"), 1.0)),
    ("speed", (0.5, float("nan"))),
    ("dt", float("nan")),
    ("dt", float("inf")),
], ids=["radius_nan", "rmax_inf", "box_inf", "vmax_nan", "dt_nan", "dt_inf"])
def test_non_finite_numbers(circles_cpu, field, value):
    refused(scene(circles_cpu, **{field: value}), r"(?i)nan|inf")


@pytest.mark.parametrize("field, value, limit", [
    ("scheme", "rk4", "event"),
    ("boundary", "mirror", "periodic"),
    ("mass", "volume", "area"),
    ("precision", "f16", "f64"),
])
def test_unknown_names(circles_cpu, field, value, limit):
    refused(scene(circles_cpu, **{field: value}), value, limit)


def test_unknown_arch(circles_cpu):
    refused(lambda: circles_cpu.init(arch="tpu"), "tpu", "cpu")


@pytest.mark.parametrize("dt, shown", [(0.0, ZERO), (-0.5, number(-0.5))], ids=["zero", "negative"])
def test_dt_not_positive(circles_cpu, dt, shown):
    refused(scene(circles_cpu, dt=dt), shown, ZERO)


@pytest.mark.parametrize("n, radius, fraction", ids=["equal", "mixed"], argvalues=[
    (121, 0.05, 121 * math.pi * 0.05**2),                         # equal radii: 0.9503
    (120, (0.04, 0.06), 120 * math.pi * (0.04**2 + 0.04 * 0.06 + 0.06**2) / 3),  # 0.9550
])
def test_area_fraction_beyond_densest_packing(circles_cpu, n, radius, fraction):
    """In a unit box; the message names the fraction (2 decimals at least,
    rounded or cut) and the densest packing 0.9069 (3 decimals at least)."""
    assert fraction > DENSEST
    shown = "|".join(re.escape(f"{x:.2f}") for x in (fraction, math.floor(fraction * 100) / 100))
    refused(scene(circles_cpu, n=n, box=(1.0, 1.0), radius=radius), shown, r"0\.9(07|069)|0\.91\b")


def test_a_fraction_just_above_the_densest_packing_is_shown_apart_from_it(circles_cpu):
    """4157 circles of radius 0.1 in 16 x 9 fill 0.90692: shown to 4 places it read 'area
    fraction 0.9069 ... exceeds the densest packing 0.9069'."""
    message = refused(scene(circles_cpu, n=4157, box=(16.0, 9.0), radius=0.1), "0.90692", "0.90690")
    assert "0.9069 " not in message


# ---- Simulation.from_arrays ----------------------------------------------

def arrays(n=4):
    pos = np.array([[0.2, 0.2], [0.6, 0.2], [0.2, 0.6], [0.6, 0.6]])[:n]
    vel = np.full((n, 2), 0.3)
    radius = np.full(n, 0.05)
    return pos, vel, radius


def from_arrays(circles, pos=None, vel=None, radius=None, **kw):
    p, v, r = arrays()
    p = p if pos is None else pos
    v = v if vel is None else vel
    r = r if radius is None else radius
    kw.setdefault("box", (1.0, 1.0))
    return lambda: circles.Simulation.from_arrays(p, v, r, **kw)


def test_from_arrays_non_finite(circles_cpu):
    p, v, r = arrays()
    p[2, 1] = np.nan
    refused(from_arrays(circles_cpu, pos=p), r"(?i)nan")
    p, v, r = arrays()
    v[1, 0] = np.inf
    refused(from_arrays(circles_cpu, vel=v), r"(?i)inf")
    refused(from_arrays(circles_cpu, box=(1.0, np.inf)), r"(?i)inf")


def test_from_arrays_radius_not_positive(circles_cpu):
    p, v, r = arrays()
    r[3] = -0.02
    refused(from_arrays(circles_cpu, radius=r), number(-0.02), ZERO)


def test_from_arrays_radius_larger_than_box(circles_cpu):
    p, v, r = arrays(1)
    refused(from_arrays(circles_cpu, pos=np.array([[0.5, 0.5]]), vel=v, radius=np.array([0.7])),
            r"0\.7|1\.4", number(1))


def test_from_arrays_box_and_names(circles_cpu):
    refused(from_arrays(circles_cpu, box=(1.0, 0.0)), ZERO)
    refused(from_arrays(circles_cpu, scheme="verlet"), "verlet", "event")
    refused(from_arrays(circles_cpu, boundary="open"), "open", "walls")
    refused(from_arrays(circles_cpu, mass="volume"), "volume", "radius")
    refused(from_arrays(circles_cpu, precision="f128"), "f128", "f32")
    refused(from_arrays(circles_cpu, dt=-1.0), number(-1), ZERO)


def test_from_arrays_masses_not_positive(circles_cpu):
    refused(from_arrays(circles_cpu, mass=np.array([1.0, 0.0, 1.0, 1.0])), ZERO)
    refused(from_arrays(circles_cpu, mass=np.array([1.0, 1.0, -2.0, 1.0])), number(-2))


def test_from_arrays_shapes_disagree(circles_cpu):
    p, v, r = arrays()
    refused(from_arrays(circles_cpu, vel=v[:3]), number(3), number(4))
    refused(from_arrays(circles_cpu, radius=r[:2]), number(2), number(4))


def test_from_arrays_colors_are_0_to_255_rgb(circles_cpu):
    """Colours are whole numbers from 0 to 255, one RGB triple a circle; fractions in [0, 1]
    (as some libraries write them) are refused with the fix, where they used to truncate to
    nearly black, and values past 255 with our message, not numpy's."""
    rgb = np.array([[10, 20, 30], [255, 0, 0], [0, 128, 0], [7, 7, 7]])
    made = from_arrays(circles_cpu, color=rgb.astype(np.float64))()
    assert made.state().color.tolist() == rgb.tolist()
    refused(from_arrays(circles_cpu, color=rgb / 255.0), r"circle 0", "multiply by 255")
    refused(from_arrays(circles_cpu, color=np.eye(4, 3)), "from 0 to 1", "multiply by 255")
    refused(from_arrays(circles_cpu, color=rgb + 250), r"circle 0, \[260", number(255))
    refused(from_arrays(circles_cpu, color=-rgb), r"circle 0, \[-10", number(255))
    refused(from_arrays(circles_cpu, color=rgb[:, :2]), r"\(4, 2\)", r"\(4, 3\)")
    refused(from_arrays(circles_cpu, color=rgb > 9), "bool")


@pytest.mark.parametrize("precision", ["f32", "f64"])
def test_a_random_scene_leaves_room_to_place_its_largest_circle(circles_cpu, precision):
    """A walled scene whose circle fills the box's side was accepted and then failed inside the
    placement ("internal error"): it is refused with the largest radius that can be placed,
    and that radius places."""
    message = refused(scene(circles_cpu, n=1, box=(1.0, 1.0), radius=0.5, precision=precision), number(0.5),
                      "no room")
    most = float(re.search(r"at most ([\d.]+)", message).group(1))
    assert 0.4999 < most < 0.5
    placed = circles_cpu.Simulation(circles_cpu.Scene(n=1, box=(1.0, 1.0), radius=most, precision=precision))
    x = placed.state().pos[0]
    assert np.all((x >= most) & (x <= 1.0 - most))


def test_from_arrays_touching_circles_in_f32(circles_cpu):
    """A row of touching circles given in float64 overlaps by float32's rounding once stored
    (3.7e-7 of the contact distance here): it is a contact in f32, not an overlap, as it is
    in f64; an overlap beyond the rounding is still refused."""
    pos = np.array([[0.2, 0.5]] + [[0.37 + 0.1 * k, 0.5] for k in range(5)])
    vel = np.array([[1.0, 0.0]] + [[0.0, 0.0]] * 5)
    radius = np.full(6, 0.05)
    for precision in ("f32", "f64"):
        sim = circles_cpu.Simulation.from_arrays(pos, vel, radius, box=(1.2, 1.0), precision=precision)
        sim.advance(0.2)
        assert sim.state().vel[5, 0] == pytest.approx(1.0, abs=1e-6)  # the cradle passes it on
    closer = pos.copy()
    closer[2, 0] -= 1e-4  # 1e-3 of a contact into circle 1
    refused(lambda: circles_cpu.Simulation.from_arrays(closer, vel, radius, box=(1.2, 1.0), precision="f32"),
            "overlap by 0.001", "tolerance")


def test_masses_of_any_size_within_the_ratio_the_precision_carries(circles_cpu):
    """Only mass ratios change the motion, and the kernels hold masses in a unit of their own (a
    power of two): masses near 2^127 (1.7e38) or 2^-140 (7e-43) in f32, whose inverses were
    lost to float32's range, move bit for bit as masses near 1, with the stats in the masses'
    own unit; a ratio beyond what the precision carries is refused before any work."""
    p, v, r = arrays()
    runs = {}
    for unit in (1.0, 2.0 ** 127, 2.0 ** -140):
        sim = circles_cpu.Simulation.from_arrays(p, v, r, mass=np.array([1.0, 2.0, 3.0, 4.0]) * unit,
                                                 box=(1.0, 1.0), precision="f32")
        sim.advance(3.0)
        runs[unit] = (sim.state(), sim.stats())
    (s1, t1) = runs[1.0]
    assert t1["pair_collisions"] > 0 and t1["wall_collisions"] > 0
    for unit in (2.0 ** 127, 2.0 ** -140):
        s, t = runs[unit]
        assert np.array_equal(s.pos, s1.pos) and np.array_equal(s.vel, s1.vel)
        for key in ("kinetic_energy", "virial", "wall_impulse"):
            assert t[key] == pytest.approx(t1[key] * unit, rel=1e-12), key
    refused(from_arrays(circles_cpu, mass=np.array([1.0, 1e37, 1.0, 1.0]), precision="f32"),
            r"circle 1 \(mass 1e\+37\) is 1e\+37 times as heavy as circle 0", r"1e\+36")
    refused(from_arrays(circles_cpu, mass=np.array([1e-200, 1.0, 1e200, 1.0])), r"is 1e\+400 times", r"1e\+300")
    # Radii 1e18 apart, within f32's lengths (a box 1e4 wide, the least radius 4.8e-16).
    p, v, r = arrays()
    refused(from_arrays(circles_cpu, pos=p * 1e4, vel=v * 10, radius=np.array([500, 4.8e-16, 500, 500]),
                        mass="area", box=(1e4, 1e4), precision="f32"), "times as heavy as circle 1", r"1e\+36")


def test_from_arrays_takes_real_numbers_only(circles_cpu):
    """numpy would turn complex places into real ones (dropping the imaginary part), strings
    into numbers and booleans into 0 and 1: each is refused, naming the array and its type."""
    p, v, r = arrays()
    refused(from_arrays(circles_cpu, pos=p + 1j), "pos", "complex")
    refused(from_arrays(circles_cpu, vel=v.astype(str)), "vel", "<U")
    refused(from_arrays(circles_cpu, radius=r.astype(str)), "radius", "<U")
    refused(from_arrays(circles_cpu, mass=np.ones(4, bool)), "mass", "bool")
    refused(from_arrays(circles_cpu, pos=[[0.2, 0.2], [0.6]] * 2), "pos", "numbers")
    whole = circles_cpu.Simulation.from_arrays(np.array([[1, 1], [3, 1]]), [[1, 0], [0, 0]], [1, 1], box=(5, 3))
    assert whole.state().pos.tolist() == [[1.0, 1.0], [3.0, 1.0]]  # integers are numbers


def test_from_arrays_one_radius_for_every_circle(circles_cpu):
    """A single radius, as Scene takes it, is every circle's: the same simulation as with the
    array of it."""
    p, v, r = arrays()
    one, each = (circles_cpu.Simulation.from_arrays(p, v, radius, box=(1.0, 1.0)) for radius in (0.05, r))
    for sim in (one, each):
        sim.advance(1.0)
    assert np.array_equal(one.state().pos, each.state().pos)
    assert one.stats()["pair_collisions"] == each.stats()["pair_collisions"]
    refused(from_arrays(circles_cpu, radius=r[:3]), r"\(4, 2\)", r"\(3, 2\).*3 radii")


def test_from_arrays_a_wall_contact_by_round_off_is_inside(circles_cpu):
    """0.3 - 0.2 is 0.09999999999999998: a circle of radius 0.1 placed there touches the wall x = 0
    up to the rounding of the place, and is taken, as from a scene file (within the precision's
    `place_slack`). A circle across a wall by more is refused with the range its centre takes."""
    x = 0.3 - 0.2
    assert x < 0.1
    for precision in ("f64", "f32"):
        sim = circles_cpu.Simulation.from_arrays([[x, 0.5]], [[-1.0, 0.0]], [0.1], box=(1.0, 1.0),
                                                 precision=precision)
        sim.advance(1.0)
        assert sim.stats()["wall_collisions"] == 2 and sim.state().vel[0, 0] == -1.0
    refused(lambda: circles_cpu.Simulation.from_arrays([[0.099, 0.5]], [[0.0, 0.0]], [0.1], box=(1.0, 1.0)),
            r"circle 0 at \(0\.099, 0\.5\)", r"x in \[0\.1, 0\.9\]")
    from circles import scenefile

    circle = {"pos": [x, 0.5], "vel": [1.0, 0.0], "radius": 0.1}
    listed = scenefile.circle_list_from_dict({"box": [1.0, 1.0], "circle": [circle]})
    assert listed.pos[0, 0] == x


@pytest.mark.parametrize("box, precision", [((1e12, 1e-4), "f32"), ((1e-320, 3.0), "f64")])
def test_a_box_too_thin_for_the_precision_is_refused_as_such(circles_cpu, box, precision):
    """A box whose long side rounds a place by more than its short side leaves no radius that
    places: it is refused as too thin (with a fix), not with a negative largest radius."""
    message = refused(scene(circles_cpu, n=5, box=box, radius=1e-5 if precision == "f32" else 1e-322,
                            precision=precision), "too thin", precision)
    assert "at most -" not in message


def test_a_huge_box_leaves_room_for_its_circles(circles_cpu):
    """A box near the largest float: the rounding margin (4 units in the last place of its side)
    stays finite, so a scene that fits is not refused."""
    from circles.scene import check_room, rounding_margin

    assert math.isfinite(rounding_margin((1e308, 1e308), False))
    check_room(1e300, (1e308, 1e308), "walls", "f64")  # no error


def test_a_scene_too_close_to_jamming_names_the_fraction_that_places(circles_cpu):
    """2000 equal circles at area fraction 0.88 in a walled 16 x 9 box: below the densest packing,
    but no lattice of them fits, and Monte Carlo cannot grow them back from smaller radii. The
    error names the fraction and the radii (a scale of these) at which a lattice holds them,
    and those place."""
    n, box = 2000, (16.0, 9.0)
    r = math.sqrt(0.88 * box[0] * box[1] / (n * math.pi))
    message = refused(lambda: circles_cpu.Simulation(circles_cpu.Scene(n=n, box=box, radius=r, scheme="discrete")),
                      r"area fraction 0\.8800", "jamming")
    scale = float(re.search(r"every radius ([\d.]+) times", message).group(1))
    fraction = float(re.search(r"area fraction (0\.\d+)\), which places", message).group(1))
    assert 0.99 < scale < 1.0 and fraction == pytest.approx(0.88 * scale ** 2, abs=1e-4)
    placed = circles_cpu.Simulation(circles_cpu.Scene(n=n, box=box, radius=r * scale, scheme="discrete"))
    assert placed.stats()["max_overlap"] == 0


@pytest.mark.parametrize("length, simulated", [(1e-300, 1e-140), (1e300, 1e150)])
def test_boxes_of_any_finite_size_have_an_area_fraction(circles_cpu, length, simulated):
    """The area fraction is pi sum (r / W)(r / H): in a box of 1e-300 the squares of lengths
    underflowed to 0 (0 / 0 raised ZeroDivisionError), in one of 1e300 they overflowed. One
    circle of a quarter of the box's side fills pi / 16 of it, in a Scene's check as in
    from_arrays' (at lengths the simulation takes, `scene.check_scale`)."""
    from circles.scene import area_fraction

    assert area_fraction([0.25 * length], (length, length)) == pytest.approx(math.pi / 16, rel=1e-15)
    length = simulated
    assert circles_cpu.Scene(n=3, box=(length, length), radius=0.25 * length).area_fraction == pytest.approx(
        3 * math.pi / 16, rel=1e-15)
    sim = circles_cpu.Simulation.from_arrays([[0.5 * length, 0.5 * length]], [[0.0, 0.0]], [0.25 * length],
                                             box=(length, length))
    assert sim.state().radius[0] == 0.25 * length
    refused(lambda: circles_cpu.Scene(n=20, box=(length, length), radius=0.25 * length), "densest packing")


# F: overlaps across the seam of a periodic box.
def test_overlap_across_the_periodic_seam_is_measured_and_refused(circles_cpu):
    with pytest.raises(ValueError, match="overlap"):
        circles_cpu.Simulation.from_arrays([[0.03, 0.5], [0.97, 0.5]], [[0.0, 0.0], [0.0, 0.0]], [0.05, 0.05],
                                           box=(1.0, 1.0), boundary="periodic", scheme="discrete", dt=1e-3)
    sim = circles_cpu.Simulation.from_arrays([[0.04, 0.5], [0.96, 0.5]], [[-1.0, 0.0], [1.0, 0.0]], [0.04, 0.04],
                                             box=(1.0, 1.0), boundary="periodic", scheme="discrete", dt=1e-3)
    sim.step(1)  # each moves 1e-3 towards the other across the seam: overlap 2e-3 / 0.08
    assert sim.stats()["max_overlap"] == pytest.approx(0.025, rel=1e-9)


# H: grid cells at least `reach` wide, whatever the fractional part of box / reach.
@pytest.mark.parametrize("ratio", [3.7, 5.5, 5.7, 10.9])
def test_grid_cells_are_at_least_reach_wide(circles_cpu, ratio):
    from circles.grid import Grid
    grid = Grid(1000, (1.0, 1.0), False)
    ncx, ncy = grid.shape_for(1.0 / ratio)
    assert 1.0 / ncx >= 1.0 / ratio and 1.0 / ncy >= 1.0 / ratio


def test_overlap_two_cells_apart_is_refused(circles_cpu):
    # Contact 0.1754 = reach in a 1 x 1 box: 5 cells a side; the circles sit in cells 0 and 1 of 5
    # (cells 0 and 2 of 6 were the box cut into cells narrower than the reach).
    r = 1.0 / 11.4
    with pytest.raises(ValueError, match="overlap"):
        circles_cpu.Simulation.from_arrays([[0.166, 0.5], [0.336, 0.5]], [[0, 0], [0, 0]], [r, r], box=(1.0, 1.0),
                                           scheme="discrete", dt=1e-3)


@pytest.mark.parametrize("precision", ["f32", "f64"])
def test_lengths_and_speeds_beyond_what_the_precision_squares_are_refused(circles_cpu, precision):
    """A box 1e25 wide in f32 overflowed every squared distance (its circles passed through each
    other, 0 collisions), and a contact distance and speed near 1e-17 in f32 underflowed (Taichi
    flushes to 0): such scenes are refused with the bound and the fix, and scenes at the bounds
    run and collide."""
    from circles.scene import MAX_LENGTH, MAX_SPEED, MIN_LENGTH

    lo, hi = MIN_LENGTH[precision], MAX_LENGTH[precision]
    refused(scene(circles_cpu, n=10, box=(4 * hi, 4 * hi), radius=hi / 20, speed=(0.0, 0.1), precision=precision),
            "box side .* is above", re.escape(f"{hi:g}"))
    refused(scene(circles_cpu, n=10, box=(100 * lo, 100 * lo), radius=lo / 2, speed=(0.0, 1e5), precision=precision),
            "radius .* is below", re.escape(f"{lo:g}"))
    fast = MAX_SPEED[precision] / 2  # allowed alone
    refused(scene(circles_cpu, n=10, box=(1e3, 1e3), radius=0.1, speed=(0.0, fast), precision=precision),
            "times the largest speed .* is .*, above", re.escape(f"{hi:g}"))
    refused(scene(circles_cpu, n=10, box=(4.0, 4.0), radius=0.1, speed=(0.0, lo), precision=precision),
            "times the largest speed .* is .*, below", re.escape(f"{lo:g}"))
    p, v, r = arrays()
    refused(from_arrays(circles_cpu, pos=p * 8 * lo, vel=v, radius=r * 8 * lo, box=(8 * lo, 8 * lo),
                        precision=precision), "is below", re.escape(f"{lo:g}"))
    refused(from_arrays(circles_cpu, mass=np.array([1.0, 1e-310, 1.0, 1.0])), "mass 1e-310 is below 2.22507e-308")
    # Times within a step stay below geometry.NEVER (1e30): a pair 1e35 apart at speed 1, with
    # the default step of 3e33, collided without end.
    refused(scene(circles_cpu, n=10, box=(1e18, 1e18), radius=1e16, speed=1e-12, precision=precision),
            "give a step dt = 3e\\+27, beyond the steps from 0 to 1e\\+27", "measure lengths and times")
    refused(scene(circles_cpu, dt=1e28, precision=precision), "dt = 1e\\+28 is above 1e\\+27", "shorter dt")
    # At the bounds: two circles meet head on, in a box of the least lengths and in one of the
    # largest (speeds such that their products with the lengths stay within the bounds).
    # Steps are at most MAX_DT (1e27), which bounds f64's lengths at speeds within the bounds
    # before MAX_LENGTH does: 1e80 wide at a speed of 1e60.
    for unit, speed in ((20 * lo, 1.0), (hi / 8, 1.0) if precision == "f32" else (1e80, 1e60)):
        pos = np.array([[0.25, 0.5], [0.75, 0.5]]) * unit
        sim = circles_cpu.Simulation.from_arrays(pos, np.array([[speed, 0.0], [-speed, 0.0]]), np.full(2, 0.1 * unit),
                                                 box=(unit, unit), precision=precision)
        sim.advance(0.2 * unit / speed)
        assert sim.stats()["pair_collisions"] == 1, unit
        assert sim.state().vel[0, 0] == pytest.approx(-speed, rel=1e-6)



@pytest.mark.parametrize("fields, message", [
    ({"aspect": 0.0, "area_fraction": 0.7}, "aspect = 0.0 must be > 0: give the box's width over its height, e.g. 1.0 "
                                            "for a square"),
    ({"aspect": -2.0, "area_fraction": 0.7}, "aspect = -2.0 must be > 0: give the box's width over its height, e.g. "
                                             "1.0 for a square"),
    ({"aspect": math.inf, "area_fraction": 0.7}, "aspect = inf is not finite: give a finite number"),
    ({"aspect": 1.0}, "aspect = 1.0 shapes the box made from area_fraction: give area_fraction with it, in place of "
                      "a box"),
    ({"aspect": 1.0, "box": (20.0, 20.0)}, "aspect = 1.0 shapes the box made from area_fraction: give area_fraction "
                                           "with it, in place of a box"),
    ({"aspect": 1.0, "area_fraction": 0.7, "crystal": (16, 14), "boundary": "periodic"},
     "aspect = 1.0 and crystal = [16, 14] are both given: the crystal fixes the box's aspect (nx : ny sqrt(3)/2); "
     "drop aspect"),
])
def test_an_aspect_is_refused_where_it_shapes_no_box(circles_cpu, fields, message):
    with pytest.raises(ValueError) as info:
        circles_cpu.Scene(n=224, radius=0.5, **fields)
    assert str(info.value) == message


def test_an_aspect_shapes_the_box_made_from_the_area_fraction(circles_cpu, tmp_path):
    """224 disks of diameter 1 at area fraction 0.7 in a square box: side sqrt(224 pi / 4 / 0.7),
    from Scene, a scene file and the command line's --area-fraction over a file's aspect; a
    scene written back holds the box alone."""
    import argparse

    from circles.sceneflags import sized_scene_fields

    side = math.sqrt(224 * math.pi / 4 / 0.7)
    scene = circles_cpu.Scene(n=224, radius=0.5, mass="equal", boundary="periodic", area_fraction=0.7, aspect=1.0)
    assert scene.box == pytest.approx((side, side), rel=1e-14) and scene.area_fraction == pytest.approx(0.7, rel=1e-14)
    written = scene.to_dict()
    assert "aspect" not in written and "area_fraction" not in written
    assert circles_cpu.Scene.from_dict(written).box == scene.box
    wide = circles_cpu.Scene(n=224, radius=0.5, area_fraction=0.7, aspect=2.0)
    assert wide.box == pytest.approx((side * math.sqrt(2), side / math.sqrt(2)), rel=1e-14)
    path = tmp_path / "square.toml"
    path.write_text("n = 224\nradius = 0.5\narea_fraction = 0.7\naspect = 1.0\n")
    assert circles_cpu.Scene.from_toml(path).box == pytest.approx((side, side), rel=1e-14)
    fields = {"n": 224, "radius": 0.5, "area_fraction": 0.6, "aspect": 1.0}
    flagged = sized_scene_fields(fields, {}, argparse.Namespace(area_fraction=0.7, scene=str(path)))
    assert circles_cpu.Scene.from_dict(flagged).box == pytest.approx((side, side), rel=1e-14)
    boxed = sized_scene_fields(fields, {"box": [32.0, 8.0]}, argparse.Namespace(area_fraction=0.7, scene=str(path)))
    assert circles_cpu.Scene.from_dict(boxed).box == pytest.approx((2 * side, side / 2), rel=1e-14)  # --box's aspect


@pytest.mark.parametrize("args, message", [
    ((True, 0.5, 0.5), "n = True must be a whole number of circles"),
    ((2.5, 0.5, 0.5), "n = 2.5 must be a whole number of circles"),
    ((0, 0.5, 0.5), "n = 0 must be > 0"),
    ((1, 0.0, 0.5), "radius = 0.0: the smallest value 0.0 is out of range (must be > 0)"),
    ((1, -0.1, 0.5), "radius = -0.1: the smallest value -0.1 is out of range (must be > 0)"),
    ((1, 0.5, 0.5, math.nan), "box aspect = nan is not finite: give a finite number"),
    ((1, 0.5, 0.5, 0.0), "box aspect 0.0 must be > 0"),
])
def test_the_box_for_an_area_fraction_refuses_what_makes_no_box(args, message):
    from circles.scene import box_for_area_fraction

    with pytest.raises(ValueError) as info:
        box_for_area_fraction(*args)
    assert str(info.value) == message


def test_the_box_for_an_area_fraction_holds_one_circle_as_asked():
    """One disk of radius 0.5 at area fraction 0.5 in a square: side sqrt(pi / 4 / 0.5)."""
    from circles.scene import box_for_area_fraction

    side = math.sqrt(math.pi / 4 / 0.5)
    assert box_for_area_fraction(1, 0.5, 0.5, 1.0) == pytest.approx((side, side), rel=1e-15)


def test_a_crystal_is_refused_without_a_box_it_fits(circles_cpu):
    """A crystal needs area_fraction or a box of its aspect, 29 : 30 sqrt(3)/2 for 29 x 30."""
    with pytest.raises(ValueError) as info:
        circles_cpu.Scene(n=870, crystal=(29, 30), radius=0.5, boundary="periodic")
    assert str(info.value) == ("crystal = [29, 30]: give area_fraction (the box is then made of the crystal's aspect) "
                               "or a box of aspect nx : ny sqrt(3)/2")
    with pytest.raises(ValueError) as info:
        circles_cpu.Scene(n=870, crystal=(29, 30), box=(40.0, 20.0), radius=0.5, boundary="periodic")
    assert str(info.value) == (f"box = [40.0, 20.0] has aspect 2, and crystal = [29, 30] fits a box of aspect "
                               f"{29 / (30 * math.sqrt(3) / 2):.9g} (nx : ny sqrt(3)/2): give area_fraction in place "
                               "of the box, or a box of that aspect")


def test_the_box_suggested_beyond_the_densest_packing_holds_the_circles_at_half_full():
    """The refusal offers a box of the given one's shape, each side rounded up to 3 significant
    digits, that holds the circles at area fraction 0.5: at most 0.5 and within the rounding."""
    from circles.scene import Scene

    for n, box in ((121, (1.0, 1.0)), (4157, (16.0, 9.0)), (2000, (0.0123, 0.0456))):
        r = 0.05 if box == (1.0, 1.0) else 0.1 if box == (16.0, 9.0) else 0.0006
        with pytest.raises(ValueError) as info:
            Scene(n=n, box=box, radius=r)
        found = re.search(r": (\S+) x (\S+) holds them at area fraction 0\.5 \(box = \[(\S+), (\S+)\], or "
                          r"area_fraction = 0\.5 in place of the box\)$", str(info.value))
        w, h = float(found[1]), float(found[2])
        assert (float(found[3]), float(found[4])) == (w, h)
        filled = n * math.pi * r * r / (w * h)
        assert 0.5 * (1 - 0.02) <= filled <= 0.5  # each side up by less than a unit in its third digit
        assert w / h == pytest.approx(box[0] / box[1], rel=0.01)
        assert len(f"{w:g}".replace(".", "").strip("0")) <= 3 and len(f"{h:g}".replace(".", "").strip("0")) <= 3


@pytest.mark.parametrize("x, rounded", [
    (0.12345, 0.124), (1234.5, 1240.0), (999.9, 1000.0), (3.4567e-7, 3.46e-7),
    (1.5, 1.5), (150.0, 150.0),  # already 3 digits: kept, not raised by a unit for their round-off
    (0.0, 0.0), (-1.0, -1.0),  # no side to round: as given
])
def test_a_side_is_rounded_up_to_three_significant_digits(x, rounded):
    from circles.scene import _round_up

    assert _round_up(x) == pytest.approx(rounded, rel=1e-12)
    assert x <= 0 or _round_up(x) >= x * (1 - 1e-12)  # up, never down


@pytest.mark.parametrize("fields, message", [
    ({"radius": math.inf}, "radius = inf is not finite: give a finite number"),
    ({"radius": (1, 2, 3)}, "radius = (1, 2, 3) must be a number or a pair (min, max)"),
    ({"radius": ("ab", 0.1)}, "radius = 'ab' is not a number"),
    ({"radius": (0.1, "b")}, "radius = 'b' is not a number"),
    ({"radius": (0.1, 0.05)}, "radius = (0.1, 0.05): max 0.05 is below min 0.1"),
    ({"radius": -0.1}, "radius = -0.1: the smallest value -0.1 is out of range (must be > 0)"),
    ({"radius": 0.0}, "radius = 0.0: the smallest value 0.0 is out of range (must be > 0)"),
    ({"n": True}, "n = True must be a whole number of circles"),
    ({"start": "melted"}, "start 'melted' is unknown: use one of 'fluid', 'crystal', 'compressed'"),
    ({"seed": -1}, "seed = -1 must be a whole number >= 0"),
    ({"n": 4, "crystal": (0, 4), "radius": 0.5, "box": None, "area_fraction": 0.05, "boundary": "periodic"},
     "crystal = [0, 4]: give nx >= 1 columns and an even number ny >= 2 of rows (a periodic box stacks the rows of a "
     "triangular crystal in pairs)"),
    ({"crystal": (16, 1.5), "box": None, "area_fraction": 0.7, "boundary": "periodic"},
     "crystal[1] = 1.5 must be a whole number >= 0"),
    ({"n": 224, "crystal": (16, 14), "radius": (0.4, 0.5), "box": None, "area_fraction": 0.7, "boundary": "periodic"},
     "crystal = [16, 14] with radii from 0.4 to 0.5: a crystal is of equal circles; give one radius"),
    ({"n": 224, "crystal": (16, 14), "radius": 0.5, "box": None, "area_fraction": 0.7},
     "crystal = [16, 14] in a box with walls: the crystal fills a periodic box; give boundary = 'periodic'"),
    ({"n": 100, "box": (1.0, 1.0), "radius": 0.1},
     "area fraction 3.1416 of 100 circles in a 1.0 x 1.0 box exceeds the densest packing 0.9069: use fewer or smaller "
     "circles or a bigger box: 2.51 x 2.51 holds them at area fraction 0.5 (box = [2.51, 2.51], or area_fraction = 0.5 "
     "in place of the box)"),
    ({"start": "compressed", "precision": "f32"}, "start = 'compressed' needs precision = 'f64': a compression leaves "
                                                  "pairs at contact, which positions rounded to float32 would overlap; "
                                                  "give precision = 'f64'"),
    ({"start": "compressed", "speed": 0.0}, "start = 'compressed' needs moving circles, not speed = 0.0: the disks "
                                            "grow while they collide; give a speed above 0"),
    ({"start": "crystal"}, "start = 'crystal' needs the crystal's shape: give crystal = [nx, ny], its columns and rows "
                           "(n = nx ny, ny even)"),
    ({"mass": "heavy"}, "mass model 'heavy' is unknown: use one of 'radius', 'area', 'equal' (masses of your own go "
                        "to Simulation.from_arrays)"),
    ({"boundary": "torus"}, "boundary 'torus' is unknown: use one of 'walls', 'periodic'"),
    ({"scheme": "x"}, "scheme 'x' is unknown: use one of 'event', 'discrete'"),
    ({"precision": "f16"}, "precision 'f16' is unknown: use one of 'f32', 'f64'"),
    ({"species": [{"count": 2, "radius": 1.0}], "radius": 0.3, "box": (20.0, 20.0), "n": 2},
     "radius = 0.3 and species are both given: the species give the radii; drop radius"),
    ({"n": 2.5}, "n = 2.5 must be a whole number of circles"),
    ({"speed": (-1.0, 1.0)}, "speed = (-1.0, 1.0): the smallest value -1.0 is out of range (must be >= 0)"),
    ({"speed": ("x", 1.0)}, "speed = 'x' is not a number"),
])
def test_a_scene_field_is_refused_word_for_word(fields, message):
    from circles.scene import Scene

    assert refused(lambda: Scene(**{"n": 10, "box": (4.0, 4.0), **fields})) == message


def test_a_scene_dict_s_lists_are_shown_as_the_scene_holds_them():
    """A scene file's lists ([a, b]) become the tuples a Scene holds before they are checked, so
    a refusal shows the value as Scene(...) given it would."""
    from circles.scene import Scene

    for fields, message in (({"radius": [0.1, 0.05]}, "radius = (0.1, 0.05): max 0.05 is below min 0.1"),
                            ({"speed": [-1.0, 1.0]}, "speed = (-1.0, 1.0): the smallest value -1.0 is out of range "
                                                     "(must be >= 0)"),
                            ({"box": [-4.0, 4.0]}, "box = (-4.0, 4.0): both sides must be > 0"),
                            ({"crystal": [2, 3, 4], "boundary": "periodic"},
                             "crystal = (2, 3, 4) must be [nx, ny]: the columns and rows of the triangular crystal")):
        assert refused(lambda: Scene.from_dict({"n": 10, "box": [4.0, 4.0], **fields})) == message


def test_numpy_scalars_are_taken_as_numbers():
    import numpy as np

    from circles.scene import Scene

    scene = Scene(n=np.array(40), radius=np.array(0.05), box=(np.float64(4.0), 4.0), seed=np.int64(3))
    assert scene == Scene(n=40, radius=0.05, box=(4.0, 4.0), seed=3) and type(scene.n) is int
    scene = Scene(n=np.int64(40), radius=0.05, box=(4.0, 4.0), dt=np.array(0.01), seed=np.int64(5))
    assert (type(scene.n), type(scene.dt), scene.dt, type(scene.seed)) == (int, float, 0.01, int)


def test_the_rounding_margin_is_four_units_in_the_last_place_of_the_longer_side():
    """4 eps of the longer side, eps = 2^-24 in float32 and 2^-53 in float64: a bound, with
    room, on how far rounding a position to the precision and wrapping it move it."""
    from circles.scene import rounding_margin

    assert rounding_margin((3.0, 5.0), True) == 5.0 * 4 * 2.0 ** -24
    assert rounding_margin((3.0, 5.0), False) == 5.0 * 4 * 2.0 ** -53
    assert rounding_margin((1e300, 2.0), False) == 1e300 * 4 * 2.0 ** -53  # finite for any finite box


@pytest.mark.parametrize("precision, eps", [("f32", 2.0 ** -24), ("f64", 2.0 ** -53)])
def test_room_to_place_ends_exactly_at_the_side(precision, eps):
    """A walled box's side must hold the diameter, twice the placement's clearance of it and
    twice the rounding margin (4 eps of the longer side): a radius that makes the sum the side
    exactly fits, and one that does not is told the largest that does, worked out here. A box
    whose rounding margins alone fill the side is too thin; one a little wider is not."""
    from circles.scene import PLACE_CLEARANCE, check_room

    rounding = 4 * eps * 1.0
    limit = (1.0 - 2 * rounding) / (2 * (1 + 2 * PLACE_CLEARANCE))
    near, down, up = [limit], limit, limit  # the floats around it
    for _ in range(40):
        down, up = math.nextafter(down, 0.0), math.nextafter(up, 1.0)
        near += [down, up]
    exact = [y for y in near if 2 * y * (1 + 2 * PLACE_CLEARANCE) + 2 * rounding == 1.0]
    assert exact
    check_room(max(exact), (1.0, 1.0), "walls", precision)  # no error: it fits exactly
    most = float(f"{limit * (1 - 1e-8):.9g}")
    assert refused(lambda: check_room(0.5, (1.0, 1.0), "walls", precision)) == (
        f"radius 0.5 leaves no room to place the circle at random in the box 1.0 x 1.0 (its diameter, with a "
        f"clearance of 2e-06 of it for rounding, must fit the side 1.0): use a radius of at most {most:.9g}, a bigger "
        "box, or give the places yourself with Simulation.from_arrays")
    wide = 2.0 ** 20
    margin = 4 * eps * wide
    fix = "use a box whose sides differ less" + (", or precision 'f64'" if precision == "f32" else "")
    thin = refused(lambda: check_room(margin, (wide, 2 * margin), "walls", precision))
    assert "is too thin to place circles at random" in thin and thin.endswith(fix)
    assert "leaves no room to place the circle" in refused(lambda: check_room(margin, (wide, 2.5 * margin), "walls",
                                                                              precision))


def test_an_area_fraction_runs_from_above_zero_to_the_densest_packing_itself():
    """pi / sqrt(12), the hexagonal packing, is the largest area fraction a box can be made for;
    anything above it, zero or less, or no number, is refused in one line naming it."""
    from circles.scene import check_area_fraction_value

    densest = math.pi / math.sqrt(12.0)
    assert check_area_fraction_value(densest) == densest and check_area_fraction_value(1e-300) == 1e-300
    tail = " is out of range: give a fraction > 0 and at most the densest packing 0.9069 (below about 0.7 for a fluid)"
    for value, message in ((math.nextafter(densest, 1.0), f"area_fraction = {math.nextafter(densest, 1.0)!r}{tail}"),
                           (0.0, f"area_fraction = 0.0{tail}"), ("x", "area_fraction = 'x' is not a number"),
                           (math.nan, "area_fraction = nan is not finite: give a finite number")):
        assert refused(lambda: check_area_fraction_value(value)) == message


def test_a_crystal_scene_goes_to_a_dict_and_back():
    from circles.scene import Scene

    scene = Scene(n=224, crystal=(16, 14), radius=0.5, area_fraction=0.7, boundary="periodic", mass="equal",
                  start="crystal")
    d = scene.to_dict()
    assert d["crystal"] == [16, 14] and "area_fraction" not in d and "species" not in d
    assert Scene.from_dict(d) == scene
    listed = Scene(n=224, crystal=[16, 14], radius=0.5, area_fraction=0.7, boundary="periodic", mass="equal",
                   start="crystal")
    assert listed == scene and listed.crystal == (16, 14)  # held as a tuple, however given
    smallest = Scene(n=2, crystal=(1, 2), radius=0.5, area_fraction=0.05, boundary="periodic", start="crystal")
    assert smallest.crystal == (1, 2)  # one column of two rows: the least a periodic box stacks
    # n given beside the crystal is checked, not replaced
    assert refused(lambda: Scene.from_dict({**d, "n": 100})) == (
        "n = 100 but crystal = [16, 14] holds 224 circles: give n = 224 (a scene file or sweep file may leave n out)")


def test_a_side_that_is_no_finite_number_is_left_as_it_is():
    from circles.scene import _round_up

    assert _round_up(math.inf) == math.inf and math.isnan(_round_up(math.nan))


def test_a_scene_file_that_cannot_be_read_is_named_with_the_reason(tmp_path):
    from circles.scene import Scene

    missing = tmp_path / "missing.toml"
    refused(lambda: Scene.from_toml(missing), f"^{re.escape(f'scene file {missing} not found')}$")
    refused(lambda: Scene.from_toml(tmp_path), f"^{re.escape(f'scene file {tmp_path} is a folder: give a .toml file')}$")
    latin = tmp_path / "latin.toml"
    latin.write_bytes(b'n = 10\n# caf\xe9\n')
    refused(lambda: Scene.from_toml(latin), "^" + re.escape(f"{latin}: not UTF-8 text (byte 0xe9 at offset 12): save "
                                                            "the scene file as UTF-8") + "$")
    bad = tmp_path / "bad.toml"
    bad.write_text("n = \n")
    refused(lambda: Scene.from_toml(bad), "^" + re.escape(f"{bad}: not valid TOML (") + r".+\)$")
    under_a_file = tmp_path / "latin.toml" / "scene.toml"  # a path through a file: an OSError of its own
    refused(lambda: Scene.from_toml(under_a_file),
            f"^cannot read scene file {re.escape(str(under_a_file))}: Not a directory$")
    if os.geteuid() != 0:  # root reads any file
        locked = tmp_path / "locked.toml"
        locked.write_text("n = 10\n")
        locked.chmod(0)
        refused(lambda: Scene.from_toml(locked), f"^cannot read scene file {re.escape(str(locked))}: Permission denied$")


def test_a_scene_file_s_run_table_is_for_the_command_line_alone(tmp_path):
    from circles.scene import Scene, read_scene_toml

    path = tmp_path / "scene.toml"
    path.write_text('n = 12\nradius = 0.1\n\n[run]\nduration = 3.0\n')
    assert read_scene_toml(path) == {"n": 12, "radius": 0.1}
    assert Scene.from_toml(path) == Scene(n=12, radius=0.1)


def test_scene_from_dict_refuses_in_words_what_a_scene_cannot_hold():
    from dataclasses import fields

    from circles.scene import Scene

    known = ", ".join(sorted(f.name for f in fields(Scene)))
    cases = [
        ({"n": 3, "circle": [{"x": 1}]}, "the scene lists its circles ([[circle]] entries), which a random Scene cannot "
                                         "hold: read it with circles.scenefile.read_circle_list and simulate it with "
                                         "circles.Simulation.from_arrays"),
        ({"n": 3, "colour": 1, "bounds": 2}, f"unknown scene key(s) bounds, colour: known keys are {known}"),
        ({"n": 3, "box": [2.0, 2.0], "area_fraction": 0.3}, "box = [2.0, 2.0] and area_fraction = 0.3 are both given: "
                                                            "give one of them (area_fraction makes a box of aspect 16:9 "
                                                            "for the circles, or of the aspect given)"),
        ({"radius": 0.1, "species": [{"count": 3, "radius": 0.1}]}, "radius and species are both given: the species "
                                                                   "give the radii; drop radius"),
    ]
    for fields_, words in cases:
        with pytest.raises(ValueError) as info:
            Scene.from_dict(fields_)
        assert str(info.value) == words


def test_scene_from_dict_takes_toml_s_lists_and_counts_n_from_species_and_crystals():
    from circles.scene import Scene

    scene = Scene.from_dict({"n": 5, "box": [3.0, 2.0], "radius": [0.1, 0.2], "speed": [0.5, 1.0]})
    assert (scene.box, scene.radius, scene.speed) == ((3.0, 2.0), (0.1, 0.2), (0.5, 1.0))
    mixed = Scene.from_dict({"species": [{"count": 3, "radius": 0.1}, {"count": 4, "radius": 0.2}], "box": [4.0, 4.0]})
    assert mixed.n == 7 and isinstance(mixed.species, tuple)
    crystal = Scene.from_dict({"crystal": [4, 6], "area_fraction": 0.5, "radius": 0.5, "boundary": "periodic"})
    assert crystal.n == 24 and crystal.crystal == (4, 6)
    assert Scene.from_dict({"n": 5, "radius": 0.1}) == Scene(n=5, radius=0.1)
