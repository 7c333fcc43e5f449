"""The memory a simulation needs, checked before anything is made (`check_memory`)."""
from __future__ import annotations

from .backend import available_memory, current_arch
from .schemes import STEPPERS

#: Bytes per circle of the arrays a simulation holds on a CPU, by scheme and precision: the
#: least memory a scene needs, before the temporary arrays of its placement (counted by
#: tests/test_memory.py), from each scheme's stepper. An event queue split into parts holds
#: PART_BYTES a circle more.
ARRAY_BYTES = {(scheme, precision): per for scheme, stepper in STEPPERS.items()
               for precision, per in stepper.ARRAY_BYTES.items()}
PART_BYTES = STEPPERS["event"].PART_BYTES


def bytes_per_circle(n, scheme, precision):
    """ARRAY_BYTES of a CPU simulation of n circles, with PART_BYTES when its scheme will split
    its steps into parts (`Stepper.bytes_per_circle`)."""
    return STEPPERS[scheme].bytes_per_circle(n, precision)


#: Bytes of the event log per collision it can keep (a float64 time and two int32 ids), and the
#: most collisions it can keep (Taichi's arrays count their items in 32 bits).
LOG_BYTES = 16
MOST_RECORDED = 2 ** 31 - 1


class NotEnoughMemory(MemoryError, ValueError):
    """A scene whose arrays would not fit in the memory available (`check_memory`)."""


def check_memory(n: int, scheme: str, precision: str, available=None, record_events=0):
    """Refuse, before anything is made, a CPU simulation of n circles whose arrays alone
    (`bytes_per_circle`, and LOG_BYTES for each collision its event log can keep) need more than the
    memory available (`available_memory`, or `available` bytes when given): it would otherwise
    be killed part way, or swap for hours. A GPU holds the arrays in its own memory, which
    Taichi reserves at start; it is not checked here."""
    if current_arch() != "cpu" or (scheme, precision) not in ARRAY_BYTES:
        return  # (an unknown scheme is refused where it is read)
    per = bytes_per_circle(n, scheme, precision)
    available = available_memory() if available is None else available
    if available is None:
        return
    need = n * per
    log = record_events * LOG_BYTES
    if need + log > available and log > 0:
        raise NotEnoughMemory(
            f"record_events = {record_events} keeps a log of {log / 1e9:.3g} GB ({LOG_BYTES} bytes a collision), "
            f"which with the {need / 1e9:.3g} GB of the circles' arrays is more than the {available / 1e9:.3g} "
            f"GB of memory available: keep at most {max(available - need, 0) // LOG_BYTES} collisions")
    if need > available:
        fix = f"at most {available // per} circles"
        if precision == "f64":
            fix += f" (in f32, {available // bytes_per_circle(n, scheme, 'f32')})"
        who = "circle needs" if n == 1 else "circles need"
        raise NotEnoughMemory(
            f"n = {n} {who} at least {need / 1e9:.3g} GB for their arrays ({per} bytes a circle with the "
            f"{scheme} scheme in {precision}), more than the {available / 1e9:.3g} GB of memory available: "
            f"simulate {fix}, or use a machine with more memory")
