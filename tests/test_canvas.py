"""The headless rasteriser: placement, colours, coverage (anti-aliasing) and input checks.

Coverage is measured with white circles on a black background, where the red channel of
a pixel is 255 times the fraction of it that circles cover: the channel summed over the
image, over 255, is the area drawn in pixels, which must be pi r^2.
"""

import math

import numpy as np
import pytest

from conftest import TEST_ARCH

BOX = (16.0, 9.0)
WHITE = (255, 255, 255)
BLACK = (0, 0, 0)


@pytest.fixture(scope="module")
def canvas(circles_cpu):
    from circles import canvas

    return canvas


def draw(canvas, pos, radius, color=WHITE, vel=None, width=320, height=180, box=BOX,
         color_mode="random", background=BLACK, **options):
    pos = np.atleast_2d(np.asarray(pos, dtype=np.float64))
    n = len(pos)
    radius = np.broadcast_to(np.asarray(radius, dtype=np.float64), (n,))
    colors = np.broadcast_to(np.asarray(color, dtype=np.uint8), (n, 3))
    vel = np.zeros((n, 2)) if vel is None else np.asarray(vel, dtype=np.float64)
    return canvas.render(pos, vel, radius, colors, box, width, height, color_mode,
                         background, **options)


def drawn_area(image):
    """Area covered, in pixels, of white circles drawn on black."""
    return image[..., 0].astype(np.float64).sum() / 255.0


def test_circle_is_drawn_at_its_place_in_its_colour(canvas):
    # 20 pixels per world unit; world y is up, image rows go down.
    image = draw(canvas, [4.0, 6.0], 1.0, color=(200, 60, 120), background=(16, 16, 24))
    assert image.shape == (180, 320, 3) and image.dtype == np.uint8
    assert tuple(image[60, 80]) == (200, 60, 120)  # row (9 - 6) * 20, column 4 * 20
    assert tuple(image[60, 80 + 18]) == (200, 60, 120)
    assert tuple(image[60, 80 + 21]) == (16, 16, 24)
    assert tuple(image[120, 80]) == (16, 16, 24)  # the mirror place is empty
    assert tuple(image[0, 0]) == (16, 16, 24)


@pytest.mark.parametrize("radius_px", [0.5, 0.8, 1.2, 1.5, 2.0, 3.3, 7.5, 20.0])
def test_coverage_sums_to_the_circle_area(canvas, radius_px):
    # Sub-pixel placements differ; each image must hold pi r^2 pixels within 3%.
    rng = np.random.default_rng(int(radius_px * 10))
    expected = math.pi * radius_px ** 2
    for centre in rng.uniform([4.0, 3.0], [12.0, 6.0], size=(5, 2)):
        area = drawn_area(draw(canvas, centre, radius_px / 20.0))
        assert area == pytest.approx(expected, rel=0.03)


def test_sub_pixel_circle_is_a_faint_dot(canvas):
    radius_px = 0.25
    image = draw(canvas, [8.013, 4.527], radius_px / 20.0)
    lit = image[..., 0] > 0
    assert 1 <= lit.sum() <= 4  # shared among the nearest pixels, never lost
    assert image[..., 0].max() < 255  # faint: less than one pixel covered
    # Each pixel rounds to a 1/255 step, so allow 4 half-steps on top of 3%.
    assert drawn_area(image) == pytest.approx(math.pi * radius_px ** 2,
                                              rel=0.03, abs=2.0 / 255)


def test_many_sub_pixel_circles_show_their_density(canvas):
    # 20 000 circles of radius 0.3 pixels cover 10% of the image: their sum shows.
    rng = np.random.default_rng(1)
    n, radius_px = 20_000, 0.3
    image = draw(canvas, rng.uniform((0, 0), BOX, size=(n, 2)), radius_px / 20.0)
    assert drawn_area(image) == pytest.approx(n * math.pi * radius_px ** 2, rel=0.02)


def test_box_is_letterboxed_with_its_aspect_kept(canvas):
    # A square box in a 2:1 image: 100 x 100 pixels in the middle, margins either side.
    background = (40, 40, 60)
    image = draw(canvas, [0.5, 0.5], 0.1, color=(255, 0, 0), width=200, height=100,
                 box=(1.0, 1.0), background=background)
    assert tuple(image[50, 100]) == (255, 0, 0)
    assert tuple(image[50, 60]) == background
    margin = image[50, 10].astype(int)
    assert (margin < np.array(background)).all()  # the margin is darker
    assert tuple(image[50, 10]) == tuple(image[50, 190])


