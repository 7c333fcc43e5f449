"""Frame writers: a run's frames into an MP4, a looping GIF or a folder of PNGs.

``FrameWriter(path, fps)`` picks the format from the path: ``*.mp4`` is H.264 (yuv420p,
through imageio-ffmpeg), ``*.gif`` a GIF that loops forever, anything else a folder of
``frame_00000.png``, ``frame_00001.png``, ... (more digits when told of more than 100000
frames, so that the names sort in frame order). Each frame is encoded and written when it is
given, so memory does not grow with the length of a run, and ``close()`` (or leaving the
``with`` block, also on an exception) finishes the file so that the frames written so far
play.

``check_writable(path, fps, size)`` tells before any work whether the output can be
written: the folder can be made, a file can be created there, the format can take the frame
rate and the frame size.

A frame is written whole or not at all, and a failure to write (a full disk, an encoder that
quits) raises a `WriteError` that says what was kept: a GIF keeps the frames before the one
that failed and stays readable, a PNG folder holds whole frames only, and an MP4 that ffmpeg
could not finish is removed (it would not play).
"""

import math
import os
import re
import signal
import subprocess
import tempfile
from pathlib import Path

import numpy as np

# GIF frame delays are whole hundredths of a second, and players show delays below 2/100 s
# as 10/100 s, so a GIF cannot play faster than 50 frames per second.
GIF_MAX_FPS = 50
# A delay is stored in two bytes: a GIF frame shows at most 655.35 s, so a GIF plays at
# least 100/65535 (about 0.0015) frames per second.
GIF_MAX_DELAY = 65535
GIF_MIN_FPS = 100 / GIF_MAX_DELAY
#: A GIF frame that the first frame's palette renders with more than GIF_LOCAL_SHARE of its
#: pixels off by more than GIF_LOCAL_LEVELS (of 255) in a channel, and with more than twice the
#: share of the first frame itself (which may hold more colours than a palette), gets a palette
#: of its own: colours that the first frame lacked (circles coloured by speed, whose speeds
#: spread). A frame with the colours of the first keeps its palette, so that they do not flicker.
GIF_LOCAL_LEVELS = 24
GIF_LOCAL_SHARE = 1e-3
# MP4 frame rates (ffmpeg 7 of imageio-ffmpeg, libx264, the mp4 muxer; measured). ffmpeg reads
# a rate as a fraction of whole numbers up to 1001000 (av_parse_video_rate): a higher rate
# is silently taken as 1001000 frames per second, one below 1/2002000 as 0, which it
# refuses. The muxer stores a frame's duration as at most 2**31 - 1 ticks, at 10000 to 20000
# ticks a second when the rate's numerator is small, and libx264's B-frames give the first
# packet up to 5 frames' duration: moving frames failed at 3.7e-5 frames per second
# ("Application provided duration ... is invalid") and played from 3.9e-5. The lower limit
# keeps a margin of two; the upper is a round number within the fraction's.
MP4_MIN_FPS = 1e-4
MP4_MAX_FPS = 1_000_000
# MP4 frame sizes: ffmpeg refuses a picture unless 8 * (width + 128) * (height + 128) is
# below 2**31 - 1 (av_image_check_size: "Picture size ... is invalid"), that is
# (width + 128) * (height + 128) < 2**28. Measured: 16384x16128 and 16128x16384 encode,
# 16384x16130 and 16256x16256 are refused. Both sides must be even: yuv420p halves the
# colour resolution.
MP4_AREA_LIMIT = 2**28
# Constant quality for H.264: 18 is visually lossless, which keeps one-pixel circles crisp.
MP4_CRF = 18
# libx264's speed preset. "veryfast" encodes the showcase (150 frames of 1280x720) in 4.3 s of
# processor time against 10.2 s for the default "medium", at a 10% larger file and a PSNR
# 0.8 dB lower (31.8 against 32.6 dB, both at CRF 18); 30 frames of 1e6 one-pixel circles at
# 1920x1080 in 2.0 s against 6.2 s, at a 6% smaller file and 0.35 dB lower. An encoder that
# shares the processors with the simulation held `circles run` up more than the simulation.
MP4_PRESET = "veryfast"
# zlib level for PNG frames: nearly the size of level 6 at a fraction of the time.
PNG_COMPRESS_LEVEL = 3
PNG_PATTERN = re.compile(r"frame_\d{5,}\.png")
# A PNG frame is written under this name, then renamed: a frame is whole or absent.
PART_PATTERN = re.compile(r"\.frame_\d{5,}\.png\.part")


