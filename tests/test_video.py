"""Frame writers: every format gives back the frames written, at their size, in order."""

import sys

import imageio.v3 as iio
import numpy as np
import pytest

from circles.video import FrameWriter, OutputError, check_writable, output_kind

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


def test_mp4_with_odd_size_is_padded_to_even(tmp_path):
    path = tmp_path / "odd.mp4"
    with FrameWriter(path, FPS) as writer:
        for frame in frames(3, 63, 95):
            writer.write(frame)
    assert read_back(path).shape == (3, 64, 96, 3)


def test_gif_loops_and_keeps_the_frame_rate(tmp_path):
    path = tmp_path / "loop.gif"
    with FrameWriter(path, 25) as writer:
        for frame in frames(4):
            writer.write(frame)
    meta = iio.immeta(path, index=0)
    assert meta["loop"] == 0  # forever
    assert meta["duration"] == pytest.approx(40)  # milliseconds


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


@pytest.mark.parametrize("name", ["frames.png", "run.AVI", "notes.txt"])
def test_a_file_suffix_of_no_output_format_is_refused(tmp_path, name):
    """A path that names a file of another format is a mistake, not a folder of PNG frames:
    refused before anything is made, with the formats to use; an existing folder of that
    name still takes PNG frames."""
    path = tmp_path / "new" / name
    with pytest.raises(OutputError, match=r"not an output format; write an \.mp4, a \.gif, or PNG frames"):
        check_writable(path, FPS)
    assert not (tmp_path / "new").exists()
    path.mkdir(parents=True)
    assert check_writable(path, FPS) == path
    assert output_kind(path) == "png"
    assert output_kind(tmp_path / "run.v2") == "png"  # a folder's name may hold a dot
    check_writable(tmp_path / "run.v2", FPS)


def test_check_makes_folders_and_leaves_no_file(tmp_path):
    path = tmp_path / "new" / "deeper" / "run.gif"
    check_writable(path, FPS)
    assert path.parent.is_dir() and not path.exists()


def test_gif_frame_rate_is_limited(tmp_path):
    with pytest.raises(OutputError, match="50"):
        check_writable(tmp_path / "fast.gif", 60)


def test_mp4_without_imageio_ffmpeg_says_what_to_install(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "imageio_ffmpeg", None)  # import fails
    with pytest.raises(OutputError, match="pip install imageio-ffmpeg") as error:
        check_writable(tmp_path / "run.mp4", FPS)
    assert ".gif" in str(error.value)
