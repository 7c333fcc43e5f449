"""Bond-orientational order of disks: the local hexatic order psi_6 of each circle and the
global order |psi_6|.

For circle j with its six nearest neighbours k (centre distances, across the periodic box's
sides when it is periodic),

    psi_6(j) = (1/6) sum_k exp(6 i theta_jk),

theta_jk the angle of the vector from j to k against the x axis. |psi_6(j)| is 1 when the six
sit at the corners of a regular hexagon, whatever its orientation; the angle of psi_6(j) over
6 is the orientation of that hexagon, which is what the hexatic colouring shows
(`--color hexatic`). The global order is |(1/N) sum_j psi_6(j)|: near 1 in a crystal or a
hexatic domain that fills the box, of order 1/sqrt(N) in a fluid.

Six nearest neighbours (not Voronoi neighbours) is freud's ``freud.order.Hexatic(k=6)`` with a
``num_neighbors=6`` query, so the values equal freud's on the same positions (tested). Order is
computed only when asked for (`Simulation.order`, `--color hexatic`, a trajectory's
`log/particles/circles/psi6` with `GSDWriter(order=True)`): a run that does not ask pays
nothing.
"""
from __future__ import annotations

import numpy as np

#: The neighbours each circle's psi_6 takes.
NEIGHBOURS = 6


def psi6(pos, box, periodic) -> np.ndarray:
    """psi_6 of each circle, complex (N,), from positions (N, 2) in the box [0, W] x [0, H]."""
    from scipy.spatial import cKDTree

    pos = np.asarray(pos, dtype=np.float64)
    n = pos.shape[0]
    if n <= NEIGHBOURS:
        raise ValueError(f"psi_6 needs more than {NEIGHBOURS} circles (each takes its {NEIGHBOURS} nearest "
                         f"neighbours): this scene has {n}")
    w, h = float(box[0]), float(box[1])
    if periodic:
        wrapped = np.mod(pos, [w, h])
        wrapped[wrapped >= [w, h]] = 0.0  # a coordinate that rounds up to the side is at 0
        tree = cKDTree(wrapped, boxsize=[w, h])
    else:
        wrapped = pos
        tree = cKDTree(wrapped)
    _, index = tree.query(wrapped, k=NEIGHBOURS + 1)
    neighbours = index[:, 1:]  # the first is the circle itself
    d = wrapped[neighbours] - wrapped[:, None, :]
    if periodic:
        d -= np.array([w, h]) * np.round(d / np.array([w, h]))
    angle = np.arctan2(d[..., 1], d[..., 0])
    return np.exp(6j * angle).mean(axis=1)


def hexatic_order(local) -> float:
    """|psi_6| of the whole: the modulus of the mean of the circles' psi_6."""
    return float(abs(np.mean(local)))


def orientation(local) -> np.ndarray:
    """The orientation of each circle's hexagon of neighbours, in [0, pi/3): arg(psi_6) / 6."""
    return np.mod(np.angle(local) / 6.0, np.pi / 3.0)


def hexatic_colors(local) -> np.ndarray:
    """(N, 3) uint8 colours of circles by their psi_6: the hue is the orientation of the hexagon
    of neighbours (its 60 degrees once round the colour wheel, so that one domain is one hue),
    the brightness grows with |psi_6| (dark where the neighbours are disordered)."""
    hue = (np.angle(local) / (2 * np.pi)) % 1.0
    value = 0.25 + 0.75 * np.clip(np.abs(local), 0.0, 1.0)
    sector = np.floor(hue * 6.0).astype(int) % 6
    f = hue * 6.0 - np.floor(hue * 6.0)
    p, q, t = np.zeros_like(value), value * (1 - f), value * f
    rgb = np.select([sector[:, None] == k for k in range(6)],
                    [np.stack(c, axis=1) for c in ((value, t, p), (q, value, p), (p, value, t), (p, q, value),
                                                   (t, p, value), (value, p, q))])
    return np.round(255 * rgb).astype(np.uint8)
