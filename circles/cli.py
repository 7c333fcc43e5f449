"""Command line: ``circles run [SCENE.toml] [flags]`` simulates a scene and writes its frames.

A scene comes from a TOML file (the Scene fields at top level, and a ``[run]`` table with
``duration``, ``fps``, ``size``, ``color``, ``out``, ``arch`` and ``threads``), from flags, or from both:
flags override the file. Without a file the scene is the showcase below, which flags
change in the same way; ``circles`` with no arguments at all runs the showcase.

A file may instead list its circles one by one (``[[circle]]`` tables, see
`circles.scenefile`); it is simulated with ``Simulation.from_arrays``. Then --box,
--boundary, --scheme, --precision, --dt and --mass (the model for circles without a mass)
still override the file, and --n, --radius, --speed and --seed are refused.

Frames are taken every 1/fps of simulated time, starting with the state at t = 0, so a run
of ``duration`` seconds gives ``ceil(duration * fps)`` frames showing t = 0, 1/fps, ...,
each shown for 1/fps, so the video lasts ``duration`` seconds (up to the next whole frame,
``ceil(duration * fps) / fps``) and shows the same motion on every machine. The
simulation runs the whole ``duration``; the state at the end is summarised, not drawn. A run
makes at most MOST_FRAMES frames and MOST_STEPS steps (refused before any simulating beyond
those).

Exit status: 0 done; 2 bad input (one line on stderr, before any simulating); 1 the run
failed (one line on stderr; the frames written so far are kept readable, except in an MP4
that ffmpeg itself could not finish, which is removed); 130 stopped by Ctrl-C, with the
frames made so far written and playable. A first Ctrl-C stops after the current frame, a
second at once; neither cuts short the writing of a frame or the finishing of the file.
"""

import array
import contextlib
import importlib
import math
import os
import re
import signal
import statistics
import sys
import time

DEFAULT_OUT = "outputs/circles.mp4"
# The showcase run, made when no scene file is given: 1500 circles of a range of sizes
# (area fraction 0.11), mass by radius, in a 16:9 box with walls, exact collisions; 5 s at
# 30 frames per second, about 15 000 collisions: well under a minute on a 2-core CPU.
RUN_DEFAULTS = {
    "duration": 5.0,
    "fps": 30.0,
    "size": "1280x720",
    "color": "random",
    "out": DEFAULT_OUT,
    "arch": "auto",
    "threads": 0,  # CPU threads: 0 takes all of them
}
from .sceneflags import (FRAME_KEYS, RANDOM_SCENE_FLAGS, SHOWCASE_SCENE, add_scene_flags, circle_count,  # noqa: F401
                         frame_source, random_scene, scene_defaults_text, scene_from_frame, scene_overrides,
                         read_scene_file, sized_scene_fields, species_entry)
from .command import EXIT_BAD_INPUT, EXIT_FAILED, EXIT_INTERRUPTED, Parser, UsageError, remove_made


def version_text():
    """This package's version and those of what it runs on, as `circles --version` prints them."""
    import platform
    from importlib import metadata

    from . import __version__

    def of(name):
        try:
            return metadata.version(name)
        except metadata.PackageNotFoundError:
            return "not installed"

    return (f"circles {__version__} (taichi {of('taichi')}, numpy {of('numpy')}, "
            f"python {platform.python_version()})")


