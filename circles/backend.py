"""Taichi runtime set-up: `circles.init` wraps `ti.init`; nothing here runs at import."""
from __future__ import annotations

import contextlib
import difflib
import io
import math
from pathlib import Path

import taichi as ti

ARCHES = ("auto", "cpu", "gpu")

_state = {"initialized": False, "arch": None, "runtime": 0, "optimization_given": False}
#: Callables run before `init` restarts the runtime, to let go of the arrays the running one
#: made (`on_restart`).
_restart_hooks = []
#: Callables run when `compile_for` changes how kernels compile: each drops the compiled
#: kernels it holds (`on_recompile`).
_recompile_hooks = []

#: From this many circles up, kernels on a CPU compile with Taichi's CFG optimisation pass;
#: below, without it. The pass takes most of a kernel's compile time and gives the same bits;
#: below this size the kernels it makes run no faster, at a million circles they run faster
#: (the Performance page gives the measurements).
OPTIMIZE_FROM_N = 100_000


def on_restart(hook):
    """Run `hook()` before each restart of the runtime by `init`: it drops every Taichi array it
    holds. Arrays that outlive the runtime that made them crash later kernels of the next one
    (seen with Taichi 1.7 on a CPU: a step after the restart ends the process), so none may."""
    _restart_hooks.append(hook)
    return hook


def on_recompile(hook):
    """Run `hook()` whenever `compile_for` switches Taichi's CFG optimisation: it drops every
    compiled kernel it holds, so that none compiled one way serves a scene meant for the other."""
    _recompile_hooks.append(hook)
    return hook


def init(arch: str = "auto", **options) -> str:
    """Start the Taichi runtime on `arch` ("cpu", "gpu" or "auto") and return the arch in use.

    `options` go to `ti.init` unchanged (for example `cpu_max_num_threads=1`). Without
    `cfg_optimization` among them, each Simulation on a CPU chooses it by its size
    (`compile_for`).
    "gpu" fails with a clear error when no GPU backend can start; "auto" takes a GPU when
    one is present and the CPU otherwise. Calling it again restarts the runtime: every
    Simulation made before lets go of its arrays and raises a RuntimeError when used.
    """
    if arch not in ARCHES:
        raise ValueError(f"arch {arch!r} is unknown: use one of {', '.join(ARCHES)}")
    _check_options(options)
    options.setdefault("log_level", ti.ERROR)
    # No reassociation of floating-point arithmetic: pair arithmetic must round the same way
    # whichever circle of a pair comes first, so results do not depend on memory order.
    options.setdefault("fast_math", False)
    if _state["initialized"]:
        for hook in _restart_hooks:
            hook()
        ti.reset()
    _state["runtime"] += 1  # the arrays of every earlier runtime are gone (`runtime`)
    _state.update(initialized=False, arch=None)  # until ti.init succeeds: the next use starts anew
    # ti.init prints "[Taichi] Starting on arch=..." on stdout; circles' output is its own (the
    # arch is what init returns, and the command line's summary names it).
    with contextlib.redirect_stdout(io.StringIO()):
        if arch == "cpu":
            ti.init(arch=ti.cpu, **options)
        else:
            # Named GPU backends, not ti.gpu: its OpenGL probe can crash a machine without a display.
            ti.init(arch=[ti.cuda, ti.vulkan, ti.metal], **options)
    used = ti.lang.impl.current_cfg().arch
    name = "cpu" if used in (ti.x64, ti.arm64) else "gpu"
    if arch == "gpu" and name == "cpu":
        ti.reset()
        _state["initialized"] = False
        raise RuntimeError("arch 'gpu' asked for, but no GPU backend could start: "
                           "use arch='cpu' or arch='auto' (on the command line, --arch cpu or --arch auto)")
    _state.update(initialized=True, arch=name, optimization_given="cfg_optimization" in options)
    return name


