"""circles: many 2D elastic circles in a box, exact (event-driven) or fast (discrete), on CPU or GPU.

    import circles
    circles.init(arch="cpu")
    sim = circles.Simulation(circles.Scene(n=10_000))
    sim.advance(1.0)
    print(sim.stats())
"""
import os

# Taichi prints a banner line on stdout when it is imported; circles' output is its own (set
# ENABLE_TAICHI_HEADER_PRINT=1 to see it).
os.environ.setdefault("ENABLE_TAICHI_HEADER_PRINT", "0")

from .backend import init  # noqa: E402 (after the switch above, which Taichi reads at import)
from .scene import Scene  # noqa: E402
from .simulation import Simulation, State  # noqa: E402

__all__ = ["init", "Scene", "Simulation", "State"]
__version__ = "0.1.0"
