"""Frame writers: a run's frames into an MP4, a looping GIF or a folder of PNGs.

``FrameWriter(path, fps)`` picks the format from the path: ``*.mp4`` is H.264 (yuv420p,
through imageio-ffmpeg), ``*.gif`` a GIF that loops forever, anything else a folder of
``frame_00000.png``, ``frame_00001.png``, ... (more digits when told of more than 100000
frames, so that the names sort in frame order). Each frame is encoded and written when it is
given, so memory does not grow with the length of a run, and ``close()`` (or leaving the
``with`` block, also on an exception) finishes the file so that the frames written so far
play.

``check_writable(path, fps)`` tells before any work whether the output can be written:
the folder can be made, a file can be created there, the format can be encoded.
"""

import os
import re
import tempfile
from pathlib import Path

import numpy as np

# GIF frame delays are whole hundredths of a second, and players show delays below 2/100 s
# as 10/100 s, so a GIF cannot play faster than 50 frames per second.
GIF_MAX_FPS = 50
# Constant quality for H.264: 18 is visually lossless, which keeps one-pixel circles crisp.
MP4_CRF = 18
# zlib level for PNG frames: nearly the size of level 6 at a fraction of the time.
PNG_COMPRESS_LEVEL = 3
PNG_PATTERN = re.compile(r"frame_\d{5,}\.png")


class OutputError(ValueError):
    """The output cannot be written; the message says why and what to do."""


#: Suffixes of files that are not a format written here: a path that ends in one is a file
#: asked for by mistake (``frames.png``, ``run.avi``), not a folder of PNG frames, unless
#: that folder already exists.
NOT_WRITTEN = frozenset(
    ".png .apng .jpg .jpeg .webp .bmp .tif .tiff .avi .mov .mkv .webm .m4v .mpg .mpeg .wmv .flv .ogv "
    ".txt .csv .json .npy .npz .pdf .svg .zip".split())


def output_kind(path):
    """"mp4", "gif" or "png" (a folder of PNG frames), from the path's suffix."""
    suffix = Path(path).suffix.lower()
    return {".mp4": "mp4", ".gif": "gif"}.get(suffix, "png")


def check_writable(path, fps=None):
    """Raise ``OutputError`` unless frames at ``fps`` can be written to ``path``.

    Makes the missing parent folders (or, for PNG frames, the folder itself); leaves no
    other trace. Call it before simulating so that a bad path fails at once.
    """
    path = Path(path)
    kind = output_kind(path)
    if fps is not None and not (fps > 0):
        raise OutputError(f"fps {fps} must be positive")
    if kind == "gif" and fps is not None and fps > GIF_MAX_FPS:
        raise OutputError(
            f"a GIF plays at most {GIF_MAX_FPS} frames per second, not {fps:g}: use "
            f"--fps {GIF_MAX_FPS} or less, or write an .mp4")
    suffix = path.suffix.lower()
    if kind == "png" and suffix in NOT_WRITTEN and not path.is_dir():
        raise OutputError(
            f"cannot write {path}: a {suffix} file is not an output format; write an .mp4, a .gif, "
            f"or PNG frames into a folder (a path without a suffix, such as {path.with_suffix('')})")
    if kind == "mp4":
        _ffmpeg_executable()
    folder = path if kind == "png" else path.parent
    if kind != "png" and path.is_dir():
        raise OutputError(f"cannot write {path}: it is a folder")
    if folder.exists() and not folder.is_dir():
        raise OutputError(f"cannot write {path}: {folder} is a file, not a folder")
    try:
        folder.mkdir(parents=True, exist_ok=True)
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
      fps: frames per second of the video (GIF: at most 50).
      frames: how many frames will come, when known: PNG names get as many digits as the
        last frame's number needs (at least 5), so that they sort in frame order.

    Use as a context manager, or call ``close()``. ``frames`` counts the frames written.
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
        self._sink.write(np.ascontiguousarray(frame))
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


