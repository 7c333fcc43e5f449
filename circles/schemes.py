"""The schemes by name, each a stepper class (see `circles.stepper`)."""
from .discrete.stepper import DiscreteStepper
from .event.stepper import EventStepper

#: The stepper of each scheme that `Scene(scheme=...)` names.
STEPPERS = {"event": EventStepper, "discrete": DiscreteStepper}