class OutputError(ValueError):
    """The output cannot be written; the message says why and what to do."""


class WriteError(OSError):
    """Frames could not be written (a full disk, an encoder that quit): the message, one
    line, says what failed, why, and what was kept."""


def output_kind(path):
    """"mp4", "gif" or "png" (a folder of PNG frames), from the path's suffix."""
    suffix = Path(path).suffix.lower()
    return {".mp4": "mp4", ".gif": "gif"}.get(suffix, "png")


def _round_up(value, digits=3):
    """`value` rounded up to `digits` significant digits: a round number at least `value`."""
    scale = 10.0 ** (math.floor(math.log10(value)) - digits + 1)
    return math.ceil(value / scale) * scale


def check_fps(kind, fps):
    """Raise ``OutputError`` unless output of `kind` ("mp4", "gif", "png") plays at `fps`."""
    if not (fps > 0):
        raise OutputError(f"fps {fps} must be positive")
    if kind == "gif" and fps > GIF_MAX_FPS:
        raise OutputError(
            f"a GIF plays at most {GIF_MAX_FPS} frames per second, not {fps:g}: use "
            f"--fps {GIF_MAX_FPS} or less, or write an .mp4")
    if kind == "gif" and fps < GIF_MIN_FPS:
        raise OutputError(
            f"a GIF plays at least 100/{GIF_MAX_DELAY} = {GIF_MIN_FPS:.4g} frames per second "
            f"(a frame shows at most {GIF_MAX_DELAY / 100:g} s), not {fps:g}: use --fps "
            f"{_round_up(GIF_MIN_FPS):g} or more, or write an .mp4 (down to {MP4_MIN_FPS:g} "
            f"fps) or PNG frames (any rate)")
    if kind == "mp4" and fps < MP4_MIN_FPS:
        raise OutputError(
            f"an MP4 plays at least {MP4_MIN_FPS:g} frames per second (a frame lasts at most "
            f"{1 / MP4_MIN_FPS:g} s), not {fps:g}: use --fps {MP4_MIN_FPS:g} or more, or "
            f"write PNG frames (any rate)")
    if kind == "mp4" and fps > MP4_MAX_FPS:
        raise OutputError(
            f"an MP4 plays at most {MP4_MAX_FPS} frames per second, not {fps:g}: use --fps "
            f"{MP4_MAX_FPS} or less, or write PNG frames (any rate)")


def _mp4_size_fits(width, height):
    return (width + 128) * (height + 128) < MP4_AREA_LIMIT