def _build_parser():
    parser = Parser(prog="circles", description="Simulate many elastic circles in a box "
                     "and write the run as a video, a GIF or PNG frames.")
    parser.add_argument("--version", action="version", version=version_text())
    commands = parser.add_subparsers(dest="command", metavar="run | plot | sweep | compress")
    run = commands.add_parser(
        "run", help="simulate a scene and write its frames",
        description="Simulate a scene (the showcase, or SCENE.toml) and write its frames. "
                    "Flags override the scene file.")
    run.add_argument("scene", nargs="?", metavar="SCENE.toml",
                     help="scene file: Scene fields (or [[circle]] tables listing the "
                          "circles) at top level, a [run] table for the run options")
    add_scene_flags(run)
    run.add_argument("--from", dest="from_", metavar="FILE.gsd[:FRAME]",
                     help="start from a frame of a GSD file (the last by default): one circles wrote, or HOOMD-blue's "
                          "(circles.frames); --speed and --seed then draw the speeds a HOOMD file lacks")
    output = run.add_argument_group("run")
    output.add_argument("--duration", type=float, metavar="T",
                        help=f"simulated seconds (default {RUN_DEFAULTS['duration']:g})")
    output.add_argument("--fps", type=float, metavar="F",
                        help=f"frames per simulated second (default {RUN_DEFAULTS['fps']:g})")
    output.add_argument("--size", metavar="WxH",
                        help=f"image size in pixels (default {RUN_DEFAULTS['size']})")
    output.add_argument("--color", choices=("random", "speed", "hexatic"),
                        help="each circle's own colour, a colormap of its speed, or the orientation of its "
                             "hexatic order psi_6 (circles.order)")
    output.add_argument("--arch", choices=("auto", "cpu", "gpu"), help="where to run")
    output.add_argument("--threads", type=int, metavar="N",
                        help="CPU threads to run on (default 0: all of them; the state does not "
                             "depend on it)")
    output.add_argument("--out", metavar="PATH",
                        help=f"*.mp4, *.gif, a folder for PNG frames, or none to draw no frames "
                             f"(default {DEFAULT_OUT})")
    data = run.add_argument_group("data", "Observables and trajectories (see circles.writers)")
    data.add_argument("--stats", metavar="RUN.csv", help="a CSV row of observables per frame interval")
    data.add_argument("--trajectory", metavar="RUN.gsd",
                      help="a GSD frame (HOOMD-blue's schema) at each frame's instant")
    data.add_argument("--order", action="store_true",
                      help="also measure the hexatic order: a hexatic_order column in --stats, and each circle's "
                           "psi_6 in --trajectory (circles.order)")
    data.add_argument("--force", action="store_true", help="overwrite existing --stats and --trajectory files")
    data.add_argument("--checkpoint-every", type=float, metavar="T",
                      help="keep a full-precision restart point of the run (RUN.checkpoint.gsd beside --trajectory, "
                           "or else --stats) at the first frame after each T simulated seconds, at a stop and at the "
                           "end (circles.checkpoint)")
    data.add_argument("--resume", action="store_true",
                      help="continue the run whose --stats and --trajectory files these are, from its last frame "
                           "or checkpoint: the same bits as a run never stopped")
    from .plot import add_parser as add_plot_parser
    from .compress import add_compress_command
    from .sweep import add_sweep_command
    add_plot_parser(commands)
    add_sweep_command(commands)
    add_compress_command(commands)
    return parser


def _parse_size(size):
    if isinstance(size, list) and len(size) == 2:
        width, height = size
    else:
        match = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", str(size))
        if not match:
            raise UsageError(f"size {size!r} is not WxH, e.g. 1280x720")
        width, height = int(match[1]), int(match[2])
    from .canvas import MAX_IMAGE_SIDE
    for value in (width, height):
        if isinstance(value, bool) or not isinstance(value, int) \
                or not 1 <= value <= MAX_IMAGE_SIDE:
            raise UsageError(f"size {size!r}: width and height must be whole numbers of "
                             f"pixels from 1 to {MAX_IMAGE_SIDE}")
    return width, height


def _positive(name, value):
    if isinstance(value, bool) or not isinstance(value, (int, float)) \
            or not math.isfinite(value) or value <= 0:
        raise UsageError(f"{name} {value!r} must be a positive number")
    return float(value)


def _run_options(file_run, args):
    """The run's options: flags over the scene file's [run] table over RUN_DEFAULTS. A value
    from the file that is refused is named with the file."""
    options = {**RUN_DEFAULTS, **file_run}
    from_file = set()
    for key in RUN_DEFAULTS:
        value = getattr(args, key)
        if value is not None:
            options[key] = value
        elif key in file_run:
            from_file.add(key)
    try:
        return _checked_run_options(options)
    except UsageError as error:
        if str(error).split(" ", 1)[0].lstrip("-") in from_file:  # the messages start with the key
            raise UsageError(f"{args.scene}: [run] {error}") from None
        raise