def compile_for(n: int) -> None:
    """Make the kernels compiled from now on suit a scene of n circles: on a CPU, with Taichi's
    CFG optimisation from OPTIMIZE_FROM_N circles up, and without it below (seconds instead of
    tens of seconds to compile, the same results bit for bit). A switch drops every kernel
    compiled the other way; Taichi's offline cache keeps both kinds, keyed by the option. Does
    nothing on a GPU, or when `init` was given `cfg_optimization`."""
    if _state["arch"] != "cpu" or _state["optimization_given"]:
        return
    want = n >= OPTIMIZE_FROM_N
    config = ti.lang.impl.current_cfg()
    if bool(config.cfg_optimization) == want:
        return
    config.cfg_optimization = want
    ti.lang.impl.get_runtime().clear_compiled_functions()
    for hook in _recompile_hooks:
        hook()


#: ti.init's own options besides the fields of its compile configuration (`ti.cfg`).
_INIT_OPTIONS = ("log_level", "gdb_trigger", "short_circuit_operators", "print_full_traceback", "unrolling_limit",
                 "default_fp", "default_ip", "require_version")


_KINDS = {"int": "a whole number", "float": "a number", "bool": "True or False", "str": "a string"}


def _check_options(options):
    """Refuse options that ti.init would refuse, before the runtime is touched: ti.init stops the
    running one first and then fails, and a runtime started after such a failure has crashed
    the process (Taichi 1.7). Names it does not know, and values that its configuration's fields
    do not take (each tried on a configuration of its own, converted as ti.init converts it)."""
    scratch = ti._lib.core.CompileConfig()
    fields = {k for k in dir(scratch) if not k.startswith("_")} - {"arch", "default_up"}
    known = fields | set(_INIT_OPTIONS)
    for name, value in options.items():
        if name not in known:
            close = difflib.get_close_matches(name, sorted(known), n=1)
            hint = f"did you mean {close[0]}? " if close else ""
            raise ValueError(f"circles.init: option {name!r} is not one that ti.init takes: {hint}see ti.init's "
                             "documentation for its options (for example cpu_max_num_threads)")
        if name in fields and name not in ("default_fp", "default_ip"):
            _check_field(scratch, name, value)
        elif name in _TYPE_OPTIONS:
            if not any(value is kind for kind in _TYPE_OPTIONS[name]):
                names = " or ".join(f"ti.{kind}" for kind in _TYPE_OPTIONS[name])
                shown = f"ti.{value}" if isinstance(value, type(ti.f32)) else repr(value)
                raise ValueError(f"circles.init: option {name} = {shown} is not a value ti.init takes: give {names}")
        elif name == "log_level":
            if not (isinstance(value, str) and value.lower() in _LOG_LEVELS):
                raise ValueError(f"circles.init: option log_level = {value!r} is not a value ti.init takes: give one "
                                 f"of {', '.join(map(repr, _LOG_LEVELS))} (ti.ERROR, circles' default, is 'error')")


#: The types ti.init takes for these options, and the levels it takes for log_level.
_TYPE_OPTIONS = {"default_fp": (ti.f16, ti.f32, ti.f64), "default_ip": (ti.i32, ti.i64)}
_LOG_LEVELS = ("trace", "debug", "info", "warn", "error", "critical")


def _int_range(name):
    """The least and largest values of an integer field of the compile configuration (a C int,
    or an unsigned 64-bit one)."""
    probe = ti._lib.core.CompileConfig()
    for lo, hi in ((-2 ** 31, 2 ** 31 - 1), (0, 2 ** 64 - 1)):
        try:
            setattr(probe, name, lo)
            setattr(probe, name, hi)
            return lo, hi
        except TypeError:
            pass
    return 0, 2 ** 31 - 1


def _check_field(scratch, name, value):
    """Refuse a value of a compile configuration field that ti.init would not take, or that it
    takes and then fails on (a thread count below 1 ends the process at the first kernel)."""
    current = getattr(scratch, name)
    convert = type(current)
    try:
        setattr(scratch, name, value if convert is bool else convert(value))
    except (TypeError, ValueError, OverflowError):
        what = _KINDS.get(convert.__name__, convert.__name__)
        if convert is int and isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value):
            lo, hi = _int_range(name)
            what = f"a whole number from {1 if name == 'cpu_max_num_threads' else lo} to {hi}"
        raise ValueError(f"circles.init: option {name} = {value!r} is not a value ti.init takes: give {what}, "
                         f"as its default {current!r} is") from None
    if name == "cpu_max_num_threads" and getattr(scratch, name) < 1:
        raise ValueError(f"circles.init: option cpu_max_num_threads = {value!r} is not a thread count: give 1 or "
                         "more, or leave it out to run on all of the CPU's threads")


