"""Headless rasteriser: circles in a box to an RGB image, anti-aliased by coverage.

Contract: ``render(pos, vel, radius, color, box, width, height, color_mode)`` returns a
``uint8`` array of shape ``(height, width, 3)``. World coordinates have their origin at the
bottom-left of the box and y up; image row 0 is the top. The box is fitted into the image
with its aspect ratio kept and centred (letterbox); the margin is a darker shade of the
background.

Anti-aliasing is by coverage: a circle adds its colour to a pixel in proportion to the
fraction of the pixel it covers, so the coverage summed over the image equals the circle's
area in pixels, pi r^2, at every size:

- ``r >= 1.5`` pixels: coverage ``clamp(r' - d + 1/2, 0, 1)`` at the distance ``d`` from
  the pixel centre to the circle centre, the exact coverage of a pixel by a straight edge
  crossing it parallel to a side. Its integral over the plane is ``pi r'^2 + pi/12``, so
  the profile uses ``r' = sqrt(r^2 - 1/12)`` to make the total ``pi r^2``; sampled at pixel
  centres the sum stays within 1% of it at r = 1.5 and closer for larger circles.
- smaller circles are drawn as the square of the same area, box-filtered exactly (the area
  of the square inside each pixel). The coverages then sum to ``pi r^2`` exactly wherever
  the circle sits, so a moving dot does not twinkle; at this size the shape hardly shows,
  its brightness and position do. A square under one pixel wide is widened to one pixel
  at lower density, which shares a point's weight bilinearly among the four nearest
  pixels: a sub-pixel circle is a faint dot of its own area's weight, never dropped, and
  a million of them show their density; one alone shows where its weight times its contrast
  with the background reaches half a level of 255 (white on black: a radius of about 0.05
  pixel, spread over four pixels).

Blending is order independent: every pixel accumulates ``sum(coverage)`` and
``sum(coverage * colour)`` in 32-bit fixed point (integer sums are exact, so the image is
bit-identical whatever the thread count), then is composited over the background: where
the coverage sums to one or less the background shows through the rest; where circles
overlap (sum above one) their colours are averaged by coverage.

The image is drawn in 16 x 16 pixel tiles, in four stages (kernels):

1. count the entries (circle copies) of each tile;
2. prefix sum of the counts: the start of each tile's entries;
3. write each circle's image centre, radius and colour into the entries of every tile it
   touches (usually one);
4. ``_draw_tiles``: draw a tile's entries into a scratch tile that stays in cache, then
   composite the tile's pixels into the image; no pixel has two writers, so there are no
   atomics on pixels and the image is written once.

Stages 1 to 3 differ by device. On a GPU (``_count_tile_entries``, ``_tile_offsets``,
``_bin_circles``) a thread takes a circle and counts and places with atomics. On a CPU
(``_count_chunk_entries``, ``_chunk_offsets``, ``_bin_chunk_circles``) the circles are cut
into a few chunks per thread, each with its own row of counts and cursors, so that plain
increments do: an atomic costs more there than the rest of a circle's work. On a CPU the
few large pieces of work (chunks, rows of tiles) go to one worker per thread (see
``_CPU_BLOCK``).

All kernels take Taichi ndarrays, so they compile once per dtype and colour mode, not per
array size; the working arrays are ``ti.ndarray`` kept between calls of the same image
size. The GPU stages also run on a CPU, where the tests compare their image with the CPU
stages'. Nothing here calls ``ti.init``: the caller does (``circles.init()``).
"""

import math
from numbers import Real

import numpy as np
import taichi as ti
from taichi.lang import impl

from .backend import on_restart

COLOR_MODES = ("random", "speed", "hexatic")
MAX_IMAGE_SIDE = 16384
# Colour of the letterbox margin outside the box, as a fraction of the background.
MARGIN_SHADE = 0.55
# "speed" maps |v| / (SPEED_RMS_MULTIPLE * rms speed) onto the colormap. For a 2D gas in
# equilibrium (Rayleigh speeds) exp(-SPEED_RMS_MULTIPLE^2) = 1.8% of circles saturate.
# The rms speed is a sum over all circles, so the scale drifts slowly instead of flickering.
SPEED_RMS_MULTIPLE = 2.0

# Fixed-point unit of coverage: 2^14 keeps the 1/255 steps of the output exact to well
# below a grey level, and 255 * 2^14 * 512 < 2^31, so 512 fully covering layers of
# circles fit in a pixel before int32 overflow (non-overlapping circles sum to about 1).
_COVERAGE_BITS = 14
_COVERAGE_ONE = 1 << _COVERAGE_BITS
# Stage 4 draws the image in square tiles of this many pixels a side, one thread a tile.
_TILE_BITS = 4
_TILE = 1 << _TILE_BITS
# Entries (circle copies per tile) are counted in int32.
_MAX_ENTRIES = 2**31 - 1
# Below this radius in pixels a circle is drawn as the square of the same area (see the
# module docstring); the edge profile of larger circles sums to pi r^2 within 1% from here.
_SMALL_RADIUS = 1.5
_SQRT_PI = math.sqrt(math.pi)
# Below this radius in pixels a circle's area is under one pixel.
_POINT_RADIUS = 1.0 / _SQRT_PI

# Viridis, sampled at nine evenly spaced points and interpolated linearly in between: a
# perceptually uniform, colour-blind safe map whose lightness grows with speed.
VIRIDIS = np.array(
    [
        [68, 1, 84],
        [71, 45, 123],
        [59, 82, 139],
        [44, 114, 142],
        [33, 145, 140],
        [40, 174, 128],
        [94, 201, 98],
        [173, 220, 48],
        [253, 231, 37],
    ],
    dtype=np.float32,
)


