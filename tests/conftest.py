"""Shared fixtures.

Taichi is initialised once per test session (``ti.init`` resets every field, so
it must not run between tests that hold simulations), on the CPU unless
``CIRCLES_TEST_ARCH=gpu`` is set: then the whole suite runs on the GPU, and the
determinism tests compare two GPU runs instead of 1 and 2 CPU threads. Tests that
need the engine take the ``circles_cpu`` fixture; it returns the package.
"""

import os
import pathlib
import sys

import pytest

TESTS = pathlib.Path(__file__).resolve().parent
if str(TESTS) not in sys.path:  # lets tests import the reference simulator
    sys.path.insert(0, str(TESTS))


#: Where the suite runs: "cpu" (the default) or "gpu".
TEST_ARCH = os.environ.get("CIRCLES_TEST_ARCH", "cpu")
if TEST_ARCH not in ("cpu", "gpu"):
    raise ValueError(f"CIRCLES_TEST_ARCH={TEST_ARCH!r}: use cpu or gpu")


@pytest.fixture(scope="session")
def circles_cpu():
    import circles

    circles.init(arch=TEST_ARCH)
    return circles

