"""circles: many 2D elastic circles in a box, exact (event-driven) or fast (discrete), on CPU or GPU.

    import circles
    circles.init(arch="cpu")
    sim = circles.Simulation(circles.Scene(n=10_000))
    sim.advance(1.0)
    print(sim.stats())
"""
from .backend import init
from .scene import Scene
from .simulation import Simulation, State

__all__ = ["init", "Scene", "Simulation", "State"]
__version__ = "0.1.0"
