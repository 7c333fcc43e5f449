"""Large scenes from the command line: --n written as 1e6 or 1_000_000, --area-fraction, the
showcase's box grown with --n, and a too-dense error that names a box and a fraction that fit.
Scenes are made and checked, not simulated."""

import math
import re

import pytest

from circles import cli
from circles.scene import DEFAULT_BOX, Scene, box_for_area_fraction


def prepare(argv, tmp_path):
    return cli._prepare([*argv, "--out", str(tmp_path / "run.gif")], [])


def refused(argv, capsys):
    assert cli.main(argv) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and captured.out == "", captured.err
    return lines[0]


@pytest.mark.parametrize("text, n", [("1e6", 10**6), ("1_000_000", 10**6), ("1000000", 10**6), ("2.5e3", 2500),
                                     ("1E5", 10**5)])
def test_n_is_written_as_people_write_sizes(text, n):
    assert cli.circle_count(text) == n


@pytest.mark.parametrize("text", ["1.5", "1e-3", "many", "inf", "nan"])
def test_n_that_is_no_whole_number_is_refused_in_one_line(text, capsys):
    line = refused(["run", "--n", text], capsys)
    assert "--n" in line and text in line


def test_n_alone_grows_the_showcase_box_and_keeps_its_area_fraction(tmp_path):
    showcase = Scene.from_dict(cli.SHOWCASE_SCENE)
    scene, _ = prepare(["run", "--n", "1e6"], tmp_path)
    assert scene.n == 10**6
    assert scene.area_fraction == pytest.approx(showcase.area_fraction, rel=1e-12)
    assert scene.box[0] / scene.box[1] == pytest.approx(16 / 9, rel=1e-12)
    assert scene.box[0] == pytest.approx(16 * math.sqrt(10**6 / 1500), rel=1e-12)
    # With --box or --radius the box is the user's to choose.
    scene, _ = prepare(["run", "--n", "3000", "--box", "40", "30"], tmp_path)
    assert scene.box == (40.0, 30.0)


def test_area_fraction_sizes_the_box_with_the_aspect_of_box(tmp_path):
    scene, _ = prepare(["run", "--n", "500", "--radius", "0.05", "--area-fraction", "0.3", "--box", "4", "3"],
                       tmp_path)
    assert scene.area_fraction == pytest.approx(0.3, rel=1e-12)
    assert scene.box[0] / scene.box[1] == pytest.approx(4 / 3, rel=1e-12)
    assert scene.box[0] * scene.box[1] == pytest.approx(500 * math.pi * 0.05**2 / 0.3, rel=1e-12)
    scene, _ = prepare(["run", "--n", "500", "--area-fraction", "0.2"], tmp_path)
    assert scene.box[0] / scene.box[1] == pytest.approx(16 / 9, rel=1e-12)
    # A range of radii: the expected area, n pi E[r^2] with E[r^2] = (a^2 + a b + b^2) / 3.
    assert scene.area_fraction == pytest.approx(0.2, rel=1e-12)


@pytest.mark.parametrize("phi", ["0", "-0.1", "0.95", "nan"])
def test_area_fraction_out_of_range_is_refused(phi, capsys):
    line = refused(["run", "--area-fraction", phi], capsys)
    assert "area_fraction" in line and phi.lstrip("-") in line


def test_scene_takes_area_fraction_in_place_of_box(tmp_path):
    scene = Scene(n=200, radius=0.1, area_fraction=0.4)
    assert scene.area_fraction == pytest.approx(0.4, rel=1e-12)
    assert scene.box == pytest.approx(box_for_area_fraction(200, 0.1, 0.4))
    assert scene.box[0] / scene.box[1] == pytest.approx(DEFAULT_BOX[0] / DEFAULT_BOX[1])
    path = tmp_path / "s.toml"
    path.write_text("n = 200\nradius = 0.1\narea_fraction = 0.4\n")
    assert Scene.from_toml(path).box == scene.box
    path.write_text("n = 200\nradius = 0.1\narea_fraction = 0.4\nbox = [10.0, 10.0]\n")
    with pytest.raises(ValueError, match=r"box .* and area_fraction .* both given"):
        Scene.from_toml(path)
    with pytest.raises(ValueError, match=r"box .* and area_fraction .* both given"):
        Scene(n=200, radius=0.1, area_fraction=0.4, box=(10.0, 10.0))


def test_a_scene_file_area_fraction_gives_way_to_box_flag(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text("n = 200\nradius = 0.1\narea_fraction = 0.4\n")
    scene, _ = prepare(["run", str(path), "--box", "12", "12"], tmp_path)
    assert scene.box == (12.0, 12.0)
    scene, _ = prepare(["run", str(path), "--area-fraction", "0.2"], tmp_path)
    assert scene.area_fraction == pytest.approx(0.2, rel=1e-12)


def test_too_dense_names_a_box_and_a_fraction_that_fit(capsys):
    line = refused(["run", "--n", "100000", "--radius", "0.03", "0.08"], capsys)
    match = re.search(r"([\d.]+) x ([\d.]+) holds them at area fraction ([\d.]+)", line)
    assert match, line
    w, h, phi = map(float, match.groups())
    scene = Scene(n=100_000, box=(w, h), radius=(0.03, 0.08))
    assert scene.area_fraction <= phi and scene.area_fraction == pytest.approx(phi, rel=0.01)
    assert w / h == pytest.approx(16 / 9, rel=0.01)


def test_the_first_use_of_a_kernel_set_is_announced_once(tmp_path, monkeypatch):
    import io

    from circles import kernel_cache

    monkeypatch.setenv("TI_OFFLINE_CACHE_FILE_PATH", str(tmp_path / "cache"))
    scene = Scene(n=50, box=(4.0, 3.0), radius=0.1)
    said = io.StringIO()
    assert kernel_cache.announce(scene, "cpu", 0, stream=said)
    assert said.getvalue() == "compiling kernels for this scene; cached for next time\n"
    assert not kernel_cache.announce(Scene(n=80, box=(5.0, 3.0), radius=0.1, seed=4), "cpu", 0, stream=said)
    # Another kind of scene, or other threads, builds other kernels.
    assert kernel_cache.announce(Scene(n=50, box=(4.0, 3.0), radius=(0.05, 0.1)), "cpu", 0, stream=said)
    assert kernel_cache.announce(scene, "cpu", 1, stream=said)
    # A scene large enough to compile with Taichi's CFG pass (backend.compile_for) builds other kernels.
    assert kernel_cache.announce(Scene(n=100_000, box=(100.0, 100.0), radius=0.1), "cpu", 0, stream=said)
    assert not kernel_cache.announce(Scene(n=99_999, box=(100.0, 100.0), radius=0.1), "cpu", 0, stream=said)
    assert said.getvalue().count("compiling") == 4