def check_mp4_size(width, height):
    """Raise ``OutputError`` unless ffmpeg encodes MP4 frames of `width` x `height` pixels
    as they are: even sides (yuv420p), and within ffmpeg's picture size (`MP4_AREA_LIMIT`)."""
    from .canvas import MAX_IMAGE_SIDE

    if not _mp4_size_fits(width, height):
        # The largest even size of about the same shape that fits.
        scale = math.sqrt(MP4_AREA_LIMIT / ((width + 128) * (height + 128)))
        while True:
            fit_w, fit_h = (max(int(side * scale) // 2 * 2, 2) for side in (width, height))
            if _mp4_size_fits(fit_w, fit_h):
                break
            scale *= 0.9999
        raise OutputError(
            f"an MP4 frame of {width}x{height} pixels is larger than ffmpeg takes: (width + 128) "
            f"* (height + 128) must be below 2**28 = {MP4_AREA_LIMIT}, not "
            f"{(width + 128) * (height + 128)}: use --size {fit_w}x{fit_h} or smaller, or write "
            f"a .gif or PNG frames")
    if width % 2 or height % 2:
        down_w, down_h = width - width % 2, height - height % 2
        sizes = [f"{down_w}x{down_h}"] if down_w and down_h else []  # a side of 1 has no even size below
        up_w, up_h = width + width % 2, height + height % 2
        if max(up_w, up_h) <= MAX_IMAGE_SIDE and _mp4_size_fits(up_w, up_h):
            sizes.append(f"{up_w}x{up_h}")
        raise OutputError(
            f"an MP4 frame has an even width and height (H.264 in yuv420p halves the colour "
            f"resolution), not {width}x{height}: use --size {' or '.join(sizes)}, or write a "
            f".gif or PNG frames, which take any size")


def check_writable(path, fps=None, size=None, made=None):
    """Raise ``OutputError`` unless frames at ``fps`` of ``size`` (width, height) pixels can
    be written to ``path``.

    Makes the missing parent folders (or, for PNG frames, the folder itself), and lists them
    in ``made`` (deepest last) when it is given, so that a caller that stops before writing
    can take them away (`command.remove_made`); leaves no other trace. Call it before simulating so
    that a bad path fails at once.
    """
    path = Path(path)
    kind = output_kind(path)
    if fps is not None:
        check_fps(kind, fps)
    if kind == "mp4" and size is not None:
        check_mp4_size(*size)
    suffix = path.suffix
    # A path with another suffix is a file asked for by mistake (frames.png, run.avi, or
    # "x.mp4 " with a space), not a folder of PNG frames, unless that folder exists.
    if kind == "png" and suffix and not path.is_dir():
        raise OutputError(
            f"cannot write {path}: a {suffix!r} file is not an output format; write an .mp4, a .gif, "
            f"or PNG frames into a folder (a path without a suffix, such as {path.with_suffix('')})")
    if kind == "mp4":
        _ffmpeg_executable()
    folder = path if kind == "png" else path.parent
    if kind != "png" and path.is_dir():
        raise OutputError(f"cannot write {path}: it is a folder")
    if folder.exists() and not folder.is_dir():
        raise OutputError(f"cannot write {path}: {folder} is a file, not a folder")
    missing = [f for f in [folder, *folder.parents] if not f.exists()][::-1]
    try:
        folder.mkdir(parents=True, exist_ok=True)
        if made is not None:
            made.extend(missing)
        if kind == "png":
            with tempfile.NamedTemporaryFile(dir=folder, prefix=".circles-check-"):
                pass
        else:
            existed = path.exists()
            with open(path, "ab"):
                pass
            if not existed:
                path.unlink()
    except OSError as error:
        reason = error.strerror or str(error)
        raise OutputError(f"cannot write {path}: {reason}") from None
    return path


def _ffmpeg_executable():
    try:
        import imageio_ffmpeg
    except ImportError:
        raise OutputError("MP4 output needs imageio-ffmpeg: pip install imageio-ffmpeg, "
                          "or write a .gif or a folder of PNGs") from None
    try:
        return imageio_ffmpeg.get_ffmpeg_exe()
    except RuntimeError as error:
        raise OutputError(f"MP4 output needs an ffmpeg executable ({error}): "
                          "pip install imageio-ffmpeg, or write a .gif or a folder of "
                          "PNGs") from None


class FrameWriter:
    """Writes RGB frames to ``path`` as they come; the format follows the path.

    Args:
      path: ``*.mp4``, ``*.gif``, or a folder for PNG frames.
      fps: frames per second of the video (GIF: 100/65535 to 50; MP4: 1e-4 to 1e6).
      frames: how many frames will come, when known: PNG names get as many digits as the
        last frame's number needs (at least 5), so that they sort in frame order.

    Use as a context manager, or call ``close()``. ``frames`` counts the frames written.
    A `WriteError` from ``write`` or ``close`` has already finished (or, for an MP4 that
    cannot play, removed) the file: the writer is closed. A frame whose ``write`` is stopped
    midway (a KeyboardInterrupt) is left out of the file that ``close`` finishes.
    """

    def __init__(self, path, fps, frames=None):
        self.path = check_writable(path, fps)
        self.fps = float(fps)
        self.kind = output_kind(self.path)
        self.frames = 0
        self._shape = None
        if self.kind == "png":
            self._sink = _PngSink(self.path, frames)
        else:
            self._sink = {"mp4": _Mp4Sink, "gif": _GifSink}[self.kind](self.path, self.fps)

    def write(self, frame):
        """Append one frame: uint8 array (height, width, 3), the same size every time."""
        frame = np.asarray(frame)
        if frame.dtype != np.uint8 or frame.ndim != 3 or frame.shape[2] != 3:
            raise ValueError(f"a frame is a uint8 array (height, width, 3), not "
                             f"{frame.dtype} {frame.shape}")
        if self._shape is None:
            self._shape = frame.shape
        elif frame.shape != self._shape:
            raise ValueError(f"frame {self.frames} has shape {frame.shape}, the first "
                             f"had {self._shape}")
        if self._sink is None:
            raise ValueError(f"{self.path} is closed")
        try:
            self._sink.write(np.ascontiguousarray(frame))
        except WriteError:
            self._sink = None  # the sink has finished or removed its file
            raise
        self.frames += 1

    def close(self):
        """Finish the file; safe to call twice."""
        if self._sink is not None:
            sink, self._sink = self._sink, None
            sink.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc_info):
        self.close()
        return False


def _remove(path):
    """Remove a file that cannot be read back; the end of a message saying so."""
    try:
        os.unlink(path)
    except FileNotFoundError:
        return "no file was left"
    except OSError as error:
        return f"the file left there does not play and could not be removed ({error.strerror})"
    return "removed the file, which would not play"


def frames_text(count):
    """'1 frame', '2 frames'."""
    return f"{count} frame{'s' if count != 1 else ''}"


class _Mp4Sink:
    """H.264 (yuv420p) through an ffmpeg subprocess that reads raw RGB frames on its stdin.

    ffmpeg runs in a session of its own, so that a Ctrl-C at the terminal does not reach it,
    and it finishes the file when its input ends, also when this process ends early. Its
    messages go to a temporary file: when it fails, the first one is the cause, given in the
    `WriteError`'s one line, and the file it leaves (which would not play) is removed."""

    def __init__(self, path, fps):
        self.path = path
        self.fps = fps
        self._executable = _ffmpeg_executable()
        self._process = None
        self._log = None
        self._frames = 0

    def _start(self, width, height):
        check_mp4_size(width, height)
        self._log = tempfile.TemporaryFile()
        command = [
            self._executable, "-nostats", "-v", "error", "-y",
            "-f", "rawvideo", "-pix_fmt", "rgb24", "-s", f"{width}x{height}",
            "-r", repr(self.fps), "-i", "-", "-an",
            "-c:v", "libx264", "-preset", MP4_PRESET, "-pix_fmt", "yuv420p", "-crf", str(MP4_CRF),
            # "file:" and an absolute path: a name with a colon or a leading dash is a file.
            "-f", "mp4", "file:" + os.path.abspath(self.path)]
        try:
            self._process = subprocess.Popen(
                command, stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=self._log,
                start_new_session=True,
                creationflags=getattr(subprocess, "CREATE_NEW_PROCESS_GROUP", 0))
        except OSError as error:
            self._log.close()
            raise WriteError(f"cannot start ffmpeg ({self._executable}) to write {self.path}: "
                             f"{error.strerror or error}") from None

    def write(self, frame):
        if self._process is None:
            self._start(frame.shape[1], frame.shape[0])
        try:
            self._process.stdin.write(frame)
            self._process.stdin.flush()
        except OSError as error:  # a broken pipe: ffmpeg has quit
            raise self._failure(error) from None
        self._frames += 1

    def close(self):
        if self._process is None:
            return
        try:
            self._process.stdin.close()  # the end of the input: ffmpeg finishes the file
        except OSError as error:
            raise self._failure(error) from None
        if self._process.wait() != 0:
            raise self._failure()
        self._process = None
        self._log.close()

    def _failure(self, error=None):
        """After ffmpeg failed: wait for it, remove its file, and say why in one line."""
        process, self._process = self._process, None
        try:
            process.stdin.close()
        except OSError:
            pass
        code = process.wait()
        self._log.seek(0)
        messages = self._log.read().decode(errors="replace").splitlines()
        self._log.close()
        if code == 0:  # ffmpeg finished the file, but a frame could not be sent
            return WriteError(f"cannot send frame {self._frames} to ffmpeg for {self.path} "
                              f"({error.strerror or error}); the file holds the "
                              f"{frames_text(self._frames)} before")
        # ffmpeg prefixes a message with the parts that send it: "[out#0/mp4 @ 0x5f...] ".
        messages = [re.sub(r"^(\[[^\]]*\]\s*)+", "", line).strip() for line in messages]
        messages = [line for line in messages if line and not line.startswith("Last message")]
        if code < 0:
            reason = f"killed by {signal.Signals(-code).name}: {signal.strsignal(-code)}"
        elif messages:
            reason = messages[0]
        else:
            reason = f"exit status {code}"
        return WriteError(f"ffmpeg failed to write {self.path} after {frames_text(self._frames)} "
                          f"({reason}); {_remove(self.path)}")


class _GifSink:
    """A GIF streamed frame by frame: the header, then each frame as it comes.

    The 256-colour palette is taken from the first frame and kept, so colours do not
    flicker from frame to frame; pixels map to their nearest palette colour, undithered
    (dithering would add noise that moves every frame). A frame that palette cannot show
    (colours the first frame lacked, see GIF_LOCAL_LEVELS) carries a palette of its own.

    When a write fails, or stops midway (Ctrl-C), the file is cut back to the end of the last
    whole frame and ended there, so that the frames before stay readable."""

    def __init__(self, path, fps):
        self.path = path
        self.fps = fps
        self._file = None
        self._palette_image = None
        self._index = 0
        self._end = 0  # bytes of the header and the whole frames
        self._first_off = 0.0  # share of the first frame's pixels its palette shows off

    def _delay(self, index):
        # Hundredths of a second; rounding the frame's end time keeps the total exact.
        delay = round((index + 1) * 100 / self.fps) - round(index * 100 / self.fps)
        return min(max(delay, 2), GIF_MAX_DELAY)

    @staticmethod
    def _own_palette(image):
        """The image in 256 colours of its own (median cut, undithered)."""
        from PIL import Image

        return image.quantize(256, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE)

    @staticmethod
    def _color_table(indexed):
        """The 256-colour table (768 bytes) of a palette image."""
        return bytes(indexed.getpalette()[:768]).ljust(768, b"\0")

    def _open(self, image):
        self._palette_image = self._own_palette(image)
        width, height = image.size
        header = (b"GIF89a" + width.to_bytes(2, "little") + height.to_bytes(2, "little")
                  + bytes([0xF7, 0, 0]) + self._color_table(self._palette_image)
                  # Application extension: loop forever.
                  + b"!\xff\x0bNETSCAPE2.0\x03\x01\x00\x00\x00")
        try:
            self._file = open(self.path, "wb")
            self._file.write(header)
            self._file.flush()
        except OSError as error:
            raise self._failure(error) from None
        self._end = len(header)

    def write(self, frame):
        from PIL import GifImagePlugin, Image

        image = Image.fromarray(frame, "RGB")
        if self._file is None:
            self._open(image)
        indexed = image.quantize(palette=self._palette_image, dither=Image.Dither.NONE)
        shown = np.asarray(indexed.convert("RGB"), dtype=np.int16)
        off = float(np.mean(np.abs(shown - frame).max(axis=2) > GIF_LOCAL_LEVELS))
        if self._index == 0:
            self._first_off = off
        local = off > GIF_LOCAL_SHARE and off > 2.0 * self._first_off
        if local:
            indexed = self._own_palette(image)
        image_data = b"".join(GifImagePlugin.getdata(indexed))
        if local:
            # The image descriptor (10 bytes) flags a local table of 256 colours, which follows it.
            image_data = image_data[:9] + bytes([0x87]) + self._color_table(indexed) + image_data[10:]
        # Graphic control extension: keep the frame (disposal 1), then wait the delay.
        data = b"".join([b"!\xf9\x04\x04" + self._delay(self._index).to_bytes(2, "little")
                         + b"\x00\x00", image_data])
        try:
            self._file.write(data)
            self._file.flush()
        except OSError as error:
            raise self._failure(error) from None
        self._end += len(data)
        self._index += 1

    def close(self):
        if self._file is not None:
            try:
                # Past the last whole frame, in case a frame's writing was cut (Ctrl-C).
                self._file.seek(self._end)
                self._file.truncate()
                self._file.write(b";")  # the trailer
                self._file.flush()
            except OSError as error:
                raise self._failure(error) from None
            self._file.close()
            self._file = None

    def _failure(self, error):
        """After a failed write: end the file after its last whole frame; one line to say so."""
        file, self._file = self._file, None
        if file is not None:
            try:
                file.close()  # flushes what it still holds, which may fail again
            except OSError:
                pass
        reason = error.strerror or str(error)
        if self._index == 0:
            return WriteError(f"cannot write {self.path} ({reason}): no frame was written; "
                              f"{_remove(self.path)}")
        said = f"cannot write {self.path} beyond {frames_text(self._index)} ({reason})"
        try:
            os.truncate(self.path, self._end)
            with open(self.path, "ab") as ended:
                ended.write(b";")
        except OSError as second:
            return WriteError(f"{said}: the file keeps those {self._index}, but its last byte "
                              f"could not be written ({second.strerror or second}) and some "
                              f"players may refuse it")
        return WriteError(f"{said}: the file keeps those {self._index} and plays")


class _PngSink:
    """``frame_00000.png``, ... in a folder; frames of an earlier run there are removed
    first, so the folder holds this run only. Each frame is written under a hidden name and
    then renamed, so that a frame is whole or absent, whatever stops the writing."""

    def __init__(self, path, frames=None):
        self.path = path
        self._index = 0
        # As many digits as the last frame's number needs, when the count is known; at least 5.
        self.digits = 5 if frames is None else max(5, len(str(max(int(frames) - 1, 0))))
        for old in os.scandir(path):
            if old.is_file() and (PNG_PATTERN.fullmatch(old.name)
                                  or PART_PATTERN.fullmatch(old.name)):
                os.unlink(old.path)

    def write(self, frame):
        import imageio.v3 as iio

        name = f"frame_{self._index:0{self.digits}d}.png"
        part = self.path / f".{name}.part"
        try:
            iio.imwrite(part, frame, extension=".png", compress_level=PNG_COMPRESS_LEVEL)
            os.replace(part, self.path / name)
        except BaseException as error:
            try:
                os.unlink(part)
            except OSError:
                pass
            if isinstance(error, OSError):
                raise WriteError(f"cannot write {self.path / name} "
                                 f"({error.strerror or error}); the folder holds the "
                                 f"{frames_text(self._index)} before it") from None
            raise
        self._index += 1

    def close(self):
        pass
