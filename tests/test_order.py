"""Hexatic order (circles.order) against freud's `freud.order.Hexatic` on the same positions,
and on configurations whose order is known: a perfect crystal (|psi_6| = 1 for every circle, in
any orientation), a random gas (global order of order 1 / sqrt(N)). The crystal start of a
scene (Scene.crystal, Scene.start) and the hexatic colouring."""

import math

import numpy as np
import pytest

from circles import order
from circles.placement.lattice import crystal_positions
from circles.scene import Scene

freud = pytest.importorskip("freud")


def freud_psi6(pos, box, periodic):
    """freud's psi_6 with six nearest neighbours: a periodic box as it is, a walled one inside a
    box three times as large (so that no neighbour is found across a side)."""
    w, h = box
    scale = 1.0 if periodic else 3.0
    fbox = freud.box.Box.from_box([w * scale, h * scale], dimensions=2)
    points = np.zeros((len(pos), 3), np.float32)
    points[:, :2] = pos - [w / 2, h / 2]
    hexatic = freud.order.Hexatic(k=6)
    hexatic.compute(system=(fbox, points), neighbors={"num_neighbors": 6, "exclude_ii": True})
    return hexatic.particle_order


@pytest.mark.parametrize("periodic", [True, False])
def test_psi6_equals_freuds_on_a_dense_fluid(circles_cpu, periodic):
    scene = Scene(n=900, box=(33.0, 30.0), radius=0.5, speed=1.0, mass="equal",
                  boundary="periodic" if periodic else "walls", seed=5)
    sim = circles_cpu.Simulation(scene)
    sim.advance(3.0)
    pos = sim.state().pos
    ours = order.psi6(pos, sim.box, periodic)
    theirs = freud_psi6(pos, sim.box, periodic)
    # freud takes float32 positions and forms the bond vectors in float32: each coordinate
    # rounded by up to half a unit in the last place of the largest (the box's half side), twice
    # for a difference, turns a bond of length d by up to 2 ulp / d, and psi_6 by six times that.
    ulp = float(np.spacing(np.float32(max(sim.box) / 2 * (1 if periodic else 3))))
    tolerance = 6 * 2 * ulp / 1.0  # bonds of at least a diameter (the disks touch at most)
    assert tolerance < 1e-4
    np.testing.assert_allclose(ours, theirs, rtol=0, atol=tolerance)


@pytest.mark.parametrize("turn", [0.0, 0.3])
def test_a_perfect_crystal_has_psi6_of_modulus_one_and_one_orientation(turn):
    pos = crystal_positions(29, 30, (29.0, 30 * math.sqrt(3) / 2))
    c, s = math.cos(turn), math.sin(turn)
    centre = pos.mean(axis=0)
    turned = (pos - centre) @ np.array([[c, s], [-s, c]]) + centre + 100.0  # walls far away: no periodic image
    box = (300.0, 300.0)
    local = order.psi6(turned if turn else pos, box if turn else (29.0, 30 * math.sqrt(3) / 2), not turn)
    if turn:  # the edge circles of an open crystal have other neighbours
        inner = np.linalg.norm(turned - turned.mean(axis=0), axis=1) < 8.0
        local = local[inner]
    np.testing.assert_allclose(np.abs(local), 1.0, atol=1e-12)
    off = (order.orientation(local) - turn) % (math.pi / 3)  # angles of a hexagon: modulo 60 degrees
    np.testing.assert_allclose(np.minimum(off, math.pi / 3 - off), 0.0, atol=1e-12)
    assert order.hexatic_order(local) == pytest.approx(1.0, abs=1e-12)


def test_a_random_gas_has_little_global_order():
    rng = np.random.default_rng(2)
    pos = rng.uniform(0, 100.0, (4000, 2))
    local = order.psi6(pos, (100.0, 100.0), True)
    # The mean of 4000 unit-bounded numbers of random phase: |mean| ~ rms / sqrt(N), about 0.01.
    assert order.hexatic_order(local) < 5 * np.sqrt(np.mean(np.abs(local) ** 2) / len(local))


def test_psi6_needs_seven_circles():
    with pytest.raises(ValueError, match="more than 6 circles"):
        order.psi6(np.zeros((6, 2)), (1.0, 1.0), True)