@ti.func
def _reach(r: ti.f32) -> ti.f32:
    """Distance in pixels from a circle's centre beyond which it covers nothing."""
    reach = 0.0
    if r < _SMALL_RADIUS:
        reach = 0.5 * ti.max(_SQRT_PI * r, 1.0)
    else:
        reach = ti.sqrt(r * r - 1.0 / 12.0) + 0.5
    return reach


@ti.func
def _pixel_range(cx: ti.f32, cy: ti.f32, reach: ti.f32, clip: ti.math.ivec4) -> ti.math.ivec4:
    """Pixels [x_lo, x_hi) x [y_lo, y_hi) a circle may cover, within ``clip``."""
    # Clamped as floats first: a circle far larger than the image would overflow an i32.
    lo = ti.cast(clip, ti.f32) - 1.0
    hi = ti.cast(clip, ti.f32) + 1.0
    return ti.math.ivec4(ti.max(ti.floor(ti.max(cx - reach, lo[0]), ti.i32), clip[0]),
                         ti.min(ti.floor(ti.min(cx + reach, hi[1]), ti.i32) + 1, clip[1]),
                         ti.max(ti.floor(ti.max(cy - reach, lo[2]), ti.i32), clip[2]),
                         ti.min(ti.floor(ti.min(cy + reach, hi[3]), ti.i32) + 1, clip[3]))


@ti.func
def _tile_range(pixels: ti.math.ivec4) -> ti.math.ivec4:
    """Tiles [tx_lo, tx_hi) x [ty_lo, ty_hi) holding ``pixels``; none if it is empty."""
    tiles = ti.math.ivec4(0)
    if pixels[0] < pixels[1] and pixels[2] < pixels[3]:
        # Pixel indices are >= 0 here, so the shift is the floor division.
        tiles = ti.math.ivec4(pixels[0] >> _TILE_BITS, ((pixels[1] - 1) >> _TILE_BITS) + 1,
                              pixels[2] >> _TILE_BITS, ((pixels[3] - 1) >> _TILE_BITS) + 1)
    return tiles


@ti.func
def _image_centre(wx: ti.f32, wy: ti.f32, shift: ti.template(), view: ti.math.vec4,
                  box: ti.math.vec2) -> ti.math.vec2:
    """Image position of world point (wx, wy) moved by ``shift`` boxes (periodic copies)."""
    # view = (scale, origin_x, origin_y, box_h * scale + origin_y)
    return ti.math.vec2(view[1] + (wx + shift[0] * box[0]) * view[0],
                        view[3] - (wy + shift[1] * box[1]) * view[0])


# The copies of a circle drawn on a torus: a circle crossing an edge also shows on the
# opposite side. Without periodic boundaries only the first is drawn.
_SHIFTS = ((0, 0), (-1, 0), (1, 0), (0, -1), (0, 1), (-1, -1), (-1, 1), (1, -1), (1, 1))


# Taichi 1.7 runs a parallel loop on a CPU as one contiguous block of iterations per
# thread, each block at least this long: a loop over fewer than this many items per thread
# leaves threads idle (a loop over the 68 rows of tiles of a 1080-row image runs on one
# thread). Work that comes in a few large pieces (chunks of circles, rows of tiles) is
# therefore run by a loop of this many iterations per worker, the first iteration of each
# block being a worker: it takes pieces from a shared counter until none is left, so a
# thread slowed by other work takes fewer. Were the blocks laid out otherwise, the image
# would be the same, only drawn by fewer threads.
_CPU_BLOCK = 512


