"""Frame writers: every format gives back the frames written, at their size, in order."""

import os
import resource
import sys
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest

from circles import video
from circles.command import remove_made
from circles.video import FrameWriter, OutputError, WriteError, check_writable, output_kind

FPS = 10


def frames(count=7, height=64, width=96):
    """A red square moving right on a dark background: frames that differ."""
    result = []
    for k in range(count):
        frame = np.full((height, width, 3), (16, 16, 24), np.uint8)
        frame[20:36, 8 + 8 * k:24 + 8 * k] = (230, 40, 40)
        result.append(frame)
    return result


def read_back(path):
    if path.is_dir():
        return np.stack([iio.imread(p) for p in sorted(path.glob("frame_*.png"))])
    return iio.imread(path, index=None)[..., :3]


@pytest.mark.parametrize("name", ["run.mp4", "run.gif", "run_frames"])
def test_writer_gives_back_every_frame_at_its_size(tmp_path, name):
    written = frames()
    path = tmp_path / name
    with FrameWriter(path, FPS) as writer:
        for frame in written:
            writer.write(frame)
    assert writer.frames == len(written)
    got = read_back(path)
    assert got.shape == (len(written), 64, 96, 3)
    if name.endswith(".mp4"):
        # Lossy (H.264, chroma at half resolution): close on average, and in order.
        for k, frame in enumerate(written):
            errors = [np.abs(got[k].astype(int) - other.astype(int)).mean()
                      for other in written]
            assert errors[k] < 4.0 and int(np.argmin(errors)) == k
    else:
        # GIF: all the colours are in the first frame's palette; PNG: lossless.
        assert (got == np.stack(written)).all()


def test_mp4_with_odd_size_is_refused_not_padded(tmp_path):
    """yuv420p needs even sides: an odd frame is refused (padding it would change the size
    and repeat the edge pixels), with the even sizes near it; GIF and PNG keep any size."""
    with pytest.raises(OutputError, match="not 95x63: use --size 94x62 or 96x64"):
        check_writable(tmp_path / "odd.mp4", FPS, (95, 63))
    path = tmp_path / "odd.mp4"
    with FrameWriter(path, FPS) as writer:
        with pytest.raises(OutputError, match="even width and height"):
            writer.write(frames(1, 63, 95)[0])
    assert not path.exists()
    for name in ("odd.gif", "odd_frames"):
        with FrameWriter(tmp_path / name, FPS) as writer:
            for frame in frames(2, 63, 95):
                writer.write(frame)
        assert read_back(tmp_path / name).shape == (2, 63, 95, 3)


def test_mp4_size_limit_is_ffmpegs(tmp_path):
    """ffmpeg refuses a picture unless (w + 128) * (h + 128) < 2**28: 16384x16128 is the
    tallest at width 16384 (both measured with ffmpeg); the refusal names a size that fits."""
    path = tmp_path / "big.mp4"
    assert (16384 + 128) * (16128 + 128) < 2**28 <= (16384 + 128) * (16130 + 128)
    check_writable(path, FPS, (16384, 16128))
    check_writable(path, FPS, (16128, 16384))
    for size in ((16384, 16130), (16256, 16256), (16384, 16384)):
        with pytest.raises(OutputError, match=r"below 2\*\*28") as error:
            check_writable(path, FPS, size)
        fit = error.value.args[0].split("--size ")[1].split(" ")[0]
        check_writable(path, FPS, tuple(map(int, fit.split("x"))))  # the size named fits
    check_writable(tmp_path / "big.gif", FPS, (16384, 16384))  # a GIF takes it


