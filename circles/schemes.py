"""The schemes by name, each a stepper class (see `circles.stepper`), and the step each chooses."""
import numpy as np

from .discrete.stepper import DiscreteStepper
from .event.stepper import EventStepper
from .scene import MAX_DT
from .theory import enskog_rate

#: The area fraction at most that the collision rate is estimated at (that of a triangular
#: crystal of equal disks, beyond which Liu's equation of state means nothing).
MOST_AREA_FRACTION = 0.9069
#: The stepper of each scheme that `Scene(scheme=...)` names.
STEPPERS = {"event": EventStepper, "discrete": DiscreteStepper}


def default_dt(scheme, radius, vel, box=None):
    """The step the scheme's stepper chooses for circles of these radii and velocities in a box
    of sides `box` (1 when none moves; None: the collision rate is not taken into account)."""
    vmax = float(np.hypot(vel[:, 0], vel[:, 1]).max()) if len(vel) else 0.0
    if vmax <= 0:
        return 1.0
    rate = collision_rate(radius, vel, box) if box is not None else 0.0
    dt = STEPPERS[scheme].default_dt(radius, vmax, rate)
    if not (0 < dt <= MAX_DT):
        raise ValueError(f"the largest speed {vmax:g} and the radii (mean {float(radius.mean()):g}) give a step "
                         f"dt = {dt:g}, beyond the steps from 0 to {MAX_DT:g} that a run takes: give dt, or measure "
                         "lengths and times in other units")
    return dt


def collision_rate(radius, vel, box):
    """Collisions a circle takes part in per unit time, by Enskog's frequency for equal disks of
    the mean radius at the circles' area fraction and mean kinetic energy per unit mass (an
    estimate that sets the step, not a measurement: see `theory.enskog_rate`)."""
    n = len(radius)
    area = float(box[0]) * float(box[1])
    if n == 0 or not area > 0:
        return 0.0
    eta = min(float(np.pi * np.sum(np.square(radius))) / area, MOST_AREA_FRACTION)
    # kT / m per degree of freedom: half the mean square speed in two dimensions.
    kt = 0.5 * float(np.mean(np.sum(np.square(vel), axis=1)))
    return enskog_rate(eta, n / area, 2.0 * float(radius.mean()), kt, 1.0)
