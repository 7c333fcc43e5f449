"""circles: many 2D elastic circles in a box, exact (event-driven) or fast (discrete), on CPU or GPU.

    import circles
    circles.init(arch="cpu")
    sim = circles.Simulation(circles.Scene(n=10_000))
    sim.advance(1.0)
    print(sim.stats())

The names below are imported when first used (`import circles` alone loads no kernels), so
that the command line can take hold of Ctrl-C before Taichi's modules load.
"""
import importlib
import os

# Taichi prints a banner line on stdout when it is imported; circles' output is its own (set
# ENABLE_TAICHI_HEADER_PRINT=1 to see it).
os.environ.setdefault("ENABLE_TAICHI_HEADER_PRINT", "0")

__all__ = ["init", "Scene", "Simulation", "State"]
__version__ = "0.1.0"

#: Where each public name lives.
_HOMES = {"init": "backend", "Scene": "scene", "Simulation": "simulation", "State": "state"}


def __getattr__(name):
    """The public names, and the submodules (`circles.simulation`, ...), on first use."""
    if name in _HOMES:
        value = getattr(importlib.import_module(f".{_HOMES[name]}", __name__), name)
        globals()[name] = value
        return value
    if not name.startswith("_"):
        try:
            return importlib.import_module(f".{name}", __name__)
        except ModuleNotFoundError as error:
            if error.name != f"{__name__}.{name}":
                raise
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted([*globals(), *_HOMES])