def test_mp4_frame_rate_limits(tmp_path):
    """The lowest and highest MP4 rates encode every frame (the moving square: B-frames,
    the case that fails first at low rates), and the lowest keeps its timing: 7 frames at
    1e-4 per second last 70000 s. Just beyond either, the rate is refused."""
    written = frames()
    for fps in (video.MP4_MIN_FPS, video.MP4_MAX_FPS):
        path = tmp_path / f"{fps:g}.mp4"
        with FrameWriter(path, fps) as writer:
            for frame in written:
                writer.write(frame)
        assert read_back(path).shape == (len(written), 64, 96, 3)
        if fps == video.MP4_MIN_FPS:
            assert iio.immeta(path)["duration"] == pytest.approx(len(written) / fps)
    with pytest.raises(OutputError, match="at least 0.0001 frames per second"):
        check_writable(tmp_path / "slow.mp4", video.MP4_MIN_FPS * 0.99)
    with pytest.raises(OutputError, match="at most 1000000 frames per second"):
        check_writable(tmp_path / "fast.mp4", video.MP4_MAX_FPS * 1.01)


def limited_ffmpeg(tmp_path, size_limit):
    """An ffmpeg that may write files of at most `size_limit` bytes: it fails as on a full disk."""
    import imageio_ffmpeg

    script = tmp_path / "limited_ffmpeg"
    script.write_text(f"#!{sys.executable}\n"
                      "import os, resource, sys\n"
                      f"resource.setrlimit(resource.RLIMIT_FSIZE, ({size_limit}, {size_limit}))\n"
                      f"os.execv({imageio_ffmpeg.get_ffmpeg_exe()!r}, ['ffmpeg', *sys.argv[1:]])\n")
    script.chmod(0o755)
    return script


def test_mp4_encoder_failure_is_one_line_and_leaves_no_broken_file(tmp_path, monkeypatch):
    """ffmpeg that cannot write its file (here at most 2000 bytes, then "File too large")
    fails the writer with ffmpeg's own reason in one line, and the file, which would not
    play, is removed."""
    monkeypatch.setenv("IMAGEIO_FFMPEG_EXE", str(limited_ffmpeg(tmp_path, 2000)))
    noise = np.random.default_rng(1).integers(0, 256, (3, 64, 96, 3), dtype=np.uint8)
    path = tmp_path / "full.mp4"
    writer = FrameWriter(path, FPS)
    with pytest.raises(WriteError) as error:
        for frame in noise:  # incompressible: more than 2000 bytes of video
            writer.write(frame)
        writer.close()
    message = str(error.value)
    assert "\n" not in message and "full.mp4" in message and "File too large" in message
    assert "removed the file" in message and not path.exists()
    writer.close()  # closed already: nothing more to do


@pytest.mark.parametrize("room, words", [
    (16, "keeps those 3 and plays"),
    (0, "keeps those 3, but its last byte could not be written"),
])
def test_gif_write_failure_keeps_the_frames_before_readable(tmp_path, room, words):
    """A write that fails midway through a frame (the file may grow by `room` bytes only, as
    on a full disk) cuts the GIF back to its last whole frame and ends it there."""
    path = tmp_path / "full.gif"
    written = frames(4)
    writer = FrameWriter(path, FPS)
    for frame in written[:3]:
        writer.write(frame)
    soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
    resource.setrlimit(resource.RLIMIT_FSIZE, (path.stat().st_size + room, hard))
    try:
        with pytest.raises(WriteError, match=f"beyond 3 frames \\(File too large\\): the file {words}"):
            writer.write(written[3])
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))
    writer.close()
    assert writer.frames == 3
    assert (read_back(path) == np.stack(written[:3])).all()


@pytest.mark.parametrize("stop", [KeyboardInterrupt(), OSError(28, "No space left on device")])
def test_a_png_frame_is_whole_or_absent(tmp_path, monkeypatch, stop):
    """A frame whose writing stops midway (Ctrl-C, a full disk) leaves no file behind."""
    folder = tmp_path / "frames"
    writer = FrameWriter(folder, FPS)
    writer.write(frames(1)[0])

    def stopped(uri, image, **kwargs):
        Path(uri).write_bytes(b"\x89PNG\r\n\x1a\n")  # the start of a frame, then the stop
        raise stop

    monkeypatch.setattr(iio, "imwrite", stopped)
    with pytest.raises(type(stop)) as error:
        writer.write(frames(2)[1])
    if isinstance(stop, OSError):
        assert "No space left on device" in str(error.value)
        assert "holds the 1 frame before it" in str(error.value)
    assert os.listdir(folder) == ["frame_00000.png"]