def _checked_run_options(options):
    from .backend import ARCHES
    from .canvas import COLOR_MODES
    options["duration"] = _positive("duration", options["duration"])
    options["fps"] = _positive("fps", options["fps"])
    check_frame_count(options["duration"], options["fps"])
    options["size"] = _parse_size(options["size"])
    for key, allowed in (("color", COLOR_MODES), ("arch", ARCHES)):
        if options[key] not in allowed:
            raise UsageError(f"{key} {options[key]!r} is unknown: use one of "
                             f"{', '.join(allowed)}")
    threads = options["threads"]
    if isinstance(threads, bool) or not isinstance(threads, int) or threads < 0:
        raise UsageError(f"threads {threads!r} must be a whole number >= 0 (0 takes all the CPU's threads)")
    available = os.cpu_count() or 1
    if threads > available:
        raise UsageError(f"threads {threads} is more than this machine's {available} CPU threads: "
                         f"give at most {available}, or 0 for all of them")
    if not isinstance(options["out"], str) or not options["out"]:
        raise UsageError(f"out {options['out']!r} must be a path")
    return options


#: Frames a run may make at most: about 9 hours of video at 30 frames per second. More is
#: a mistyped duration or fps, and would fill the disk (or, as a GIF, never finish).
MOST_FRAMES = 1_000_000


#: Steps a run may take at most: over a day at 10 microseconds a step, the least a step costs
#: on a CPU. More is a mistyped --dt (or speeds far beyond the radii), and would never end.
MOST_STEPS = 10 ** 10


def check_step_count(duration, dt):
    """Refuse a run of more than MOST_STEPS steps of dt (the scene's, once it is made)."""
    steps = duration / dt
    if steps > MOST_STEPS:
        raise UsageError(f"duration {duration:g} s in steps of dt = {dt:.3g} s makes {steps:.3g} steps, more than "
                         f"the {MOST_STEPS:.0e} a run may take: give a longer --dt, or a shorter --duration (the "
                         "default dt comes from the radii over the largest speed)")


def frame_count(duration, fps):
    """How many frames a run makes: one at each k / fps with k / fps < duration (a last,
    partial interval gets one), at least one."""
    return max(math.ceil(duration * fps - 1e-9), 1)


def check_frame_count(duration, fps):
    """The frame count (`frame_count`), or a UsageError when it exceeds MOST_FRAMES."""
    frames = duration * fps  # both are finite and positive (`_positive`); the product may be inf
    if frames > MOST_FRAMES:
        count = f"{frames:.3g} frames" if math.isfinite(frames) else "more frames than a float holds"
        raise UsageError(f"duration {duration:g} s at {fps:g} fps makes {count}, more than "
                         f"the {MOST_FRAMES} a run may make: shorten --duration or lower --fps, so that "
                         f"duration times fps is at most {MOST_FRAMES}")
    return frame_count(duration, fps)


#: Flags that shape a random scene only: refused with a file that lists its circles.
def _longest_dt(scene):
    """The longest step the scene can take, known before it is placed: its dt, the default dt of
    the circles a file lists, or for a random scene the default dt as if every circle had the
    largest radius and the fastest the least speed (None when a speed may be 0). The run's own
    dt is then checked again (`check_step_count`)."""
    import numpy as np

    from .schemes import STEPPERS, default_dt

    if scene.dt is not None:
        return scene.dt
    if not hasattr(scene, "speed"):  # a CircleList
        return default_dt(scene.scheme, scene.radius, scene.vel)
    slowest = scene.speed[0]
    return STEPPERS[scene.scheme].default_dt(np.array([scene.radius[1]]), slowest) if slowest > 0 else None


def _circle_list(path, fields, args):
    """The circles of a scene file with [[circle]] entries, flags applied and checked."""
    from .scenefile import circle_list_from_dict

    for key in RANDOM_SCENE_FLAGS:
        if getattr(args, key) is not None:
            raise UsageError(f"argument --{key.replace('_', '-')} does not apply to {path}: it lists its circles "
                             "([[circle]] entries), and --n, --radius, --speed, --seed, --area-fraction, --crystal, --start and "
                             "--species only "
                             "shape random scenes: drop the flag or edit the file")
    try:
        return circle_list_from_dict({**fields, **scene_overrides(args)})
    except (ValueError, TypeError) as error:
        raise UsageError(f"{path}: {error}") from None