def test_circles_do_not_spill_into_the_margin(canvas):
    image = draw(canvas, [0.05, 0.5], 0.1, width=200, height=100, box=(1.0, 1.0))
    assert image[:, :50, 0].max() == 0  # white would show in the red channel
    assert image[:, 50:56, 0].max() > 0


def test_periodic_copies_wrap_around(canvas):
    # Centre 0.2 world units from the left edge, radius 0.5: it crosses onto the right.
    walls = draw(canvas, [0.2, 4.5], 0.5)
    torus = draw(canvas, [0.2, 4.5], 0.5, periodic=True)
    assert walls[90, 315, 0] == 0 and torus[90, 315, 0] == 255
    assert drawn_area(torus) == pytest.approx(math.pi * 10.0 ** 2, rel=0.03)


def test_speed_colour_mode_shows_slow_and_fast_apart(canvas):
    pos = [[4.0, 4.5], [12.0, 4.5]]
    vel = [[0.1, 0.0], [0.0, -2.0]]
    image = draw(canvas, pos, 0.5, color=(255, 0, 0), vel=vel, color_mode="speed",
                 background=(16, 16, 24))
    slow, fast = image[90, 80].astype(int), image[90, 240].astype(int)
    assert np.abs(slow - fast).sum() > 150
    assert fast.sum() > slow.sum()  # the colormap grows lighter with speed
    assert tuple(slow) != (255, 0, 0)  # the circles' own colours are not used
    # A fixed scale keeps a circle's colour from frame to frame.
    again = draw(canvas, pos, 0.5, vel=vel, color_mode="speed", speed_scale=2.0)
    alone = draw(canvas, pos[1], 0.5, vel=vel[1:], color_mode="speed", speed_scale=2.0)
    assert tuple(again[90, 240]) == tuple(alone[90, 240])


def test_random_colour_mode_uses_each_circles_colour(canvas):
    image = draw(canvas, [[4.0, 4.5], [12.0, 4.5]], 0.5,
                 color=[[250, 10, 10], [10, 250, 10]])
    assert tuple(image[90, 80]) == (250, 10, 10)
    assert tuple(image[90, 240]) == (10, 250, 10)


def test_touching_circles_blend_without_gap_or_overflow(canvas):
    # Two halves of a pixel covered by two circles: full coverage, colours averaged.
    image = draw(canvas, [[7.5, 4.5], [8.5, 4.5]], 0.5, color=[[200, 0, 0], [0, 0, 200]],
                 width=1600, height=900)
    row = image[450, 790:811].astype(int)
    assert (row.sum(axis=1) > 150).all()  # no dark seam where they touch


def test_image_of_any_size(canvas):
    for width, height in [(1, 1), (17, 5), (64, 200), (333, 111)]:
        image = draw(canvas, [8.0, 4.5], 2.0, width=width, height=height)
        assert image.shape == (height, width, 3)


def test_no_circles_gives_the_background(canvas):
    image = canvas.render(np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0),
                          np.zeros((0, 3), np.uint8), BOX, 32, 18, background=(1, 2, 3))
    assert (image == np.array([1, 2, 3], np.uint8)).all()


@pytest.mark.parametrize("options, words", [
    ({"width": 0}, ["width", "0", "1 to"]),
    ({"height": 100_000}, ["height", "100000"]),
    ({"width": 12.5}, ["width", "12.5"]),
    ({"color_mode": "rainbow"}, ["rainbow", "random", "speed"]),
    ({"speed_scale": "a"}, ["speed_scale", "'a'", "positive finite number"]),
    ({"speed_scale": -1.0}, ["speed_scale", "-1.0", "positive finite number"]),
])
def test_bad_arguments_are_refused_with_the_allowed_values(canvas, options, words):
    arguments = {"width": 64, "height": 36, "color_mode": "random", **options}
    with pytest.raises(ValueError) as error:
        canvas.render(np.zeros((1, 2)), np.zeros((1, 2)), np.ones(1),
                      np.zeros((1, 3), np.uint8), BOX, **arguments)
    for word in words:
        assert word in str(error.value)