class _CutOnce:
    """A file (or ffmpeg's input) whose next write stops halfway with a Ctrl-C."""

    def __init__(self, real):
        self.real, self.cut = real, False

    def write(self, data):
        if not self.cut:
            self.cut = True
            data = memoryview(data).cast("B")
            self.real.write(data[:len(data) // 2])
            self.real.flush()
            raise KeyboardInterrupt
        return self.real.write(data)

    def __getattr__(self, name):
        return getattr(self.real, name)


@pytest.mark.parametrize("name", ["cut.mp4", "cut.gif"])
def test_a_frame_cut_by_ctrl_c_is_left_out_and_the_file_plays(tmp_path, name):
    """Ctrl-C in a program's own loop can stop `write` halfway through a frame's bytes; the
    file that `close` finishes holds the whole frames before it, and plays."""
    path = tmp_path / name
    written = frames(4)
    with pytest.raises(KeyboardInterrupt):
        with FrameWriter(path, FPS) as writer:
            for frame in written[:3]:
                writer.write(frame)
            if name.endswith(".mp4"):
                writer._sink._process.stdin = _CutOnce(writer._sink._process.stdin)
            else:
                writer._sink._file = _CutOnce(writer._sink._file)
            writer.write(written[3])
    assert writer.frames == 3
    got = read_back(path)
    assert got.shape == (3, 64, 96, 3)
    if name.endswith(".gif"):
        assert (got == np.stack(written[:3])).all()


def test_gif_loops_and_keeps_the_frame_rate(tmp_path):
    path = tmp_path / "loop.gif"
    with FrameWriter(path, 25) as writer:
        for frame in frames(4):
            writer.write(frame)
    meta = iio.immeta(path, index=0)
    assert meta["loop"] == 0  # forever
    assert meta["duration"] == pytest.approx(40)  # milliseconds


def test_gif_frames_with_colours_the_first_lacked_keep_them(tmp_path):
    """The GIF's palette comes from the first frame; circles coloured by speed change colour as
    the speeds spread, so a later frame can hold colours the first lacked. Such a frame carries
    a palette of its own: each frame reads back as written (a few colours, so exactly)."""
    written = frames(4)
    for k, colour in enumerate([(230, 40, 40), (40, 200, 90), (60, 80, 250), (250, 220, 30)]):
        written[k][20:36, 8 + 8 * k:24 + 8 * k] = colour
        written[k][40:50, 10:90] = (k * 60, 255 - k * 60, 128)
    path = tmp_path / "speeds.gif"
    with FrameWriter(path, FPS) as writer:
        for frame in written:
            writer.write(frame)
    assert (read_back(path) == np.stack(written)).all()


def test_gif_is_written_while_frames_come(tmp_path):
    # Streaming: each frame reaches the file before the next, nothing is held back.
    path = tmp_path / "stream.gif"
    writer = FrameWriter(path, FPS)
    sizes = []
    for frame in frames(3):
        writer.write(frame)
        sizes.append(path.stat().st_size)
    writer.close()
    assert 0 < sizes[0] < sizes[1] < sizes[2] < path.stat().st_size + 1


def test_png_folder_replaces_the_frames_of_an_earlier_run(tmp_path):
    folder = tmp_path / "frames"
    folder.mkdir()
    (folder / "frame_00042.png").write_bytes(b"old")
    (folder / "notes.txt").write_text("kept")
    with FrameWriter(folder, FPS) as writer:
        writer.write(frames(1)[0])
    assert sorted(p.name for p in folder.iterdir()) == ["frame_00000.png", "notes.txt"]


def test_png_names_have_the_digits_the_last_frame_needs(tmp_path):
    """Names sort in frame order: 5 digits up to frame 99999, 6 when told of 100001 frames."""
    for count, names in ((100_000, ["frame_00000.png", "frame_00001.png"]),
                         (100_001, ["frame_000000.png", "frame_000001.png"]),
                         (None, ["frame_00000.png", "frame_00001.png"])):
        folder = tmp_path / f"frames_{count}"
        with FrameWriter(folder, FPS, count) as writer:
            for frame in frames(2):
                writer.write(frame)
        assert sorted(p.name for p in folder.iterdir()) == names


def test_frames_must_keep_their_size(tmp_path):
    with FrameWriter(tmp_path / "a.gif", FPS) as writer:
        writer.write(frames(1)[0])
        with pytest.raises(ValueError, match="shape"):
            writer.write(frames(1, 32, 32)[0])
        with pytest.raises(ValueError, match="uint8"):
            writer.write(np.zeros((64, 96, 3), np.float32))


def test_unwritable_path_is_refused(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("a file, not a folder")
    for path in (blocker / "run.gif", blocker / "run.mp4", blocker / "frames"):
        with pytest.raises(OutputError, match="cannot write"):
            check_writable(path, FPS)
    (tmp_path / "taken.mp4").mkdir()
    with pytest.raises(OutputError, match="is a folder"):
        check_writable(tmp_path / "taken.mp4", FPS)


@pytest.mark.parametrize("name", ["frames.png", "run.AVI", "notes.txt", "clip.3gp", "out.y4m", "x.mp4 ", "run.v2"])
def test_a_file_suffix_of_no_output_format_is_refused(tmp_path, name):
    """A path with a suffix other than .mp4 and .gif names a file, by mistake, not a folder of
    PNG frames: refused before anything is made, with the formats to use (only a fixed list
    of suffixes was, and clip.3gp, out.y4m or "x.mp4 " became folders of PNG frames); an
    existing folder of that name still takes PNG frames."""
    path = tmp_path / "new" / name
    with pytest.raises(OutputError, match=r"not an output format; write an \.mp4, a \.gif, or PNG frames"):
        check_writable(path, FPS)
    assert not (tmp_path / "new").exists()
    path.mkdir(parents=True)
    assert check_writable(path, FPS) == path
    assert output_kind(path) == "png"


def test_check_makes_folders_and_leaves_no_file(tmp_path):
    path = tmp_path / "new" / "deeper" / "run.gif"
    made = []
    check_writable(path, FPS, made=made)
    assert path.parent.is_dir() and not path.exists()
    assert made == [tmp_path / "new", tmp_path / "new" / "deeper"]
    (tmp_path / "new" / "kept").mkdir()  # a folder that is no longer empty stays
    remove_made(made)
    assert sorted(p.name for p in (tmp_path / "new").iterdir()) == ["kept"] and made == []


def test_gif_frame_rate_is_limited(tmp_path):
    with pytest.raises(OutputError, match="50"):
        check_writable(tmp_path / "fast.gif", 60)
    # A delay of 65535 hundredths of a second is the longest the GIF's two bytes hold.
    with pytest.raises(OutputError, match=r"at least 100/65535 = 0.001526 .* --fps 0.00153"):
        check_writable(tmp_path / "slow.gif", 0.0015)
    path = tmp_path / "slowest.gif"
    with FrameWriter(path, video.GIF_MIN_FPS) as writer:
        for frame in frames(2):
            writer.write(frame)
    assert iio.immeta(path, index=0)["duration"] == 655350  # milliseconds, exactly
    assert read_back(path).shape == (2, 64, 96, 3)


def test_mp4_without_imageio_ffmpeg_says_what_to_install(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "imageio_ffmpeg", None)  # import fails
    with pytest.raises(OutputError, match="pip install imageio-ffmpeg") as error:
        check_writable(tmp_path / "run.mp4", FPS)
    assert ".gif" in str(error.value)


# K: a GIF's frame delays add up to the duration.
@pytest.mark.parametrize("fps", [30, 7])
def test_gif_frame_delays_sum_to_frames_over_fps(tmp_path, fps):
    rng = np.random.default_rng(0)
    with FrameWriter(tmp_path / "t.gif", fps) as writer:
        for _ in range(fps):
            writer.write(rng.integers(0, 255, (16, 16, 3), dtype=np.uint8))
    total = sum(iio.immeta(tmp_path / "t.gif", index=i)["duration"] for i in range(fps))
    assert total == pytest.approx(1000)  # ms: whole hundredths, rounded at each frame's end