def _check_resume_flags(args):
    """Refuse --resume and --checkpoint-every where they cannot work, before anything else."""
    if args.checkpoint_every is not None:
        _positive("--checkpoint-every", args.checkpoint_every)
    if args.checkpoint_every is not None and args.stats is None and args.trajectory is None:
        raise UsageError("--checkpoint-every keeps a restart point of a run's --stats and --trajectory files: give "
                         "one of them")
    if not args.resume:
        return
    if args.force:
        raise UsageError("--resume continues the files of a run, and --force would overwrite them: give one of "
                         "the two")
    if args.stats is None and args.trajectory is None:
        raise UsageError("--resume continues a run's --stats and --trajectory files: give those the run wrote")
    if args.out is not None and args.out.lower() != "none":
        raise UsageError(f"--resume continues --stats and --trajectory, and a video cannot be continued: drop "
                         f"--out {args.out}, or give --out none")


def _checkpoint_path(options, args):
    """The run's checkpoint (`checkpoint.path_beside` its trajectory, else its stats table), or
    None for a run without data files. A new run refuses one left by an earlier run unless
    --force, which has it removed when the run starts."""
    from . import checkpoint

    data = options["trajectory"] or options["stats"]
    if data is None:
        return None
    path = checkpoint.path_beside(data)
    if path.exists() and not args.resume and not args.force:
        raise UsageError(f"{path} exists, a checkpoint of an earlier run: give --resume to continue that run, or "
                         "--force to start again")
    return path


def _prepare(argv, made):
    """Everything that can fail on bad input, before any simulating: (scene, options).

    The scene is a `Scene`, or a `CircleList` for a file that lists its circles. The folders
    made for the output are listed in `made`.
    """
    parser = _build_parser()
    if not argv:
        argv = ["run"]
    args = parser.parse_args(argv)
    if args.command is None:
        raise UsageError("give a command: circles run [SCENE.toml] [flags] "
                         "(see circles run --help)")
    from .scenefile import lists_circles
    from .video import check_writable

    fields, file_run = (read_scene_file(args.scene, RUN_DEFAULTS) if args.scene
                        else (dict(SHOWCASE_SCENE), {}))
    source = frame_source(args, fields)
    if source is not None:
        scene = scene_from_frame(source, fields if args.scene else {}, args)
    elif args.scene and lists_circles(fields):
        scene = _circle_list(args.scene, fields, args)
    else:
        scene = random_scene(fields, args)
    options = _run_options(file_run, args)
    try:
        longest = _longest_dt(scene)
    except ValueError as error:
        raise UsageError(f"{args.scene}: {error}") from None
    if longest is not None:
        check_step_count(options["duration"], longest)
    _check_resume_flags(args)
    from .trajectory import check_path
    try:
        for key, suffix in (("stats", ".csv"), ("trajectory", ".gsd")):
            path = getattr(args, key)
            options[key] = None if path is None else check_path(path, args.force or args.resume, suffix, f"--{key}",
                                                                made)
            if args.resume and path is not None and not options[key].is_file():
                raise UsageError(f"--resume: --{key} {path} does not exist, so there is no run to continue: drop "
                                 "--resume to start the run")
        options["force"] = args.force
        options["resume"] = args.resume
        options["checkpoint_every"] = args.checkpoint_every
        options["checkpoint"] = _checkpoint_path(options, args)
        options["order"] = args.order
        if args.order and options["stats"] is None and options["trajectory"] is None:
            raise UsageError("--order measures the hexatic order into --stats and --trajectory: give one of them")
        if args.order and scene.n <= 6:
            raise UsageError(f"--order with {scene.n} circles: the hexatic order of a circle takes its 6 nearest "
                             "neighbours, so it needs at least 7 circles")
        if args.resume and args.out is None and str(options["out"]).lower() != "none":
            # The video of a scene file's [run] table, or the default one: a resumed run writes none.
            options["out"] = "none"
            options["video_left"] = True
        if str(options["out"]).lower() == "none":
            options["out"] = None
        else:
            options["out"] = check_writable(options["out"], options["fps"], options["size"], made)
    except ValueError as error:
        raise UsageError(str(error)) from None
    from . import resume
    from .writers import frame_times

    options["identity"] = resume.identity(scene, options["fps"], options["order"])
    options["restart"] = None
    if args.resume:
        options["restart"] = resume.restart_point(options["trajectory"], options["checkpoint"], options["identity"])
        if options["restart"] is not None:
            resume.check_schedule(options["restart"], frame_times(options["duration"], options["fps"]), options["fps"])
    return scene, options


