"""Runs of a script in fresh processes, for the tests that compare whole runs bit for bit.

``ti.init`` is per process, so each configuration runs in its own process and writes its
arrays to an npz file. A configuration is "cpu:THREADS" or "gpu"; the script receives it as
its first argument and starts Taichi with `INIT` (paste it into the script).
"""

import os
import pathlib
import subprocess
import sys

import numpy as np

from conftest import TEST_ARCH, TEST_INIT_OPTIONS

ROOT = pathlib.Path(__file__).resolve().parents[1]

#: Script lines that start Taichi as the first argument says ("cpu:2", "gpu"), with the
#: suite's options (conftest.TEST_INIT_OPTIONS).
INIT = f"""
arch, _, threads = sys.argv[1].partition(":")
circles.init(arch=arch, **({{"cpu_max_num_threads": int(threads)}} if threads else {{}}), **{TEST_INIT_OPTIONS!r})
"""


def compared_runs():
    """The two configurations whose states must agree bit for bit: 1 and 2 CPU threads, or,
    when the suite runs on the GPU, two GPU runs (atomic slot orders differ between them)."""
    return ("gpu", "gpu") if TEST_ARCH == "gpu" else ("cpu:1", "cpu:2")


def run_script(script, where, out, *args, timeout=900):
    """Run `script` with arguments (where, out, *args) in a fresh process; returns np.load(out)."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")])
    done = subprocess.run([sys.executable, "-c", script, where, str(out), *args], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=timeout)
    assert done.returncode == 0, done.stderr[-3000:]
    return np.load(out)