def test_a_crystal_scene_fits_its_box_and_starts_on_the_crystal(circles_cpu):
    scene = Scene(n=870, crystal=(29, 30), area_fraction=0.70, radius=0.5, speed=1.0, mass="equal",
                  boundary="periodic", start="crystal", seed=1)
    w, h = scene.box
    assert w / h == pytest.approx(29 / (30 * math.sqrt(3) / 2), rel=1e-12)
    assert 870 * math.pi * 0.25 / (w * h) == pytest.approx(0.70, rel=1e-12)
    sim = circles_cpu.Simulation(scene)
    pos = sim.state().pos
    spacing = w / 29
    d = pos[:, None, :] - pos[None, :, :]
    d -= np.array([w, h]) * np.round(d / np.array([w, h]))
    dist = np.sqrt((d ** 2).sum(-1)) + np.eye(870) * 1e9
    np.testing.assert_allclose(dist.min(axis=1), spacing, rtol=1e-12)  # every circle, six at one spacing
    assert np.all(np.sum(dist < spacing * (1 + 1e-9), axis=1) == 6)
    assert order.hexatic_order(order.psi6(pos, sim.box, True)) == pytest.approx(1.0, abs=1e-12)
    fluid = Scene.from_dict({**scene.to_dict(), "start": "fluid"})
    assert fluid.box == scene.box and fluid.n == 870


def test_a_compressed_start_is_a_fluid_where_the_placed_one_keeps_the_lattice(circles_cpu):
    """870 disks at 0.714, above freezing: placed at random (start "fluid") they keep the rows
    of the lattice placement begins from, |psi_6| 0.76; compressed from 0.357 at rate 0.01 they
    are a fluid, |psi_6| 0.08 to 0.22 (seeds 1 to 6), where the equilibrium fluid near 0.70 has
    0.2 to 0.4.
    The compression keeps the radii (to round-off), the box, the temperature it started with
    and zero momentum, and leaves no overlap (brute force)."""
    fields = dict(n=870, crystal=(29, 30), area_fraction=0.714, radius=0.5, speed=1.0, mass="equal",
                  boundary="periodic", seed=1)
    placed = circles_cpu.Simulation(Scene(**fields))
    scene = Scene(**fields, start="compressed")
    sim = circles_cpu.Simulation(scene)
    state = sim.state()
    assert sim.box == placed.box
    np.testing.assert_allclose(state.radius, 0.5, rtol=1e-14)
    assert order.hexatic_order(order.psi6(placed.state().pos, placed.box, True)) > 0.6
    assert order.hexatic_order(order.psi6(state.pos, sim.box, True)) < 0.35
    w, h = sim.box
    d = state.pos[:, None, :] - state.pos[None, :, :]
    d -= np.array([w, h]) * np.round(d / np.array([w, h]))
    dist = np.sqrt((d ** 2).sum(-1)) + np.eye(870) * 1e9
    assert dist.min() >= 2 * state.radius.max()
    np.testing.assert_allclose(state.vel.sum(axis=0), 0.0, atol=1e-12)
    drawn = placed.state().vel  # the same seed draws the same speeds: 1 each
    kt_drawn = (0.5 * np.sum(drawn ** 2) - 0.5 * np.sum(drawn.sum(axis=0) ** 2) / 870) / 869
    assert 0.5 * np.sum(state.vel ** 2) / 869 == pytest.approx(kt_drawn, rel=1e-12)


def test_the_command_line_starts_compressed(circles_cpu, tmp_path):
    """`--start compressed` reaches the scene: the trajectory's first frame is the compressed
    fluid (|psi_6| below 0.35, as above) at the scene's radii and box."""
    from circles import cli
    from circles.trajectory import read_simulation

    out = tmp_path / "run.gsd"
    assert cli.main(["run", "--crystal", "29", "30", "--area-fraction", "0.714", "--radius", "0.5", "--mass", "equal",
                     "--boundary", "periodic", "--start", "compressed", "--seed", "1", "--duration", "0.1", "--fps",
                     "10", "--size", "64x64", "--out", str(tmp_path / "run.gif"), "--trajectory", str(out)]) == 0
    first = read_simulation(out, 0)
    state = first.state()
    np.testing.assert_allclose(state.radius, 0.5, rtol=1e-14)
    assert order.hexatic_order(order.psi6(state.pos, first.box, True)) < 0.35