class _StopRequest:
    """The run's SIGINT handler. The first Ctrl-C asks to stop after the current frame; a
    second stops at once, but only inside `interruptible()` (drawing a frame, simulating
    to the next): elsewhere, as while a frame is written, the run stops at its next check,
    so that every frame written is whole. From `finishing()` on (the file is finished, the
    summary made), Ctrl-C waits, so that the file plays and the summary tells what it holds."""

    def __init__(self):
        self.requested = False
        self._interruptible = False
        self._finishing = None
        self._told = False

    @contextlib.contextmanager
    def interruptible(self):
        self._interruptible = True
        try:
            yield
        finally:
            self._interruptible = False

    def finishing(self, path):
        self._finishing = path

    def __call__(self, signum, frame):
        if self._finishing is not None:
            if not self._told:
                self._told = True
                sys.stderr.write(f"\nfinishing {self._finishing}: a moment (stopping now "
                                 f"would leave a file that does not play)\n")
        elif not self.requested:
            self.requested = True
            sys.stderr.write("\nstopping after this frame (Ctrl-C again to stop at once)\n")
        elif self._interruptible:
            raise KeyboardInterrupt
        else:
            sys.stderr.write("\nstopping once this frame is written\n")


def _simulation(scene):
    """A Simulation of a `Scene` (random placement) or of a `CircleList` (given circles)."""
    import circles

    if isinstance(scene, circles.Scene):
        return circles.Simulation(scene)
    return circles.Simulation.from_arrays(
        scene.pos, scene.vel, scene.radius, mass=scene.mass, box=scene.box,
        boundary=scene.boundary, scheme=scene.scheme, precision=scene.precision, dt=scene.dt,
        color=scene.color)


class _Video:
    """The video's writer of a run (`writers.Run`): each frame drawn, then written whole."""

    wants_row = False

    def __init__(self, options, frames, clock, stop):
        from .video import FrameWriter

        self.options, self.clock, self.stop = options, clock, stop
        self.speed_scale = None
        self.writer = FrameWriter(options["out"], options["fps"], frames)
        self.path = self.writer.path

    def write(self, sim, row, stats):
        from . import canvas

        tick = time.perf_counter()
        with self.stop.interruptible():
            if self.speed_scale is None:
                # Fixed for the whole run, so that a colour means one speed in every frame.
                self.speed_scale = canvas.speed_scale_of(sim.state().vel)
            frame = sim.render(*self.options["size"], self.options["color"], speed_scale=self.speed_scale)
        self.clock["render"] += time.perf_counter() - tick
        tick = time.perf_counter()
        self.writer.write(frame)  # not interruptible: a frame is written whole
        self.clock["write"] += time.perf_counter() - tick

    def close(self):
        tick = time.perf_counter()
        self.writer.close()  # the encoder finishes the frames it still holds
        self.clock["write"] += time.perf_counter() - tick


