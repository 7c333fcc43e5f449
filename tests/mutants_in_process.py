"""Run mutmut's mutants in one process: for each, switch it on and run the tests that reach its
function (from mutmut's stats), stopping at the first failure.

mutmut forks a child a mutant, and each child starts Taichi and loads the kernels its tests
use: seconds a mutant before any test runs. Here Taichi starts once and the kernels stay
loaded, so a mutant costs only its tests. Use it for modules with many mutants whose tests run
simulations (`scene`). Run it in mutmut's folder, after `mutmut run` has made the mutants and
its stats (a run stopped at once will do):

    cd mutants
    python tests/mutants_in_process.py NAMES.txt RESULTS.txt [EXTRA_TEST ...]

NAMES.txt holds a mutant name a line (`mutmut results --all true`); each line of RESULTS.txt
is "NAME killed|survived|timeout|error-STATUS SECONDS" (a timeout: an endless loop, or one
stopped by an alarm; an error: pytest found no such test, say). A mutant RESULTS.txt holds is
skipped, so a rerun goes on where it stopped, and two processes sharing one RESULTS.txt (one
given NAMES.txt in reverse) split the work. EXTRA_TEST: tests run for every mutant before its
own (tests added since the stats were taken, for the survivors of a run). Tests
that start processes of their own (a Dask cluster, the command line) do not see the mutant.
"""
import json
import os
import signal
import sys
import time

import pytest

#: Test files tried first: those of the refusals, which kill most mutants of a scene's checks.
FIRST = {"tests/test_validation.py": 0, "tests/test_compress.py": 1, "tests/test_file_fuzz.py": 2}
#: pytest in this process, tests in their given order, none of the project's default options.
PYTEST = ["-q", "-n", "0", "-p", "no:randomly", "-p", "no:cacheprovider", "-p", "no:warnings", "--no-header",
          "-o", "addopts="]


class _Timeout(Exception):
    pass


_timed_out = []


def _alarm(*_):
    _timed_out.append(True)  # pytest reports the exception as a failing test: the verdict says timeout
    raise _Timeout()


def _done(results_file):
    with open(results_file) as file:
        return {line.split()[0] for line in file if line.strip()}


def main(names_file, results_file, extra):
    sys.path.insert(0, os.getcwd())  # mutmut's folder: its mutated package, not the one installed
    names = [line.strip() for line in open(names_file) if line.strip()]
    if not os.path.isfile("mutmut-stats.json"):
        sys.exit(f"no mutmut-stats.json in {os.getcwd()}: run this in mutmut's folder (mutants/) after `mutmut run`")
    stats = json.load(open("mutmut-stats.json"))
    by_function, duration = stats["tests_by_mangled_function_name"], stats["duration_by_test"]
    package = __import__(next(iter(by_function)).split(".")[0])
    if not os.path.abspath(package.__file__).startswith(os.getcwd() + os.sep):
        sys.exit(f"{package.__name__} is imported from {package.__file__}, not from mutmut's folder {os.getcwd()}: "
                 "run this in that folder")
    os.environ["MUTANT_UNDER_TEST"] = ""
    if extra and pytest.main([*PYTEST, *extra]) != pytest.ExitCode.OK:
        sys.exit("the extra tests fail without a mutant: every mutant would look killed")
    signal.signal(signal.SIGALRM, _alarm)
    with open(results_file, "a", buffering=1) as out:
        for name in names:
            if name in _done(results_file):  # by this process, or by another sharing the file
                continue
            function = name.split("__mutmut_")[0]
            tests = sorted(by_function.get(function, []),
                           key=lambda t: (FIRST.get(t.split("::")[0], len(FIRST)), duration.get(t, 0.0)))
            tests = list(extra) + [t for t in tests if t not in extra]
            if not tests:
                out.write(f"{name} no-tests 0\n")
                continue
            os.environ["MUTANT_UNDER_TEST"] = name
            start = time.perf_counter()
            _timed_out.clear()
            # An endless loop; generous, for kernels that compile the first time they are used.
            signal.alarm(int(3 * sum(duration.get(t, 1.0) for t in tests)) + 300)
            try:
                status = pytest.main(["-x", *PYTEST, *tests])
            except _Timeout:
                status = "timeout"
            finally:
                signal.alarm(0)
                os.environ["MUTANT_UNDER_TEST"] = ""
            if status == pytest.ExitCode.INTERRUPTED:
                raise KeyboardInterrupt  # Ctrl-C: this mutant is not done
            if _timed_out:
                status = "timeout"
            verdict = {pytest.ExitCode.OK: "survived", pytest.ExitCode.TESTS_FAILED: "killed", "timeout": "timeout"}
            # any other status (a test not found, no test collected) is no verdict: say so
            out.write(f"{name} {verdict.get(status, f'error-{status}')} {time.perf_counter() - start:.1f}\n")


if __name__ == "__main__":
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2], sys.argv[3:])