@pytest.mark.parametrize("fields, words", [
    (dict(start="compressed", precision="f32"), ["precision = 'f64'"]),
    (dict(start="compressed", speed=0.0), ["speed", "above 0"]),
])
def test_a_compressed_start_is_refused_where_it_cannot_be_made(fields, words):
    with pytest.raises(ValueError) as error:
        Scene(**{**dict(n=100, radius=0.5, boundary="periodic", area_fraction=0.5), **fields})
    for word in words:
        assert word in str(error.value)


@pytest.mark.parametrize("fields, words", [
    (dict(crystal=(29, 30), n=800), ["n = 800", "870"]),
    (dict(crystal=(29, 31), n=899), ["even"]),
    (dict(crystal=(29, 30), n=870, boundary="walls"), ["periodic"]),
    (dict(crystal=(29, 30), n=870, radius=(0.4, 0.5)), ["one radius"]),
    (dict(crystal=(29, 30), n=870, box=(30.0, 30.0)), ["aspect"]),
    (dict(start="crystal"), ["crystal = [nx, ny]"]),
    (dict(start="glass"), ["start", "glass"]),
])
def test_bad_crystals_are_refused(fields, words):
    base = dict(radius=0.5, boundary="periodic", area_fraction=0.7)
    if "box" in fields:
        base.pop("area_fraction")
    with pytest.raises(ValueError) as error:
        Scene(**{**base, **fields})
    for word in words:
        assert word in str(error.value)


def test_a_scene_file_may_leave_n_to_the_crystal():
    scene = Scene.from_dict(dict(crystal=[29, 30], area_fraction=0.7, radius=0.5, boundary="periodic"))
    assert scene.n == 870 and scene.crystal == (29, 30) and scene.start == "fluid"


def test_hexatic_colours_give_one_domain_one_colour_and_disorder_darkness():
    pos = crystal_positions(29, 30, (29.0, 30 * math.sqrt(3) / 2))
    local = order.psi6(pos, (29.0, 30 * math.sqrt(3) / 2), True)
    colours = order.hexatic_colors(local)
    assert colours.shape == (870, 3) and len({tuple(c) for c in colours}) == 1
    assert colours.max() == 255  # full brightness where |psi_6| = 1
    dark = order.hexatic_colors(np.array([0.0 + 0.0j]))
    assert dark.max() == round(255 * 0.25)


def test_the_command_line_runs_a_crystal_start_in_hexatic_colours(tmp_path):
    from process_util import run_cli

    done = run_cli(["run", "--crystal", "29", "30", "--area-fraction", "0.7", "--radius", "0.5", "--mass", "equal",
                    "--boundary", "periodic", "--start", "crystal", "--duration", "0.2", "--fps", "10",
                    "--size", "96x86", "--color", "hexatic", "--out", "hex.gif", "--arch", "cpu"], tmp_path)
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("circles     870 (event")
    import imageio.v3 as iio
    first = iio.imread(tmp_path / "hex.gif", index=0)
    inside = first[30:60, 30:60].reshape(-1, 3)
    # One orientation everywhere: the pixels inside circles share one hue (red at orientation 0).
    lit = inside[inside.max(axis=1) > 200]
    assert len(lit) > 100 and np.all(lit[:, 0] >= lit[:, 1]) and np.all(lit[:, 0] >= lit[:, 2])