@pytest.mark.parametrize("arrays, words", [
    ({"radius": [-1.0]}, ["circle 0", "radius", "-1.0", "> 0"]),
    ({"radius": [np.nan]}, ["circle 0", "radius", "nan"]),
    ({"pos": [[np.inf, 4.0]]}, ["circle 0", "pos", "inf", "finite"]),
    ({"color": [[300, 0, 0]]}, ["circle 0", "300", "0 to 255"]),
    ({"color": [[0.9, 0.0, 0.0]]}, ["circle 0", "0.9", "multiply by 255"]),
])
def test_bad_circles_are_refused_naming_the_circle(canvas, arrays, words):
    """Radii, places and colours the drawing cannot mean (a negative or NaN radius drew a dot or
    nothing, a colour of 300 wrapped to 44, a fraction turned black) are refused."""
    given = {"pos": [[8.0, 4.0]], "radius": [1.0], "color": [[255, 0, 0]], **arrays}
    with pytest.raises(ValueError) as error:
        canvas.render(np.array(given["pos"]), np.zeros((1, 2)), np.array(given["radius"]),
                      np.array(given["color"]), BOX, 64, 36)
    for word in words:
        assert word in str(error.value)


def test_a_circle_far_larger_than_the_image_covers_the_box(canvas):
    """A radius of 1e9 box widths: its pixel range is clamped before it becomes an integer (it
    overflowed one and drew nothing)."""
    image = draw(canvas, [[8.0, 4.5]], 1.6e10, color=(255, 0, 0), width=64, height=36)
    assert (image[..., 0] == 255).all()


@pytest.mark.parametrize("unit", [2.0 ** -200, 1e-30, 1e30, 1e300])
def test_the_picture_does_not_depend_on_the_units(canvas, unit):
    """Lengths and speeds in other units (a box of 1e-30 or 1e300, speeds scaled alike) draw the
    same picture: the kernels' float32 would lose such lengths, and the squares of such speeds,
    so lengths are drawn in units near the box's side, and speeds scaled before their square.
    Powers of two scale exactly, so the pictures are equal to the last bit; other factors
    round the places by an ulp, within one level of 255."""
    rng = np.random.default_rng(3)
    pos = rng.uniform([1.0, 1.0], [15.0, 8.0], (200, 2))
    radius = rng.uniform(0.1, 0.4, 200)
    vel = rng.normal(0.0, 1.0, (200, 2))
    colors = rng.integers(0, 256, (200, 3)).astype(np.uint8)
    for mode in ("random", "speed"):
        one = canvas.render(pos, vel, radius, colors, BOX, 160, 90, mode)
        other = canvas.render(pos * unit, vel * unit, radius * unit, colors, (BOX[0] * unit, BOX[1] * unit), 160, 90,
                              mode)
        difference = np.abs(one.astype(int) - other.astype(int)).max()
        assert difference <= (0 if math.log2(unit).is_integer() else 1), mode


def test_mismatched_arrays_are_refused(canvas):
    with pytest.raises(ValueError, match="pos"):
        canvas.render(np.zeros((3, 2)), np.zeros((2, 2)), np.ones(2),
                      np.zeros((2, 3), np.uint8), BOX)


def test_gpu_layout_draws_the_same_image(canvas, monkeypatch):
    # On a GPU stage 4 gives each tile its own thread instead of a row of tiles per
    # thread: run that layout on the CPU and compare.
    rng = np.random.default_rng(2)
    n = 3000
    args = (rng.uniform((0, 0), BOX, size=(n, 2)), rng.normal(size=(n, 2)),
            rng.uniform(0.005, 0.3, n), rng.integers(0, 256, (n, 3), dtype=np.uint8), BOX,
            331, 187, "speed")
    cpu_image = canvas.render(*args, periodic=True)
    monkeypatch.setattr(canvas, "_on_cpu", lambda: False)
    monkeypatch.setattr(canvas, "_buffers", canvas._Buffers())
    gpu_layout_image = canvas.render(*args, periodic=True)
    assert canvas._buffers.tiles_per_item == 1
    assert (cpu_image == gpu_layout_image).all()