def _run(scene, options):
    from tqdm import tqdm

    import circles
    from .trajectory import GSDWriter
    from .writers import Run, StatsWriter

    started = time.perf_counter()
    frames = frame_count(options["duration"], options["fps"])
    identity = options["identity"]
    point = options.get("restart")
    try:
        threads = options["threads"]
        arch = circles.init(options["arch"], **({"cpu_max_num_threads": threads} if threads else {}))
        # Placement can still refuse a scene that passed the checks of Scene, and
        # from_arrays checks what a CircleList leaves to it (such as the area fraction).
        sim = _simulation(scene) if point is None else point.simulation()
        check_step_count(options["duration"], sim.dt)
    except (ValueError, RuntimeError) as error:
        raise UsageError(str(error)) from None
    if options.get("video_left"):
        print("circles: --resume continues the data files; the run's video is not continued (--out none)",
              file=sys.stderr)
    first = point.frame if point is not None else 0
    if point is not None:
        print(f"circles: continuing from frame {first} (t = {sim.time:.6g} s) of {point.source}", file=sys.stderr)
    elif options.get("resume"):
        print("circles: the files hold no restart point yet (no trajectory frame, no checkpoint): the run starts "
              "again from the beginning, and gives the same rows", file=sys.stderr)
    run_start = point.start if point is not None else sim.time
    setup_s = time.perf_counter() - started
    clock = {"simulate": 0.0, "render": 0.0, "write": 0.0}
    speeds = Speeds(sim.n)
    stop = _StopRequest()
    previous_handler = signal.signal(signal.SIGINT, stop)
    outputs = []  # what the run writes, each closed at the end
    try:
        # A resumed run stopped before its first frame starts again: its files are written anew.
        mode = "w" if options.get("force") or options.get("resume") else "x"
        if point is not None:
            mode = "a"
        elif options["checkpoint"] is not None and options.get("force"):
            options["checkpoint"].unlink(missing_ok=True)  # an earlier run's
        if options["out"] is not None:
            outputs.append(_Video(options, frames, clock, stop))
        if options["trajectory"] is not None:
            tracker = getattr(sim, "image_tracker", None) if point is not None else None
            outputs.append(GSDWriter(options["trajectory"], mode, tracker=tracker, order=options["order"],
                                     run={"run": identity, "start": run_start}))
        table = None
        if options["stats"] is not None:
            # Continued (keep=) after the rows written by the restart point; else a new table.
            table = StatsWriter(options["stats"], mode, order=options["order"],
                                keep=first if point is not None else None)
        tick = time.perf_counter()
        measuring = options["trajectory"] is not None or table is not None
        run = Run(sim, options["duration"], options["fps"], at_frame=outputs,
                  at_interval=[table] if table else [], need_stats=measuring,
                  order=options["order"] and table is not None, start=run_start,
                  row=point.row if point is not None and point.refire else None)
        saver = _Checkpoints(options, run, identity, run_start, outputs)
        start_stats = run.before if measuring else sim.stats()
        stats_s = time.perf_counter() - tick
        if table:
            outputs.append(table)
        bar = tqdm(total=frames, initial=first, unit="frame", file=sys.stderr, disable=None,
                   dynamic_ncols=True, desc="circles")
        completed = first == frames  # the whole duration simulated, every frame written
        failure = None
        at_instant = None  # the frame instant the state is at, between two intervals
        try:
            for k in range(first, frames):
                at_instant = k
                if k > first or point is None or point.refire:
                    if k > first:
                        saver.maybe(k)
                    run.fire_frame()  # a frame is drawn interruptibly, written whole
                if stop.requested:
                    break
                at_instant = None
                tick = time.perf_counter()
                steps_before = sim.steps
                with stop.interruptible():
                    run.advance(k)
                seconds = time.perf_counter() - tick
                clock["simulate"] += seconds
                speeds.add(sim.steps - steps_before, seconds)
                run.fire_interval()  # not interruptible: a row is written whole
                at_instant = k + 1
                completed = k + 1 == frames
                bar.update(1)
                rate = speeds.recent()
                bar.set_postfix_str(f"t={sim.time:.2f}/{options['duration']:g} s, "
                                    f"{rate:.3g} circle-steps/s", refresh=False)
                if stop.requested:
                    break
        except KeyboardInterrupt:
            pass  # a second Ctrl-C, while drawing or simulating: every frame written is whole
        except Exception as error:  # raised once the files are finished
            failure = error
        stop.finishing(", ".join(str(output.path) for output in outputs) or "the run")
        if failure is None and at_instant is not None:
            saver.at_stop(at_instant)  # where a stop or the end leaves the run
        bar.close()
        for output in outputs:
            try:
                output.close()
            except OSError as error:
                if failure is None:
                    raise
                raise OSError(f"{failure}; then {error}") from failure
        if failure is not None:
            raise failure
        tick = time.perf_counter()
        stats = sim.stats()
        stats_s += time.perf_counter() - tick + run.stats_seconds
        wall_s = time.perf_counter() - started
        _summary(sim, arch, start_stats, stats, outputs, clock, speeds, setup_s, stats_s, wall_s,
                 not completed, saver)
    finally:
        signal.signal(signal.SIGINT, previous_handler)
    return 0 if completed else EXIT_INTERRUPTED