def ensure_init() -> str:
    """Initialise with arch="auto" unless `init` was already called."""
    if not _state["initialized"]:
        init("auto")
    return _state["arch"]


def current_arch() -> str | None:
    return _state["arch"]


def runtime() -> int:
    """A number that changes each time `init` starts the runtime: arrays made under another
    number were freed by the restart."""
    return _state["runtime"]


#: Up to this many circles, the loops of a step on a CPU run on one thread: starting a parallel
#: loop on the CPU's thread pool costs tens of microseconds, and the pool's start and the
#: waits between a step's stages cost more than the second thread saves on a small scene. A
#: discrete step on several threads runs as one team (one start of the pool a step,
#: `circles.team`), which overtakes one thread near this size (the Performance page of the
#: docs gives the measurements).
SERIAL_N = 30_000
#: The event scheme's limit, as circles times the CPU's threads: up to it, a step runs on one
#: thread from one queue (`event.queue_step`, each pair's first time computed once) rather
#: than in parts on every thread (`event.queue_parts`). The parts pay for their split, their
#: windows and a dozen launches a step, a few milliseconds, which on two threads the parts
#: win back from about 1.5e5 circles. More threads share that fixed cost among more parts,
#: hence the product.
EVENT_SERIAL_WORK = 200_000
#: With one thread, the event scheme runs its steps in parts from this many circles: the parts
#: run in turn, each a region of the box whose circles' arrays stay in the cache, where one
#: queue takes its events all over arrays larger than the cache (the Performance page).
EVENT_PARTS_ONE_THREAD_N = 500_000


def cpu_threads() -> int:
    """The threads of Taichi's CPU pool (`cpu_max_num_threads`)."""
    return max(int(ti.lang.impl.current_cfg().cpu_max_num_threads), 1)


def serial_loops(n: int, scheme: str = "discrete") -> bool:
    """Whether the per-step loops over n circles of `scheme` run on one thread (see `SERIAL_N`
    and `EVENT_SERIAL_WORK`)."""
    if current_arch() != "cpu":
        return False
    if scheme == "event":
        threads = cpu_threads()
        if threads < 2:
            return n < EVENT_PARTS_ONE_THREAD_N
        return n <= SERIAL_N or n * threads <= EVENT_SERIAL_WORK
    return n <= SERIAL_N


#: Where Linux says how much memory this process may still take: the system's MemAvailable,
#: and the limit and use of a control group (version 2 and version 1), relative to the root.
_MEMINFO = "proc/meminfo"
_CGROUP_LIMITS = (("sys/fs/cgroup/memory.max", "sys/fs/cgroup/memory.current"),
                  ("sys/fs/cgroup/memory/memory.limit_in_bytes", "sys/fs/cgroup/memory/memory.usage_in_bytes"))


def available_memory(root="/") -> int | None:
    """Bytes of memory this process can take now, or None where the system does not say: the
    system's MemAvailable, or less when the process runs in a control group (a container)
    whose limit leaves less (the least of what each says)."""
    root = Path(root)
    available = None
    try:
        for line in (root / _MEMINFO).read_text().splitlines():
            if line.startswith("MemAvailable:"):
                available = int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    for limit_path, usage_path in _CGROUP_LIMITS:
        try:
            limit = int((root / limit_path).read_text().split()[0])  # "max" (no limit) is not a number
            usage = int((root / usage_path).read_text().split()[0])
        except (OSError, ValueError, IndexError):
            continue
        if limit < 1 << 60:  # version 1 writes a number near 2^63 for no limit
            left = max(limit - usage, 0)
            available = left if available is None else min(available, left)
    return available