def test_order_in_the_stats_table_and_the_trajectory_equals_freuds(tmp_path):
    """`circles run --order`: a hexatic_order column, and each circle's psi_6 in the GSD log,
    equal (within freud's float32) to freud's on the frame's positions; the column equals the
    mean of the frame's psi_6 at the same instant."""
    import gsd.hoomd

    from circles.writers import read_stats
    from process_util import run_cli

    done = run_cli(["run", "--crystal", "20", "20", "--area-fraction", "0.68", "--radius", "0.5", "--mass", "equal",
                    "--boundary", "periodic", "--duration", "2", "--fps", "2", "--out", "none", "--order",
                    "--stats", "run.csv", "--trajectory", "run.gsd", "--arch", "cpu"], tmp_path)
    assert done.returncode == 0, done.stderr
    table = read_stats(tmp_path / "run.csv")
    assert "hexatic_order" in table and np.all((table["hexatic_order"] >= 0) & (table["hexatic_order"] <= 1))
    with gsd.hoomd.open(str(tmp_path / "run.gsd")) as traj:
        frames = list(traj)
    w, h = frames[0].configuration.box[:2]
    for k, frame in enumerate(frames):
        local = frame.log["particles/circles/psi6"]
        pos = frame.log["particles/circles/position"]
        theirs = freud_psi6(pos, (w, h), True)
        ulp = float(np.spacing(np.float32(max(w, h) / 2)))
        np.testing.assert_allclose(local[:, 0] + 1j * local[:, 1], theirs, rtol=0, atol=12 * ulp)
        assert frame.log["circles/hexatic_order"][0] == pytest.approx(abs(np.mean(local[:, 0] + 1j * local[:, 1])),
                                                                      rel=1e-12)
        if k > 0:  # the row of the interval ending at frame k
            assert table["hexatic_order"][k - 1] == pytest.approx(frame.log["circles/hexatic_order"][0], rel=1e-12)


def test_order_needs_somewhere_to_go(capsys):
    from circles import cli

    assert cli.main(["run", "--n", "20", "--order", "--out", "none"]) == 2
    assert "--order" in capsys.readouterr().err


def test_the_crystal_is_where_its_docstring_puts_it():
    """Circle (i, j) at x = (i + 1/4 + (j mod 2)/2) W/nx, y = (j + 1/2) H/ny, row by row."""
    from circles.placement.lattice import crystal_positions

    pos = crystal_positions(2, 2, (4.0, 2.0))
    assert pos.tolist() == [[0.5, 0.5], [2.5, 0.5], [1.5, 1.5], [3.5, 1.5]]


def test_hexatic_colours_are_the_hsv_colours_of_the_orientation_and_the_order():
    """Hue arg(psi_6) / 2 pi, value 0.25 + 0.75 |psi_6| (at most 1), full saturation: the
    standard library's HSV to RGB, rounded to bytes."""
    import colorsys

    local = np.array([0.9 * np.exp(1j * a) for a in np.linspace(-np.pi, np.pi, 37)] + [1.5 + 0j, 0.2j, -0.3 + 0j])
    expected = []
    for z in local:
        hue = (np.angle(z) / (2 * np.pi)) % 1.0
        rgb = colorsys.hsv_to_rgb(hue, 1.0, 0.25 + 0.75 * min(abs(z), 1.0))
        expected.append([round(255 * c) for c in rgb])
    got = order.hexatic_colors(local).astype(int)
    assert np.max(np.abs(got - np.array(expected))) <= 1  # rounding of the last byte only
    assert np.mean(got == np.array(expected)) > 0.95


def test_the_orientation_is_the_hexagons_angle_in_its_sixty_degrees():
    for angle in (0.0, 0.3, 0.9, 1.0):
        assert order.orientation(np.array([np.exp(6j * angle)]))[0] == pytest.approx(angle % (np.pi / 3), abs=1e-12)
    assert order.orientation(np.array([np.exp(6j * -0.2)]))[0] == pytest.approx(np.pi / 3 - 0.2, abs=1e-12)


def test_a_centre_just_below_zero_is_wrapped_onto_the_box_not_onto_its_far_side():
    """np.mod(-1e-300, W) rounds to W itself, outside [0, W): psi_6 puts such a centre at 0, so
    the crystal's values are those of the same crystal with the centre at 0."""
    from circles.placement.lattice import crystal_positions

    box = (6.0, 6 * np.sqrt(3) / 2)
    pos = crystal_positions(6, 6, box)
    pos -= pos[0]  # circle 0 at the corner, (0, 0)
    nudged = pos.copy()
    nudged[0] = [-1e-300, -1e-300]
    assert np.array_equal(order.psi6(nudged, box, True), order.psi6(pos, box, True))
    assert np.allclose(np.abs(order.psi6(pos, box, True)), 1.0)