class _Checkpoints:
    """A run's restart points (`circles.checkpoint`) with --checkpoint-every T: at the first
    frame instant T or more after the last one, before that frame's writers; at a stop between
    two intervals; at the end."""

    def __init__(self, options, run, identity, start, outputs):
        from .trajectory import GSDWriter

        self.path = options["checkpoint"]
        self.every = options["checkpoint_every"]
        self.run, self.sim, self.identity, self.start = run, run.sim, identity, start
        self.last = self.sim.time
        writers = [output for output in outputs if isinstance(output, GSDWriter)]
        self.writer = writers[0] if writers else None
        self.seconds = 0.0

    def maybe(self, frame):
        if self.every is not None and self.sim.time - self.last >= self.every:
            self.write(frame)

    def at_stop(self, frame):
        if self.every is not None and self.sim.time != self.last:
            self.write(frame)

    def write(self, frame):
        from . import checkpoint

        tick = time.perf_counter()
        # With a trajectory its image flags go along, for the frame a restart writes first.
        tracker = self.writer.tracker if self.writer is not None else None
        # The row of the interval that ended here, which this frame's writers get first.
        progress = {"run": self.identity, "frame": frame, "start": self.start, "row": self.run.row}
        checkpoint.write(self.path, self.sim, progress, tracker=tracker or None)
        self.last = self.sim.time
        self.seconds += time.perf_counter() - tick


#: Frames of a run, at least, whose median speed the summary reports (`Speeds.summary`).
MEDIAN_FRAMES = 5
#: Frames whose median speed the progress bar shows.
RECENT_FRAMES = 9


class Speeds:
    """The simulation's speed in circle-steps per second, frame by frame. The frames whose
    simulation runs a kernel for the first time in the process pay for its translation (a second
    or so) and, with an empty cache, its compilation, which would hide the speed of a short run:
    so the summary gives the median of the frames' speeds (`summary`), the progress bar that of
    the last RECENT_FRAMES (`recent`)."""

    def __init__(self, n):
        self.n = n
        self.rates = array.array("d")  # of the frames that took steps: 8 bytes a frame
        self.steps = 0
        self.seconds = 0.0

    def add(self, steps, seconds):
        """A frame's simulation: its steps and their seconds."""
        self.steps += steps
        self.seconds += seconds
        if steps > 0 and seconds > 0:
            rate = self.n * steps / seconds
            self.rates.append(rate)

    def recent(self):
        """The median speed of the last RECENT_FRAMES frames that took steps (0 before any)."""
        return statistics.median(self.rates[-RECENT_FRAMES:]) if self.rates else 0.0

    def summary(self):
        """(speed, what it covers): with MEDIAN_FRAMES frames that took steps, or more, the
        median of their speeds; with fewer, all the steps over all the time."""
        if len(self.rates) >= MEDIAN_FRAMES:
            return statistics.median(self.rates), f"median of {len(self.rates)} frames' simulation"
        rate = self.n * self.steps / self.seconds if self.seconds > 0 else 0.0
        return rate, "simulation only, the kernels' first calls included"


