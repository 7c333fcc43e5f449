"""Runs in fresh processes: of a script, for the tests that compare whole runs bit for bit,
and of the command line.

``ti.init`` is per process, so each configuration runs in its own process and writes its
arrays to an npz file. A configuration is "cpu:THREADS" or "gpu"; the script receives it as
its first argument and starts Taichi with `INIT` (paste it into the script).
"""

import os
import pathlib
import signal
import subprocess
import sys
import time

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


def child_env(**extra):
    """This process's environment, with the repository first on PYTHONPATH (so that a child
    imports this tree's circles) and `extra` added."""
    return {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]), **extra}


def run_cli(args, cwd, *, python=("-m", "circles.cli"), extra_env=None, timeout=120, **options):
    """``python PYTHON... ARGS`` in `cwd` (by default the command line, ``-m circles.cli``; a
    ``-c`` script in its place runs that); the CompletedProcess, its output captured as text
    unless `options` (for subprocess.run) say otherwise."""
    options.setdefault("capture_output", "stdout" not in options and "stderr" not in options)
    return subprocess.run([sys.executable, *python, *args], cwd=cwd, env=child_env(**(extra_env or {})),
                          text=True, timeout=timeout, **options)


def stop_with_ctrl_c(args, cwd, ready, wait=90, poll=0.1, sig=signal.SIGINT):
    """Start the command line with `args` in `cwd` and send it SIGINT (Ctrl-C), or `sig`, as
    soon as `ready()` holds; fails if it ends first or is not ready within `wait` seconds.
    Returns (returncode, stdout, stderr)."""
    process = subprocess.Popen([sys.executable, "-m", "circles.cli", *args], cwd=cwd, env=child_env(),
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + wait
        while not ready():
            assert process.poll() is None, process.communicate()
            assert time.monotonic() < deadline
            time.sleep(poll)
        process.send_signal(sig)
        stdout, stderr = process.communicate(timeout=60)
    finally:
        process.kill()
    return process.returncode, stdout, stderr


def run_script(script, where, out, *args, timeout=900):
    """Run `script` with arguments (where, out, *args) in a fresh process; returns np.load(out)."""
    done = subprocess.run([sys.executable, "-c", script, where, str(out), *args], cwd=ROOT, env=child_env(),
                          capture_output=True, text=True, timeout=timeout)
    assert done.returncode == 0, done.stderr[-3000:]
    return np.load(out)
