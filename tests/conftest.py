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


#: Taichi options of the suite's own runtimes (this process's and the scripts of
#: process_util). On the CPU: no CFG optimisation in Taichi's IR passes, so the large step
#: kernels compile about ten times sooner (the suite compiles some 140 kernel variants). The
#: kernels give the same bits either way (test_compile_options.py). circles itself compiles
#: this way below `backend.OPTIMIZE_FROM_N` circles and with the pass above, where its kernels
#: run faster; the command-line tests run `circles` as a user does, with its own choice.
TEST_INIT_OPTIONS = {"cfg_optimization": False} if TEST_ARCH == "cpu" else {}


@pytest.fixture(scope="session")
def circles_cpu():
    import circles

    circles.init(arch=TEST_ARCH, **TEST_INIT_OPTIONS)
    return circles

