"""Ctrl-C during a run takes effect between two steps, never inside one (`whole_steps`)."""
import signal
import threading


class _WholeSteps:
    """Ctrl-C (SIGINT) during `advance` or `step` takes effect between two steps, never inside
    one: a step stopped between its kernels would leave circles moved to different times and
    the simulation's clock behind them.

    Used in the main thread only, where Python runs signal handlers (`whole_steps`). Its first
    use puts this object in place of the SIGINT handler it finds, when that is a Python
    callable (Python's own, which raises KeyboardInterrupt, or a program's): outside steps it
    passes each press straight on; during a step it counts them, and passes them on when the
    step ends. Installed once, as a call of signal.signal costs microseconds (a tenth of a step
    of a few hundred circles): a program that puts in a handler of its own later takes its
    presses itself."""

    def __init__(self):
        self.previous = None  # the handler this one passes presses on to
        self.tried = False
        self.depth = 0  # calls of advance or step under way
        self.presses = 0

    def __call__(self, signum, frame):
        if self.depth > 0:
            self.presses += 1
        else:
            self.previous(signum, frame)

    def __enter__(self):
        if not self.tried:
            self.tried = True
            previous = signal.getsignal(signal.SIGINT)
            if callable(previous):
                self.previous = previous
                signal.signal(signal.SIGINT, self)
        self.depth += 1
        return self

    def between_steps(self):
        """Pass on the presses held during the step that just ended; once one raises (Python's
        handler does), the others go with it."""
        while self.presses > 0:
            self.presses -= 1
            try:
                self.previous(signal.SIGINT, None)
            except BaseException:
                self.presses = 0
                raise

    def __exit__(self, exc_type, exc, tb):
        self.depth -= 1
        if self.depth == 0:
            if exc_type is None:
                self.between_steps()
            else:
                self.presses = 0  # the call is ending with an exception already
        return False


class _AnyThread:
    """In place of `_WholeSteps` outside the main thread, whose steps a press never interrupts
    (Python raises KeyboardInterrupt in the main thread only)."""

    def __enter__(self):
        return self

    def between_steps(self):
        pass

    def __exit__(self, *exc_info):
        return False


_WHOLE_STEPS = _WholeSteps()
_ANY_THREAD = _AnyThread()


def whole_steps():
    """The guard of a call of `advance` or `step` (`_WholeSteps`) in this thread."""
    return _WHOLE_STEPS if threading.current_thread() is threading.main_thread() else _ANY_THREAD