class _Mp4Sink:
    """H.264 through an ffmpeg subprocess; ffmpeg ignores Ctrl-C, so that ``close`` can
    still finish the file after one."""

    def __init__(self, path, fps):
        _ffmpeg_executable()
        self.path = path
        self.fps = fps
        self._encoder = None

    def write(self, frame):
        # yuv420p halves the chroma resolution: both sides must be even.
        pad_rows, pad_cols = frame.shape[0] % 2, frame.shape[1] % 2
        if pad_rows or pad_cols:
            frame = np.pad(frame, ((0, pad_rows), (0, pad_cols), (0, 0)), mode="edge")
        if self._encoder is None:
            import imageio_ffmpeg
            self._encoder = imageio_ffmpeg.write_frames(
                str(self.path), size=(frame.shape[1], frame.shape[0]), fps=self.fps,
                codec="libx264", pix_fmt_in="rgb24", pix_fmt_out="yuv420p", quality=None,
                macro_block_size=1, ffmpeg_log_level="error",
                output_params=["-crf", str(MP4_CRF)])
            self._encoder.send(None)
        self._encoder.send(frame)

    def close(self):
        if self._encoder is not None:
            self._encoder.close()


class _GifSink:
    """A GIF streamed frame by frame: the header, then each frame as it comes.

    The 256-colour palette is taken from the first frame and kept, so colours do not
    flicker from frame to frame; pixels map to their nearest palette colour, undithered
    (dithering would add noise that moves every frame)."""

    def __init__(self, path, fps):
        self.path = path
        self.fps = fps
        self._file = None
        self._palette_image = None

    def _delay(self, index):
        # Hundredths of a second; rounding the frame's end time keeps the total exact.
        return max(round((index + 1) * 100 / self.fps) - round(index * 100 / self.fps), 2)

    def _open(self, image):
        from PIL import Image

        self._palette_image = image.quantize(256, method=Image.Quantize.MEDIANCUT,
                                             dither=Image.Dither.NONE)
        palette = bytes(self._palette_image.getpalette()[:768]).ljust(768, b"\0")
        self._index = 0
        self._file = open(self.path, "wb")
        width, height = image.size
        self._file.write(b"GIF89a" + width.to_bytes(2, "little") + height.to_bytes(2, "little")
                         + bytes([0xF7, 0, 0]) + palette
                         # Application extension: loop forever.
                         + b"!\xff\x0bNETSCAPE2.0\x03\x01\x00\x00\x00")

    def write(self, frame):
        from PIL import GifImagePlugin, Image

        image = Image.fromarray(frame, "RGB")
        if self._file is None:
            self._open(image)
        indexed = image.quantize(palette=self._palette_image, dither=Image.Dither.NONE)
        # Graphic control extension: keep the frame (disposal 1), then wait the delay.
        self._file.write(b"!\xf9\x04\x04" + self._delay(self._index).to_bytes(2, "little")
                         + b"\x00\x00")
        for chunk in GifImagePlugin.getdata(indexed):
            self._file.write(chunk)
        self._file.flush()
        self._index += 1

    def close(self):
        if self._file is not None:
            self._file.write(b";")
            self._file.close()


class _PngSink:
    """``frame_00000.png``, ... in a folder; frames of an earlier run there are removed
    first, so the folder holds this run only."""

    def __init__(self, path, frames=None):
        self.path = path
        self._index = 0
        # As many digits as the last frame's number needs, when the count is known; at least 5.
        self.digits = 5 if frames is None else max(5, len(str(max(int(frames) - 1, 0))))
        for old in os.scandir(path):
            if old.is_file() and PNG_PATTERN.fullmatch(old.name):
                os.unlink(old.path)

    def write(self, frame):
        import imageio.v3 as iio

        iio.imwrite(self.path / f"frame_{self._index:0{self.digits}d}.png", frame,
                    compress_level=PNG_COMPRESS_LEVEL)
        self._index += 1

    def close(self):
        pass
