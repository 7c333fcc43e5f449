"""Shared fixtures.

Taichi is initialised once per test session on the CPU (``ti.init`` resets
every field, so it must not run between tests that hold simulations). Tests
that need the engine take the ``circles_cpu`` fixture; it returns the package.
"""

import pathlib
import sys

import pytest

TESTS = pathlib.Path(__file__).resolve().parent
if str(TESTS) not in sys.path:  # lets tests import the reference simulator
    sys.path.insert(0, str(TESTS))


@pytest.fixture(scope="session")
def circles_cpu():
    import circles

    circles.init(arch="cpu")
    return circles

