"""The schemes by name, each a stepper class (see `circles.stepper`), and the step each chooses."""
import numpy as np

from .discrete.stepper import DiscreteStepper
from .event.stepper import EventStepper
from .scene import MAX_DT

#: The stepper of each scheme that `Scene(scheme=...)` names.
STEPPERS = {"event": EventStepper, "discrete": DiscreteStepper}


def default_dt(scheme, radius, vel):
    """The step the scheme's stepper chooses for circles of these radii and velocities (1 when
    none moves)."""
    vmax = float(np.hypot(vel[:, 0], vel[:, 1]).max()) if len(vel) else 0.0
    if vmax <= 0:
        return 1.0
    dt = STEPPERS[scheme].default_dt(radius, vmax)
    if not (0 < dt <= MAX_DT):
        raise ValueError(f"the largest speed {vmax:g} and the radii (mean {float(radius.mean()):g}) give a step "
                         f"dt = {dt:g}, beyond the steps from 0 to {MAX_DT:g} that a run takes: give dt, or measure "
                         "lengths and times in other units")
    return dt
