"""Small Taichi functions shared by the schemes: displacement, event keys, neighbour cells.

Event keys order events totally: (time, lo, hi), with lo < hi the two circle ids of a pair,
or (time, i, n + w) for a hit of circle i on wall w. Every choice between events compares
keys, never the order in which threads or cells were visited, so results do not depend on
the thread count or on atomic slot order inside a cell.
"""
import taichi as ti

#: "No event": larger than any step, representable in float32.
NEVER = 1.0e30

#: Wall codes stored as partners: -1 is x = 0, -2 is x = W, -3 is y = 0, -4 is y = H.
WALL_LEFT, WALL_RIGHT, WALL_BOTTOM, WALL_TOP = -1, -2, -3, -4
NO_EVENT = -10


@ti.func
def displacement(xi, xj, box, periodic: ti.template()):
    """x_j - x_i, by the minimum image in a periodic box."""
    d = xj - xi
    if ti.static(periodic):
        d -= box * ti.floor(d / box + 0.5)
    return d


@ti.func
def key_less(t1, a1, b1, t2, a2, b2):
    less = False
    if t1 < t2:
        less = True
    elif t1 == t2:
        if a1 < a2:
            less = True
        elif a1 == a2 and b1 < b2:
            less = True
    return less


@ti.func
def neighbour_cell(c, a, b, ncx, ncy, periodic: ti.template()):
    """Cell number of the (a, b)-th of the cells around cell c, or -1 outside the walls.

    a and b run over range(span(ncx)) and range(span(ncy)); in a periodic box with fewer than
    3 cells along an axis the span covers each cell once, so no pair is seen twice.
    """
    cx = c % ncx
    cy = c // ncx
    sx = 1 if ncx >= 3 else 0
    sy = 1 if ncy >= 3 else 0
    if ti.static(not periodic):
        sx = 1
        sy = 1
    nx = cx + a - sx
    ny = cy + b - sy
    out = -1
    if ti.static(periodic):
        nx = (nx + ncx) % ncx
        ny = (ny + ncy) % ncy
        out = ny * ncx + nx
    else:
        if 0 <= nx < ncx and 0 <= ny < ncy:
            out = ny * ncx + nx
    return out


def span(ncells: int, periodic: bool) -> int:
    return min(3, ncells) if periodic else 3