@pytest.mark.skipif(TEST_ARCH != "cpu", reason="the chunked binning stages run on a CPU only")
def test_cpu_stages_draw_the_same_image_with_any_chunks(canvas, monkeypatch):
    # On a CPU the circles are binned in chunks, with plain increments; with no chunks
    # (too many tiles for their counts) the atomic stages run instead. Circles large
    # and small, crossing tiles and the box edges: the images must be equal bit for bit.
    rng = np.random.default_rng(3)
    n = 5000
    args = (rng.uniform((-0.5, -0.5), (16.5, 9.5), size=(n, 2)), rng.normal(size=(n, 2)),
            rng.uniform(0.002, 0.5, n), rng.integers(0, 256, (n, 3), dtype=np.uint8), BOX,
            413, 229)
    image = canvas.render(*args, periodic=True)
    for chunks in (1, 7, 0):
        monkeypatch.setattr(canvas, "_cpu_chunks", lambda tiles, chunks=chunks: chunks)
        monkeypatch.setattr(canvas, "_buffers", canvas._Buffers())
        assert (canvas.render(*args, periodic=True) == image).all()
        assert canvas._buffers.chunks == chunks


@pytest.mark.parametrize("mode", ["random", "speed"])
def test_simulation_render_draws_its_state(canvas, circles_cpu, mode):
    """Simulation.render draws the circles in their storage order (cell order after the
    reorderings of a run), not in creation order: coverage sums are exact integers, so the
    image must equal, bit for bit, the one drawn from state() in creation order."""
    from circles.simulation import REORDER_EVERY

    sim = circles_cpu.Simulation(circles_cpu.Scene(n=3000, box=(16.0, 9.0), radius=(0.02, 0.06),
                                                   speed=(0.5, 1.5), scheme="discrete", seed=4))
    sim.step(REORDER_EVERY + 1)
    assert not np.array_equal(sim._ids, np.arange(sim.n))  # storage order is not creation order
    s = sim.state()
    expected = canvas.render(s.pos, s.vel, s.radius, s.color, sim.box, 480, 270, mode)
    assert np.array_equal(sim.render(480, 270, mode), expected)


def white(canvas, pos, r, periodic):
    pos = np.atleast_2d(pos).astype(float)
    n = len(pos)
    return canvas.render(pos, np.zeros((n, 2)), np.full(n, r), np.full((n, 3), 255, np.uint8), (16.0, 9.0),
                         320, 180, "random", (0, 0, 0), periodic=periodic)


# C: corner copies on a torus.
@pytest.mark.parametrize("centre", [(0.2, 0.2), (15.8, 8.8), (0.2, 8.8), (15.8, 0.2)])
def test_periodic_circle_at_a_corner_shows_in_all_four_corners(canvas, centre):
    image = white(canvas, centre, 0.5, True)  # 10 pixels
    assert image[..., 0].sum() / 255 == pytest.approx(math.pi * 100, rel=0.03)
    for row, col in ((0, 0), (0, 319), (179, 0), (179, 319)):
        assert image[row, col, 0] == 255, (row, col)


# E: the speed scale is twice the rms speed, and the colour is viridis at |v| / scale.
def test_speed_colour_is_viridis_at_speed_over_twice_the_rms(canvas):
    speeds = np.array([0.1, 2.0, 1.0, 0.5])
    vel = np.stack([speeds, np.zeros(4)], 1)
    pos = np.array([[2.0, 4.5], [6.0, 4.5], [10.0, 4.5], [14.0, 4.5]])
    rms = math.sqrt(np.mean(speeds ** 2))
    assert canvas.speed_scale_of(vel) == pytest.approx(2 * rms, rel=1e-12)
    image = canvas.render(pos, vel, np.full(4, 1.0), np.zeros((4, 3), np.uint8), (16.0, 9.0), 320, 180, "speed",
                          (0, 0, 0))
    for (x, _), v in zip(pos, speeds):
        top = len(canvas.VIRIDIS) - 1
        u = min(v / (2 * rms), 1.0) * top
        k = min(int(u), top - 1)
        want = (1 - (u - k)) * canvas.VIRIDIS[k] + (u - k) * canvas.VIRIDIS[k + 1]
        assert np.abs(image[90, int(x * 20)] - want).max() <= 1.0, v


# O: Simulation.render after a reorder that followed an earlier render.
def test_render_before_and_after_a_reorder_draws_the_state(canvas, circles_cpu):
    from circles.simulation import REORDER_EVERY
    sim = circles_cpu.Simulation(circles_cpu.Scene(n=3000, box=(16.0, 9.0), radius=(0.02, 0.06), speed=(0.5, 1.5),
                                                   scheme="discrete", seed=4))
    for _ in range(2):
        s = sim.state()
        expected = canvas.render(s.pos, s.vel, s.radius, s.color, sim.box, 480, 270, "random")
        assert np.array_equal(sim.render(480, 270, "random"), expected), sim.steps
        sim.step(REORDER_EVERY)