@ti.func
def _chunk_begin(c: ti.i32, n: ti.i32, chunks: ti.i32) -> ti.i32:
    """First circle of chunk ``c`` when ``n`` circles are cut into ``chunks`` equal ranges."""
    return ti.cast(ti.i64(n) * c // chunks, ti.i32)


@ti.func
def _packed_colour(i: ti.i32, vel: ti.template(), color: ti.template(), colormap: ti.template(),
                   speed_mode: ti.template(), inv_speed_scale: ti.f64) -> ti.f32:
    """Circle ``i``'s colour, its three bytes packed into the bits of an f32 (an entry's
    fourth number)."""
    rgb = ti.math.ivec3(0)
    if ti.static(speed_mode):
        # Scaled in the velocities' own precision before float32 (which the square of a speed
        # above 1e19 or below 1e-19 would leave), so the colours do not depend on the units.
        vx = ti.cast(vel[i, 0] * inv_speed_scale, ti.f32)
        vy = ti.cast(vel[i, 1] * inv_speed_scale, ti.f32)
        n_colors = colormap.shape[0]
        u = ti.math.clamp(ti.sqrt(vx * vx + vy * vy), 0.0, 1.0) * (n_colors - 1)
        k = ti.min(ti.cast(u, ti.i32), n_colors - 2)
        f = u - k
        for c in ti.static(range(3)):
            rgb[c] = ti.cast((1.0 - f) * colormap[k, c] + f * colormap[k + 1, c] + 0.5,
                             ti.i32)
    else:
        for c in ti.static(range(3)):
            rgb[c] = ti.cast(color[i, c], ti.i32)
    return ti.bit_cast(rgb[0] | (rgb[1] << 8) | (rgb[2] << 16), ti.f32)


@ti.kernel
def _count_tile_entries(
    pos: ti.types.ndarray(ndim=2),
    radius: ti.types.ndarray(ndim=1),
    tile_count: ti.types.ndarray(ndim=2),
    rank: ti.types.ndarray(ndim=1),
    view: ti.math.vec4,
    box: ti.math.vec2,
    clip: ti.math.ivec4,
    tiles_x: ti.i32,
    periodic: ti.template(),
):
    """Stage 1 (GPU): how many circles (periodic copies included) touch each tile.

    Most circles lie within one tile: those count in ``tile_count[t, 0]`` and keep their
    rank among them, so stage 3 places them without atomics (an atomic between scattered
    stores makes each store wait for the one before). Other entries count in
    ``tile_count[t, 1]`` and get ``rank = -1``."""
    for i in range(radius.shape[0]):
        reach = _reach(ti.cast(radius[i], ti.f32) * view[0])
        wx = ti.cast(pos[i, 0], ti.f32)
        wy = ti.cast(pos[i, 1], ti.f32)
        rank[i] = -1
        for s in ti.static(range(9 if periodic else 1)):
            centre = _image_centre(wx, wy, _SHIFTS[s], view, box)
            tiles = _tile_range(_pixel_range(centre[0], centre[1], reach, clip))
            if ti.static(s == 0):
                if tiles[0] + 1 == tiles[1] and tiles[2] + 1 == tiles[3]:
                    rank[i] = ti.atomic_add(tile_count[tiles[2] * tiles_x + tiles[0], 0], 1)
                    tiles[1] = tiles[0]  # counted: skip the loop below
            for ty in range(tiles[2], tiles[3]):
                for tx in range(tiles[0], tiles[1]):
                    ti.atomic_add(tile_count[ty * tiles_x + tx, 1], 1)


@ti.kernel
def _tile_offsets(tile_count: ti.types.ndarray(ndim=2), tile_start: ti.types.ndarray(ndim=1),
                  tile_cursor: ti.types.ndarray(ndim=1)) -> ti.i64:
    """Stage 2 (GPU): each tile's first entry (exclusive prefix sum of the counts) and the
    cursor where its entries without a rank go; zeroes the counts for the next call.

    Returns the number of entries. Serial: there are only a few thousand tiles."""
    total = ti.i64(0)
    ti.loop_config(serialize=True)
    for t in range(tile_count.shape[0]):
        tile_start[t] = ti.cast(ti.min(total, _MAX_ENTRIES), ti.i32)
        tile_cursor[t] = ti.cast(ti.min(total + tile_count[t, 0], _MAX_ENTRIES), ti.i32)
        total += tile_count[t, 0] + tile_count[t, 1]
        tile_count[t, 0] = 0
        tile_count[t, 1] = 0
    tile_start[tile_count.shape[0]] = ti.cast(ti.min(total, _MAX_ENTRIES), ti.i32)
    return total


@ti.kernel
def _bin_circles(
    pos: ti.types.ndarray(ndim=2),
    vel: ti.types.ndarray(ndim=2),
    radius: ti.types.ndarray(ndim=1),
    color: ti.types.ndarray(ndim=2),
    colormap: ti.types.ndarray(ndim=2),
    rank: ti.types.ndarray(ndim=1),
    tile_start: ti.types.ndarray(ndim=1),
    tile_cursor: ti.types.ndarray(ndim=1),
    entries: ti.types.ndarray(dtype=ti.math.vec4, ndim=1),
    speed_mode: ti.template(),
    inv_speed_scale: ti.f64,
    view: ti.math.vec4,
    box: ti.math.vec2,
    clip: ti.math.ivec4,
    tiles_x: ti.i32,
    periodic: ti.template(),
):
    """Stage 3 (GPU): write each circle's image centre, radius and colour into every tile
    it touches, so that stage 4 reads each tile's circles contiguously."""
    for i in range(radius.shape[0]):
        r = ti.cast(radius[i], ti.f32) * view[0]
        reach = _reach(r)
        wx = ti.cast(pos[i, 0], ti.f32)
        wy = ti.cast(pos[i, 1], ti.f32)
        packed_rgb = _packed_colour(i, vel, color, colormap, speed_mode, inv_speed_scale)
        for s in ti.static(range(9 if periodic else 1)):
            centre = _image_centre(wx, wy, _SHIFTS[s], view, box)
            tiles = _tile_range(_pixel_range(centre[0], centre[1], reach, clip))
            if ti.static(s == 0):
                if rank[i] >= 0:
                    slot = tile_start[tiles[2] * tiles_x + tiles[0]] + rank[i]
                    entries[slot] = ti.math.vec4(centre, r, packed_rgb)
                    tiles[1] = tiles[0]  # placed: skip the loop below
            for ty in range(tiles[2], tiles[3]):
                for tx in range(tiles[0], tiles[1]):
                    slot = ti.atomic_add(tile_cursor[ty * tiles_x + tx], 1)
                    entries[slot] = ti.math.vec4(centre, r, packed_rgb)


@ti.kernel
def _count_chunk_entries(
    pos: ti.types.ndarray(ndim=1),
    radius: ti.types.ndarray(ndim=1),
    chunk_count: ti.types.ndarray(dtype=ti.i32, ndim=1),
    chunks: ti.i32,
    only_tile: ti.types.ndarray(dtype=ti.i32, ndim=1),
    queue: ti.types.ndarray(dtype=ti.i32, ndim=1),
    workers: ti.i32,
    view: ti.math.vec4,
    box: ti.math.vec2,
    clip: ti.math.ivec4,
    tiles_x: ti.i32,
    periodic: ti.template(),
):
    """Stage 1 (CPU): ``chunk_count[c * tiles + t]``, the entries (circle copies) that
    chunk ``c`` of the circles puts into tile ``t``; ``only_tile[i]``, the one tile of
    circle ``i`` when it has one entry, of the circle itself (most circles), else -1.

    A chunk is a range of circles that one worker counts in the chunk's own row of
    counts, with plain increments: no atomics, which on a CPU cost more than the rest of
    the work. ``queue[0]`` hands out the chunks; it is zero before and after."""
    n = radius.shape[0]
    n_tiles = chunk_count.shape[0] // chunks
    for w in range(workers * _CPU_BLOCK):
        if w % _CPU_BLOCK == 0:
            c = ti.atomic_add(queue[0], 1)
            while c < chunks:
                row = c * n_tiles
                for t in range(n_tiles):
                    chunk_count[row + t] = 0
                for i in range(_chunk_begin(c, n, chunks), _chunk_begin(c + 1, n, chunks)):
                    reach = _reach(ti.cast(radius[i], ti.f32) * view[0])
                    wx = ti.cast(pos[2 * i], ti.f32)
                    wy = ti.cast(pos[2 * i + 1], ti.f32)
                    only = -1
                    for s in ti.static(range(9 if periodic else 1)):
                        centre = _image_centre(wx, wy, _SHIFTS[s], view, box)
                        tiles = _tile_range(_pixel_range(centre[0], centre[1], reach, clip))
                        if ti.static(s == 0):
                            if tiles[0] + 1 == tiles[1] and tiles[2] + 1 == tiles[3]:
                                only = tiles[2] * tiles_x + tiles[0]
                                chunk_count[row + only] = chunk_count[row + only] + 1
                                tiles[1] = tiles[0]  # counted: skip the loop below
                        if tiles[0] < tiles[1]:
                            # The tiles row by row in one loop: as two nested loops,
                            # LLVM takes several times longer to compile the kernel.
                            tx, ty = tiles[0], tiles[2]
                            while ty < tiles[3]:
                                k = row + ty * tiles_x + tx
                                chunk_count[k] = chunk_count[k] + 1
                                only = -1
                                tx += 1
                                if tx == tiles[1]:
                                    tx = tiles[0]
                                    ty += 1
                    only_tile[i] = only
                c = ti.atomic_add(queue[0], 1)
    queue[0] = 0


@ti.kernel
def _chunk_offsets(chunk_count: ti.types.ndarray(dtype=ti.i32, ndim=1), chunks: ti.i32,
                   tile_start: ti.types.ndarray(ndim=1)) -> ti.i64:
    """Stage 2 (CPU): each tile's first entry, and in place of each count the place of
    the chunk's first entry in the tile: a tile holds chunk 0's entries, then chunk 1's...

    Returns the number of entries. Serial: a few tens of thousands of counts."""
    n_tiles = tile_start.shape[0] - 1
    total = ti.i64(0)
    ti.loop_config(serialize=True)
    for t in range(n_tiles):
        tile_start[t] = ti.cast(ti.min(total, _MAX_ENTRIES), ti.i32)
        for c in range(chunks):
            k = c * n_tiles + t
            count = chunk_count[k]
            chunk_count[k] = ti.cast(ti.min(total, _MAX_ENTRIES), ti.i32)
            total += count
    tile_start[n_tiles] = ti.cast(ti.min(total, _MAX_ENTRIES), ti.i32)
    return total


@ti.kernel
def _bin_chunk_circles(
    pos: ti.types.ndarray(ndim=1),
    vel: ti.types.ndarray(ndim=2),
    radius: ti.types.ndarray(ndim=1),
    color: ti.types.ndarray(ndim=2),
    colormap: ti.types.ndarray(ndim=2),
    chunk_cursor: ti.types.ndarray(dtype=ti.i32, ndim=1),
    chunks: ti.i32,
    only_tile: ti.types.ndarray(dtype=ti.i32, ndim=1),
    queue: ti.types.ndarray(dtype=ti.i32, ndim=1),
    workers: ti.i32,
    entries: ti.types.ndarray(dtype=ti.math.vec4, ndim=1),
    speed_mode: ti.template(),
    inv_speed_scale: ti.f64,
    view: ti.math.vec4,
    box: ti.math.vec2,
    clip: ti.math.ivec4,
    tiles_x: ti.i32,
    periodic: ti.template(),
):
    """Stage 3 (CPU): write each circle's image centre, radius and colour into every tile
    it touches, at its chunk's cursor in the tile (the chunks of stage 1, so each cursor
    has one writer). A circle with a tile in ``only_tile`` goes there directly."""
    n = radius.shape[0]
    n_tiles = chunk_cursor.shape[0] // chunks
    for w in range(workers * _CPU_BLOCK):
        if w % _CPU_BLOCK == 0:
            c = ti.atomic_add(queue[0], 1)
            while c < chunks:
                row = c * n_tiles
                for i in range(_chunk_begin(c, n, chunks), _chunk_begin(c + 1, n, chunks)):
                    r = ti.cast(radius[i], ti.f32) * view[0]
                    wx = ti.cast(pos[2 * i], ti.f32)
                    wy = ti.cast(pos[2 * i + 1], ti.f32)
                    packed_rgb = _packed_colour(i, vel, color, colormap, speed_mode,
                                                inv_speed_scale)
                    only = only_tile[i]
                    if only >= 0:
                        k = row + only
                        slot = chunk_cursor[k]
                        chunk_cursor[k] = slot + 1
                        entries[slot] = ti.math.vec4(
                            _image_centre(wx, wy, _SHIFTS[0], view, box), r, packed_rgb)
                    else:
                        reach = _reach(r)
                        for s in ti.static(range(9 if periodic else 1)):
                            centre = _image_centre(wx, wy, _SHIFTS[s], view, box)
                            tiles = _tile_range(_pixel_range(centre[0], centre[1], reach,
                                                             clip))
                            for ty in range(tiles[2], tiles[3]):
                                for tx in range(tiles[0], tiles[1]):
                                    k = row + ty * tiles_x + tx
                                    slot = chunk_cursor[k]
                                    chunk_cursor[k] = slot + 1
                                    entries[slot] = ti.math.vec4(centre, r, packed_rgb)
                c = ti.atomic_add(queue[0], 1)
    queue[0] = 0


@ti.func
def _add(scratch: ti.template(), pixel: ti.i32, coverage: ti.f32, red_green: ti.i64,
         blue_one: ti.i64):
    """Add a coverage of the colour to scratch pixel ``pixel`` (two 64-bit words, each
    holding two 32-bit sums: red | green << 32 and blue | coverage << 32).

    The sums are non-negative and below 2^31 (see _COVERAGE_BITS), so adding the packed
    words adds each half on its own. The scratch tile has one user at a time: a plain
    read-modify-write, no atomics."""
    weight = ti.cast(ti.cast(coverage * _COVERAGE_ONE + 0.5, ti.i32), ti.i64)
    scratch[2 * pixel] = scratch[2 * pixel] + weight * red_green
    scratch[2 * pixel + 1] = scratch[2 * pixel + 1] + weight * blue_one


@ti.func
def _draw_circle(scratch: ti.template(), base: ti.i32, x0: ti.i32, y0: ti.i32, cx: ti.f32,
                 cy: ti.f32, r: ti.f32, red_green: ti.i64, blue_one: ti.i64,
                 pixels: ti.math.ivec4):
    """Accumulate the coverage of the circle of centre (cx, cy) and radius r (in pixels)
    over ``pixels`` = [x_lo, x_hi) x [y_lo, y_hi), into the scratch tile of first pixel
    ``base``, whose top-left pixel is at (x0, y0) in the image."""
    if r < _POINT_RADIUS:
        # Area below one pixel: the weights are bilinear in the sub-pixel position (the
        # general case below with a one-pixel square, unrolled: most circles of a
        # million-circle frame take this path).
        area = ti.math.pi * r * r
        fx = cx - 0.5
        fy = cy - 0.5
        x = ti.floor(fx, ti.i32)
        y = ti.floor(fy, ti.i32)
        tx = fx - x
        ty = fy - y
        first = base + (y - y0) * _TILE + x - x0
        if pixels[0] <= x and x + 1 < pixels[1] and pixels[2] <= y and y + 1 < pixels[3]:
            # All four pixels in the tile, as for most circles.
            for dy in ti.static(range(2)):
                for dx in ti.static(range(2)):
                    weight = area * (tx if dx else 1.0 - tx) * (ty if dy else 1.0 - ty)
                    _add(scratch, first + dy * _TILE + dx, weight, red_green, blue_one)
        else:
            for dy in ti.static(range(2)):
                for dx in ti.static(range(2)):
                    if pixels[0] <= x + dx < pixels[1] and pixels[2] <= y + dy < pixels[3]:
                        weight = area * (tx if dx else 1.0 - tx) * (ty if dy else 1.0 - ty)
                        _add(scratch, first + dy * _TILE + dx, weight, red_green, blue_one)
    elif r < _SMALL_RADIUS:
        # The square of the circle's area, box-filtered exactly: its pixel coverages sum
        # to pi r^2 wherever it sits. A side below one pixel is widened to one pixel at
        # lower density, which makes the weights bilinear in the sub-pixel position.
        side = ti.max(_SQRT_PI * r, 1.0)
        density = ti.math.pi * r * r / (side * side)
        half = 0.5 * side
        for y in range(pixels[2], pixels[3]):
            overlap_y = ti.min(y + 1.0, cy + half) - ti.max(y + 0.0, cy - half)
            for x in range(pixels[0], pixels[1]):
                overlap_x = ti.min(x + 1.0, cx + half) - ti.max(x + 0.0, cx - half)
                if overlap_x > 0.0 and overlap_y > 0.0:
                    _add(scratch, base + (y - y0) * _TILE + x - x0,
                         density * overlap_x * overlap_y, red_green, blue_one)
    else:
        reach = ti.sqrt(r * r - 1.0 / 12.0) + 0.5
        for y in range(pixels[2], pixels[3]):
            dy = y + 0.5 - cy
            for x in range(pixels[0], pixels[1]):
                dx = x + 0.5 - cx
                coverage = ti.min(reach - ti.sqrt(dx * dx + dy * dy), 1.0)
                if coverage > 0.0:
                    _add(scratch, base + (y - y0) * _TILE + x - x0, coverage, red_green,
                         blue_one)


@ti.func
def _draw_item(item: ti.i32, slot: ti.i32, tile_start: ti.template(), entries: ti.template(),
               scratch: ti.template(), image: ti.template(), width: ti.i32, height: ti.i32,
               clip: ti.math.ivec4, tiles_x: ti.i32, background: ti.math.vec3,
               margin: ti.math.vec3, box_px: ti.math.vec4, tiles_per_item: ti.i32):
    """Draw the ``tiles_per_item`` tiles of work item ``item`` one after the other, each
    accumulated in scratch tile ``slot``, which is left zeroed."""
    inside = ti.cast(background + 0.5, ti.i32)
    base = slot * _TILE * _TILE
    for step in range(tiles_per_item):
        t = item * tiles_per_item + step
        x0 = (t % tiles_x) * _TILE
        y0 = (t // tiles_x) * _TILE
        x1 = ti.min(x0 + _TILE, width)
        y1 = ti.min(y0 + _TILE, height)
        tile_clip = ti.math.ivec4(ti.max(x0, clip[0]), ti.min(x1, clip[1]),
                                  ti.max(y0, clip[2]), ti.min(y1, clip[3]))
        for k in range(tile_start[t], tile_start[t + 1]):
            entry = entries[k]
            cx, cy, r = entry[0], entry[1], entry[2]
            packed_rgb = ti.bit_cast(entry[3], ti.i32)
            red_green = ti.cast(packed_rgb & 255, ti.i64) \
                | (ti.cast((packed_rgb >> 8) & 255, ti.i64) << 32)
            blue_one = ti.cast(packed_rgb >> 16, ti.i64) | (ti.i64(1) << 32)
            _draw_circle(scratch, base, x0, y0, cx, cy, r, red_green, blue_one,
                         _pixel_range(cx, cy, _reach(r), tile_clip))
        # A tile wholly inside the box has the plain background; others shade the margin
        # and anti-alias the box edges by the fraction of each pixel inside.
        interior = (x0 >= box_px[0] and x1 <= box_px[1] and y0 >= box_px[2]
                    and y1 <= box_px[3])
        if interior and tile_start[t] == tile_start[t + 1]:
            # No circle here: the plain background, and the scratch is still zero.
            for y in range(y0, y1):
                for x in range(x0, x1):
                    for c in ti.static(range(3)):
                        image[(y * width + x) * 3 + c] = ti.cast(inside[c], ti.u8)
            continue
        for y in range(y0, y1):
            inside_y = ti.max(ti.min(y + 1.0, box_px[3]) - ti.max(y + 0.0, box_px[2]), 0.0)
            for x in range(x0, x1):
                rgb = inside
                if not interior:
                    inside_x = ti.max(ti.min(x + 1.0, box_px[1]) - ti.max(x + 0.0, box_px[0]),
                                      0.0)
                    rgb = ti.cast(margin + (background - margin) * (inside_x * inside_y) + 0.5,
                                  ti.i32)
                pixel = 2 * (base + (y - y0) * _TILE + x - x0)
                red_green = scratch[pixel]
                blue_total = scratch[pixel + 1]
                scratch[pixel] = ti.i64(0)
                scratch[pixel + 1] = ti.i64(0)
                total = ti.cast(blue_total >> 32, ti.i32)
                # Casting to i32 keeps the low 32 bits: the low half of a word.
                painted = ti.math.ivec3(ti.cast(red_green, ti.i32),
                                        ti.cast(red_green >> 32, ti.i32),
                                        ti.cast(blue_total, ti.i32))
                # The background shows through what the circles leave uncovered...
                mixed = (painted + rgb * (_COVERAGE_ONE - total) + _COVERAGE_ONE // 2) \
                    >> _COVERAGE_BITS
                if total > _COVERAGE_ONE:
                    # ...or overlapping circles: their colours averaged by coverage.
                    mixed = (painted + total // 2) // total
                # Without a branch on the coverage, which is as often zero as not.
                rgb = ti.select(total > 0, mixed, rgb)
                for c in ti.static(range(3)):
                    image[(y * width + x) * 3 + c] = ti.cast(ti.min(rgb[c], 255), ti.u8)


@ti.kernel
def _draw_tiles(
    tile_start: ti.types.ndarray(ndim=1),
    entries: ti.types.ndarray(dtype=ti.math.vec4, ndim=1),
    scratch: ti.types.ndarray(dtype=ti.i64, ndim=1),
    image: ti.types.ndarray(dtype=ti.u8, ndim=1),
    width: ti.i32,
    height: ti.i32,
    clip: ti.math.ivec4,
    tiles_x: ti.i32,
    background: ti.math.vec3,
    margin: ti.math.vec3,
    box_px: ti.math.vec4,
    tiles_per_item: ti.i32,
    queue: ti.types.ndarray(dtype=ti.i32, ndim=1),
    workers: ti.i32,
    cpu: ti.template(),
):
    """Stage 4: draw the tiles' circles and composite the pixels over the background.

    ``image`` is the (height, width, 3) image flattened and ``scratch`` holds tiles of
    ``_TILE * _TILE`` pixels of two words (see ``_add``): on a CPU an access through a
    one-dimensional array costs less than through a multidimensional one.

    The tiles are drawn in work items of ``tiles_per_item`` tiles. On a CPU an item is a
    row of tiles and ``workers`` workers (see ``_CPU_BLOCK``) take the items from
    ``queue[0]``, each with its own scratch tile, which stays in cache; the image is
    written band by band. On a GPU an item is a single tile, with its thread and its
    scratch tile."""
    items = (tile_start.shape[0] - 1) // tiles_per_item
    if ti.static(cpu):
        for w in range(workers * _CPU_BLOCK):
            if w % _CPU_BLOCK == 0:
                item = ti.atomic_add(queue[0], 1)
                while item < items:
                    _draw_item(item, w // _CPU_BLOCK, tile_start, entries, scratch, image,
                               width, height, clip, tiles_x, background, margin, box_px,
                               tiles_per_item)
                    item = ti.atomic_add(queue[0], 1)
        queue[0] = 0
    else:
        ti.loop_config(block_dim=128)
        for item in range(items):
            _draw_item(item, item, tile_start, entries, scratch, image, width, height, clip,
                       tiles_x, background, margin, box_px, tiles_per_item)


def _on_cpu():
    return impl.current_cfg().arch in (ti.x64, ti.arm64)


# On a CPU stages 1 and 3 cut the circles into this many chunks per thread (for balance
# when a thread is slowed), each with a row of counts over all the tiles...
_CHUNKS_PER_THREAD = 4
# ...unless the rows would take more than this many counts: then the atomic stages run.
_MAX_CHUNK_COUNTS = 1 << 24


def _cpu_threads():
    return max(int(impl.current_cfg().cpu_max_num_threads), 1)


def _cpu_chunks(tiles):
    """Chunks of circles for stages 1 and 3 on a CPU; 0 to use the atomic stages."""
    threads = _cpu_threads()
    chunks = min(_CHUNKS_PER_THREAD * threads, _MAX_CHUNK_COUNTS // tiles)
    return chunks if chunks >= threads else 0


class _Buffers:
    """Device arrays kept between calls of the same image size.

    They belong to the Taichi program that made them; after ``ti.reset`` or a new
    ``ti.init`` they are made again. Stage 1 (CPU) or 2 (GPU) zeroes the tile counts,
    stage 4 the accumulator and each CPU stage its queue, so they are cleared only after
    a call was interrupted midway.
    """

    def __init__(self):
        self.program = None
        self.size = None
        self.dirty = False

    def get(self, height, width):
        program = impl.get_runtime().prog
        if self.program is not program or self.size != (height, width):
            self.program = None  # stays None if an allocation below fails
            tiles_x, tiles_y = -(-width // _TILE), -(-height // _TILE)
            self.tiles_x, self.tiles = tiles_x, tiles_x * tiles_y
            self.scratch = self.tile_count = self.tile_cursor = self.chunk_count = None
            self.cpu = _on_cpu()
            self.workers = _cpu_threads() if self.cpu else 0
            self.tiles_per_item = tiles_x if self.cpu else 1
            self.chunks = _cpu_chunks(self.tiles) if self.cpu else 0
            # A scratch tile per worker on a CPU, per item on a GPU; two 64-bit words per
            # pixel (see _add).
            slots = self.workers if self.cpu else self.tiles // self.tiles_per_item
            self.scratch = ti.ndarray(ti.i64, shape=(slots * _TILE * _TILE * 2,))
            self.queue = ti.ndarray(ti.i32, shape=(1,))
            if self.chunks:
                self.chunk_count = ti.ndarray(ti.i32, shape=(self.chunks * self.tiles,))
            else:
                self.tile_count = ti.ndarray(ti.i32, shape=(self.tiles, 2))
                self.tile_cursor = ti.ndarray(ti.i32, shape=(self.tiles,))
            self.tile_start = ti.ndarray(ti.i32, shape=(self.tiles + 1,))
            self.entries = None
            self.rank = None
            self.dirty = True
            self.size = (height, width)
            self.program = program
        if self.dirty:
            self.scratch.fill(0)
            self.queue.fill(0)
            if self.tile_count is not None:
                self.tile_count.fill(0)
            self.dirty = False
        return self

    def reserve_circles(self, n):
        # Per circle: its rank in its tile (GPU stages) or its only tile (CPU stages).
        if self.rank is None or self.rank.shape[0] < n:
            self.rank = None
            self.rank = ti.ndarray(ti.i32, shape=(max(n + n // 4, 1024),))

    def reserve_entries(self, entries):
        if self.entries is None or self.entries.shape[0] < entries:
            capacity = max(entries + entries // 4, 1024)
            self.entries = None
            # Per entry: image centre x, y and radius in pixels, and the colour's bytes.
            self.entries = ti.ndarray(ti.math.vec4, shape=(capacity,))

    def drop(self):
        """Let go of every array (before `circles.init` restarts the runtime)."""
        self.__dict__.clear()
        self.__init__()


_buffers = _Buffers()
on_restart(_buffers.drop)


def _check_size(name, value):
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) \
            or not 1 <= value <= MAX_IMAGE_SIDE:
        raise ValueError(
            f"{name} {value!r} is not allowed: image width and height are integers "
            f"from 1 to {MAX_IMAGE_SIDE}")
    return int(value)


def _float_array(name, value, shape_tail, n):
    array = np.asarray(value)
    if array.dtype not in (np.float32, np.float64):
        array = array.astype(np.float64)
    if array.shape[1:] != shape_tail or (n is not None and array.shape[0] != n) \
            or array.ndim != 1 + len(shape_tail):
        expected = "(n, " + ", ".join(map(str, shape_tail)) + ")" if shape_tail else "(n,)"
        raise ValueError(f"{name} has shape {array.shape}, expected {expected}"
                         + (f" with n = {n}" if n is not None else ""))
    return np.ascontiguousarray(array)


def _check_circles(pos, vel, radius, n):
    """ValueError naming the first circle whose radius is not finite and > 0, or whose place or
    velocity is not finite."""
    for name, values in (("radius", radius), ("pos", pos), ("vel", vel)):
        bad = ~np.isfinite(values) | ((values <= 0) if name == "radius" else False)
        if bad.any():
            i = int(np.flatnonzero(bad.reshape(n, -1).any(axis=1))[0])
            raise ValueError(f"circle {i}'s {name} {values[i].tolist()} must be finite"
                             + (" and > 0" if name == "radius" else ""))


def letterbox(box, width, height):
    """Fit ``box`` = (W, H) into a width x height image, centred, aspect kept.

    Returns (scale, origin_x, origin_y): world (x, y) lands on image point
    ``(origin_x + x * scale, origin_y + (H - y) * scale)`` in pixels from the top-left.
    """
    box_w, box_h = float(box[0]), float(box[1])
    scale = min(width / box_w, height / box_h)
    return scale, 0.5 * (width - box_w * scale), 0.5 * (height - box_h * scale)


def speed_scale_of(vel):
    """The speed that maps to the top of the colormap in "speed" mode: a multiple of the
    root-mean-square speed (1.0 when every circle is at rest)."""
    vel = np.asarray(vel, dtype=np.float64)
    if len(vel) == 0:
        return 1.0
    squares = float(np.einsum("ij,ij->", vel, vel))
    if 1e-280 < squares < math.inf:
        return SPEED_RMS_MULTIPLE * math.sqrt(squares / len(vel))
    largest = float(np.max(np.abs(vel)))
    if not (largest > 0.0 and math.isfinite(largest)):
        return 1.0
    unit = vel / largest  # speeds whose squares overflow or underflow: in units of the fastest
    return SPEED_RMS_MULTIPLE * largest * math.sqrt(float(np.einsum("ij,ij->", unit, unit)) / len(vel))


def render(pos, vel, radius, color, box, width=1280, height=720, color_mode="random",
           background=(16, 16, 24), *, speed_scale=None, periodic=False, check=True):
    """Draw circles into a new RGB image.

    Args:
      pos: (n, 2) float, centres in world units; the box is [0, W] x [0, H], y up.
      vel: (n, 2) float, velocities in world units per time unit (used by "speed").
      radius: (n,) float, radii in world units.
      color: (n, 3) uint8, each circle's colour (used by "random").
      box: (W, H), the box size in world units.
      width, height: image size in pixels, 1 to 16384.
      color_mode: "random" (each circle's own colour), "speed" (viridis of |v|) or "hexatic"
        (the orientation of each circle's local psi_6 as a hue, its modulus as brightness:
        `circles.order.hexatic_colors`).
      background: RGB of the inside of the box; the margin outside is darker.
      speed_scale: the speed shown at the top of the colormap; by default twice the rms
        speed of this frame. Pass a fixed value to keep colours fixed over a run.
      periodic: also draw, on the opposite side, the part of a circle that crosses an edge.
      check: refuse radii that are not finite and > 0, places and velocities that are not
        finite, and colours that are not 0-255 (ValueError naming the circle); a simulation's
        own state, which holds none, skips this pass over the arrays.

    Returns:
      uint8 array of shape (height, width, 3), row 0 at the top.
    """
    width = _check_size("width", width)
    height = _check_size("height", height)
    if color_mode not in COLOR_MODES:
        raise ValueError(f"color mode {color_mode!r} is not one of {', '.join(COLOR_MODES)}")
    box_w, box_h = (float(v) for v in box)
    if not (box_w > 0 and box_h > 0 and math.isfinite(box_w) and math.isfinite(box_h)):
        raise ValueError(f"box {tuple(box)} must be two positive finite sizes (W, H)")
    radius = _float_array("radius", radius, (), None)
    n = radius.shape[0]
    pos = _float_array("pos", pos, (2,), n)
    vel = _float_array("vel", vel, (2,), n)
    if check:
        _check_circles(pos, vel, radius, n)
        from .inputs import check_colors

        color = check_colors(color, n)
    else:
        color = np.ascontiguousarray(color, dtype=np.uint8)
    if color_mode == "hexatic":
        from .order import hexatic_colors, psi6
        color = hexatic_colors(psi6(pos, (box_w, box_h), bool(periodic)))
    # World lengths in units of a power of two near the box's side (an exact scaling), so that
    # a box of any size draws in the float32 of the kernels.
    exponent = math.frexp(max(box_w, box_h))[1]
    if abs(exponent) > 60:
        pos, radius = np.ldexp(pos.astype(np.float64), -exponent), np.ldexp(radius.astype(np.float64), -exponent)
        box_w, box_h = math.ldexp(box_w, -exponent), math.ldexp(box_h, -exponent)
    background = np.asarray(background, dtype=np.float32)
    if background.shape != (3,) or not ((background >= 0) & (background <= 255)).all():
        raise ValueError(f"background {background.tolist()} must be an RGB triple of 0 to 255")

    scale, origin_x, origin_y = letterbox((box_w, box_h), width, height)
    box_px = (origin_x, origin_x + box_w * scale, origin_y, origin_y + box_h * scale)
    # Circles are clipped to the pixels the box touches, so none spill into the margin.
    clip = ti.math.ivec4(max(int(math.floor(box_px[0])), 0),
                         min(int(math.ceil(box_px[1])), width),
                         max(int(math.floor(box_px[2])), 0),
                         min(int(math.ceil(box_px[3])), height))
    view = ti.math.vec4(scale, origin_x, origin_y, origin_y + box_h * scale)
    box_vec = ti.math.vec2(box_w, box_h)
    speed_mode = color_mode == "speed"
    if speed_scale is None:
        speed_scale = speed_scale_of(vel) if speed_mode else 1.0
    if isinstance(speed_scale, bool) or not isinstance(speed_scale, Real) or not (
            speed_scale > 0 and math.isfinite(speed_scale)):
        raise ValueError(f"speed_scale {speed_scale!r} must be a positive finite number (the speed at the top of "
                         "the colormap), or None for twice the rms speed")
    periodic = bool(periodic)

    image = np.empty((height, width, 3), dtype=np.uint8)
    buffers = _buffers.get(height, width)
    _buffers.dirty = True
    buffers.reserve_circles(n)
    # The CPU stages take the positions flattened: cheaper to index.
    flat_pos = pos.reshape(-1)
    if buffers.chunks:
        _count_chunk_entries(flat_pos, radius, buffers.chunk_count, buffers.chunks,
                             buffers.rank, buffers.queue, buffers.workers, view, box_vec,
                             clip, buffers.tiles_x, periodic)
        entries = _chunk_offsets(buffers.chunk_count, buffers.chunks, buffers.tile_start)
    else:
        _count_tile_entries(pos, radius, buffers.tile_count, buffers.rank, view, box_vec,
                            clip, buffers.tiles_x, periodic)
        entries = _tile_offsets(buffers.tile_count, buffers.tile_start, buffers.tile_cursor)
    if entries > _MAX_ENTRIES:
        raise ValueError(f"{entries} circle-tile overlaps exceed {_MAX_ENTRIES}: the "
                         "circles are too large for this image size")
    buffers.reserve_entries(entries)
    inv_speed_scale = min(1.0 / speed_scale, 1e300)  # finite, so that a circle at rest maps to 0
    if buffers.chunks:
        _bin_chunk_circles(flat_pos, vel, radius, color, VIRIDIS, buffers.chunk_count,
                           buffers.chunks, buffers.rank, buffers.queue, buffers.workers,
                           buffers.entries, speed_mode, inv_speed_scale, view, box_vec, clip,
                           buffers.tiles_x, periodic)
    else:
        _bin_circles(pos, vel, radius, color, VIRIDIS, buffers.rank, buffers.tile_start,
                     buffers.tile_cursor, buffers.entries, speed_mode, inv_speed_scale, view,
                     box_vec, clip, buffers.tiles_x, periodic)
    _draw_tiles(buffers.tile_start, buffers.entries, buffers.scratch, image.reshape(-1),
                width, height, clip, buffers.tiles_x, ti.math.vec3(*background),
                ti.math.vec3(*(background * MARGIN_SHADE)), ti.math.vec4(*box_px),
                buffers.tiles_per_item, buffers.queue, buffers.workers, buffers.cpu)
    _buffers.dirty = False
    return image