def _summary(sim, arch, start_stats, stats, outputs, clock, speeds, setup_s, stats_s, wall_s,
             interrupted, saver=None):
    from .trajectory import GSDWriter
    from .video import frames_text
    from .writers import StatsWriter

    energy_0 = start_stats["kinetic_energy"]
    energy_change = (stats["kinetic_energy"] - energy_0) / energy_0 if energy_0 > 0 else 0.0
    rate, covers = speeds.summary()
    if arch == "cpu":
        from .backend import cpu_threads
        threads = cpu_threads()
        arch = f"cpu, {threads} thread{'s' if threads > 1 else ''}"
    lines = [
        ("circles", f"{sim.n} ({sim.scheme}, {sim.precision}, {sim.boundary}, {arch})"),
        ("simulated", f"{sim.time:.6g} s in {sim.steps} steps of dt <= {sim.dt:.3g} s"
                      + (" (stopped by Ctrl-C)" if interrupted else "")),
        ("wall time", f"{wall_s:.1f} s: placement {setup_s:.1f}, simulation "
                      f"{clock['simulate']:.1f}, drawing {clock['render']:.1f}, "
                      f"writing {clock['write']:.1f}, statistics {stats_s:.1f}"
                      + "".join(f", {_written_text(output)} {output.seconds:.1f}" for output in outputs
                                if not isinstance(output, _Video))
                      + (f", checkpoints {saver.seconds:.1f}" if saver is not None and saver.every else "")),
        ("throughput", f"{rate:.3g} circle-steps/s ({covers})"),
        ("collisions", f"{stats['pair_collisions']} pair, {stats['wall_collisions']} wall"),
        ("energy", f"relative change {energy_change:.2e}"),
        ("overlap", f"largest {stats['max_overlap']:.2e} of the contact distance"),
    ]
    for output in outputs:
        if isinstance(output, _Video):
            writer = output.writer
            lines.append(("wrote", f"{writer.path} ({frames_text(writer.frames)} at {writer.fps:g} fps)"
                          if writer.frames else "nothing: stopped before the first frame was written"))
        elif isinstance(output, GSDWriter):
            each = (f", {1e3 * output.seconds / output.frames:.3g} ms a frame, processor time "
                    f"{1e3 * output.cpu_seconds / output.frames:.3g} ms" if output.frames else "")
            lines.append(("wrote", f"{output.path} ({output.frames} GSD frame{'s' if output.frames != 1 else ''}"
                                   f"{each})"))
        elif isinstance(output, StatsWriter):
            lines.append(("wrote", f"{output.path} ({output.rows} row{'s' if output.rows != 1 else ''})"))
    if saver is not None and saver.every is not None and saver.path.exists():
        lines.append(("checkpoint", f"{saver.path} (continue with --resume)"))
    if not outputs:
        lines.append(("wrote", "nothing (--out none)"))
    paths = " and ".join(str(output.path) for output in outputs)
    done = f"{paths} {'are' if len(outputs) > 1 else 'is'} complete" if outputs else "it wrote no file"
    try:
        for name, text in lines:
            print(f"{name:<11} {text}")
        sys.stdout.flush()
    except BrokenPipeError:
        # The reader of the summary left (`circles run ... | head -1`): its choice, not a
        # failure. Output still buffered is dropped, so that the exit does not fail on it.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    except OSError as error:
        raise SummaryError(f"the run is done and {done}, but its summary could not be "
                           f"printed: {error}") from None


def _written_text(output):
    from .trajectory import GSDWriter

    return "trajectory" if isinstance(output, GSDWriter) else "stats table"


class SummaryError(OSError):
    """The run is done and its file complete, but the summary could not be printed."""


def _import_the_engine():
    """Import the simulation, the canvas and the video writer, with a Ctrl-C meanwhile held
    until the imports end; True when one came. (Taichi's decorators, run by the imports, catch
    every exception in a bare except: a KeyboardInterrupt raised there was lost, or left a
    half-imported module.)"""
    presses = []
    previous = signal.signal(signal.SIGINT, lambda signum, frame: presses.append(signum))
    try:
        for name in ("simulation", "canvas", "video"):
            importlib.import_module(f".{name}", __package__)
    finally:
        signal.signal(signal.SIGINT, previous)
    return bool(presses)


def main(argv=None):
    """Entry point of the ``circles`` command; returns the exit status."""
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ["sweep"]:
        return importlib.import_module(".sweep", __package__).main(argv)
    if argv[:1] == ["compress"]:
        return importlib.import_module(".compress", __package__).main(argv)
    if argv[:1] == ["plot"]:  # no simulation engine to import
        return importlib.import_module(".plot", __package__).main(argv[1:])
    made = []  # folders made for the output, taken away again if the run stops before writing
    try:
        if _import_the_engine():
            raise KeyboardInterrupt
        scene, options = _prepare(argv, made)
        importlib.import_module(".kernel_cache", __package__).announce(scene, options["arch"], options["threads"])
        status = _run(scene, options)
        made.clear()
        return status
    except UsageError as error:
        print(f"circles: error: {error}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except SystemExit as exit_:  # --help
        return exit_.code if isinstance(exit_.code, int) else 0
    except KeyboardInterrupt:  # before the frames began (placement): nothing written yet
        print("circles: stopped by Ctrl-C", file=sys.stderr)
        return EXIT_INTERRUPTED
    except SummaryError as error:
        print(f"circles: {error}", file=sys.stderr)
        return EXIT_FAILED
    except (FloatingPointError, RuntimeError, OSError, ValueError) as error:
        # A broken state, a clock that cannot move, an encoder that quit, a full disk: the
        # frames so far are kept. (Bad input is a UsageError, raised before the run.)
        print(f"circles: the run failed: {error}", file=sys.stderr)
        return EXIT_FAILED
    finally:
        if made:  # stopped before the first frame: the folders made for it go
            remove_made(made)


if __name__ == "__main__":
    sys.exit(main())
