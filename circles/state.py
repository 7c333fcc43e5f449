"""State: a copy of a simulation's circles, as `Simulation.state` returns it."""
from dataclasses import dataclass

import numpy as np


@dataclass
class State:
    """A copy of the state in creation order.

    pos (n, 2) and vel (n, 2): world units and units per second, float64.
    radius (n,), mass (n,): float64. color (n, 3): uint8 RGB.
    """

    pos: np.ndarray
    vel: np.ndarray
    radius: np.ndarray
    mass: np.ndarray
    color: np.ndarray
