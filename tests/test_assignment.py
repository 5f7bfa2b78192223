"""The first lecture's assignment: Heckbert's scene, the depth sweep, drawn light paths."""

import numpy as np
import pytest
from conftest import SCENES, run_cli

from reference.depth_sweep import parse_depths
from reference.paths import pick_pixels, project, ray_trees
from tracer import load_scene
from tracer.errors import UserError


def test_heckberts_scene_is_his_five_spheres_seen_through_25_degrees():
    s = load_scene(SCENES / "heckbert_minray.toml")
    assert (s.film.width, s.film.height) == (32, 32)
    assert s.camera.fov == 25 and s.camera.origin == (0, 0, 0)
    assert len(s.shapes) == 5 and sum(sh.emitter is not None for sh in s.shapes) == 3
    assert s.film.max_depth == 4  # his DEPTH 3
    text = (SCENES / "heckbert_minray.toml").read_text()
    assert "Fresnel" in text and "what differs" in text.lower()


@pytest.mark.parametrize("text,expected", [("1-5,10,20,25", [1, 2, 3, 4, 5, 10, 20, 25]),
                                           ("3", [3]), ("2,1,2", [1, 2])])
def test_depth_lists_parse(text, expected):
    assert parse_depths(text) == expected


@pytest.mark.parametrize("bad", ["0", "5-1", "a", "1-", ""])
def test_bad_depth_lists_are_refused(bad):
    with pytest.raises(UserError):
        parse_depths(bad)


def test_depth_sweep_writes_runtimes_and_images(tmp_path):
    out = tmp_path / "sweep"
    r = run_cli("depth-sweep", "heckbert_minray", "--depths", "1-3,8", "--repeat", "2",
                "-o", out)
    assert r.returncode == 0, r.stderr
    rows = [line.split() for line in (out / "runtimes.txt").read_text().splitlines()
            if line and not line.startswith("#") and not line.lstrip().startswith("depth")]
    assert [int(row[0]) for row in rows] == [1, 2, 3, 8]
    for row in rows:
        seconds, total, mitsuba = float(row[1]), int(row[2]), float(row[3])
        levels = [int(x) for x in row[4].split(",")]
        assert seconds > 0 and mitsuba > 0
        assert len(levels) == int(row[0]) + 1 and levels[0] == 32 * 32 * 16
        assert total >= sum(levels)
    # More depth never traces fewer rays.
    totals = [int(row[2]) for row in rows]
    assert totals == sorted(totals)
    for d in (1, 2, 3, 8):
        assert (out / f"depth_{d:02d}.png").exists()
    assert (out / "runtimes.png").stat().st_size > 0
    assert "the cost follows the rays" in r.stdout


def test_projection_puts_a_pixels_ray_back_on_that_pixel():
    s = load_scene(SCENES / "heckbert_minray_hd.toml")
    trees = ray_trees(s, [(100, 60)])
    first = trees[0].segments[0]
    xy, front = project(s, np.array([first.a + 0.5 * (first.b - first.a)]))
    assert front[0] and np.allclose(xy[0], [100.5, 60.5], atol=1e-3)


def test_picked_pixels_show_the_paths_asked_for():
    s = load_scene(SCENES / "area_lights.toml")
    picked = pick_pixels(s)
    assert all(picked[e] is not None for e in ("LE", "LDE", "LSE", "LDSE"))
    trees = ray_trees(s, [picked[e] for e in ("LE", "LDE", "LSE", "LDSE")])
    for expr, tree in zip(("LE", "LDE", "LSE", "LDSE"), trees, strict=True):
        assert expr in tree.paths, (expr, tree.paths)


def test_point_lights_cannot_be_seen_so_no_le_pixel_is_picked():
    s = load_scene(SCENES / "sphere_point.toml").with_overrides(size=(40, 30))
    picked = pick_pixels(s)
    assert picked["LE"] is None and picked["LSE"] is None and picked["LDE"] is not None


def test_paths_command_draws_a_figure(tmp_path):
    r = run_cli("paths", "area_lights", "--size", "80x60", "-o", tmp_path / "p.png")
    assert r.returncode == 0, r.stderr
    assert "LDSE: pixel" in r.stdout and "LDDE and LSDE" in r.stdout
    assert (tmp_path / "p.png").stat().st_size > 10_000
    r = run_cli("paths", "area_lights", "--pixel", "500,2", "-o", tmp_path / "q.png")
    assert r.returncode == 2 and "outside" in r.stderr


def test_ray_trees_reach_a_disk_light():
    import tomllib

    from tracer.scene import parse_scene

    text = ("[film]\nwidth = 40\nheight = 30\nspp = 1\nmax_depth = 2\n"
            "[camera]\norigin = [0, 1, 4]\ntarget = [0, 0.3, 0]\n"
            "[materials.m]\ntype = 'diffuse'\n"
            "[[shapes]]\ntype = 'disk'\nemitter = { radiance = 5 }\n"
            "to_world = [ { scale = 0.5 }, { rotate = { axis = [1, 0, 0], angle = 90 } },"
            " { translate = [0, 2, 0] } ]\n"
            "[[shapes]]\ntype = 'rectangle'\nmaterial = 'm'\n"
            "to_world = [ { scale = 3 }, { rotate = { axis = [1, 0, 0], angle = -90 } } ]\n")
    (tree,) = ray_trees(parse_scene(tomllib.loads(text)), [(20, 20)])
    assert "LDE" in tree.paths  # the floor, lit by the disk above it
