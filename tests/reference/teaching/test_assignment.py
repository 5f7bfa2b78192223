"""The first lecture's assignment: Heckbert's scene, the depth sweep, drawn light paths."""

import numpy as np
import pytest
from conftest import SCENES, run_cli

from whitted.reference.teaching.depth_sweep import parse_depths
from whitted.reference.teaching.paths import pick_pixels, project, ray_trees
from whitted.tracer import load_scene
from whitted.tracer.errors import UserError


def test_the_physically_based_version_is_his_five_spheres_seen_through_25_degrees():
    s = load_scene(SCENES / "heckbert_physical.toml")
    assert (s.film.width, s.film.height) == (32, 32)
    assert s.camera.fov == 25 and s.camera.origin == (0, 0, 0)
    assert len(s.shapes) == 5 and sum(sh.emitter is not None for sh in s.shapes) == 3
    assert s.film.max_depth == 4  # his DEPTH 3
    text = (SCENES / "heckbert_physical.toml").read_text()
    assert "Fresnel" in text and "what differs" in text.lower()


def test_heckbert_minray_is_his_five_spheres_in_his_own_model():
    from whitted.tracer.materials.classic import Classic

    s = load_scene(SCENES / "heckbert_minray.toml")
    assert (s.film.width, s.film.height, s.film.spp, s.film.depth) == (32, 32, 1, 3)
    assert s.camera.fov == 25 and s.camera.pixel_offset == (-0.5, -0.5)
    # {centre, colour, radius, kd, ks, kt, kl, ir}, as minray lists them.
    spheres = [((0, 6, .5), (1, 1, 1), .9, .05, .2, .85, 0, 1.7),
               ((-1, 8, -.5), (1, .5, .2), 1, .7, .3, 0, .05, 1.2),
               ((1, 8, -.5), (.1, .8, .8), 1, .3, .7, 0, 0, 1.2),
               ((3, -6, 15), (1, .8, 1), 7, 0, 0, 0, .6, 1.5),
               ((-3, -3, 12), (.8, 1, 1), 5, 0, 0, 0, .5, 1.5)]
    for shape, (c, color, r, kd, ks, kt, kl, ir) in zip(s.shapes, spheres, strict=True):
        m = s.material_of(shape)
        assert isinstance(m, Classic)
        assert (shape.center, shape.radius) == (c, r)
        assert (m.color, m.kd, m.ks, m.kt, m.kl, m.ir) == (color, kd, ks, kt, kl, ir)
        assert m.ambient == (0.02, 0.02, 0.02)
    assert len(s.shape_lights()) == 3                  # every sphere with kl > 0
    assert [light.radiance for light in s.lights] == [(0.02, 0.02, 0.02)]  # missed rays


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
    r = run_cli("depth-sweep", "heckbert_physical", "--depths", "1-3,8", "--repeat", "2",
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
    s = load_scene(SCENES / "heckbert_physical_hd.toml")
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

    from whitted.tracer.scene import parse_scene

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


# ------------------------------------------------------------------ whitted assignment


ASSIGNMENT_FILES = {"heckbert_depth1.png", "heckbert_depth2.png", "heckbert_depth3.png",
                    "heckbert_depth4.png", "heckbert_depth5.png", "heckbert_depth20.png",
                    "heckbert_runtimes1.txt", "heckbert_runtimes1.png", "light_paths.png",
                    "observations.md"}


def test_the_assignment_command_writes_the_assignments_files(tmp_path):
    from PIL import Image

    from whitted.reference.teaching.minray import ray_count
    from whitted.tracer.imageio import ppm_values
    from whitted.tracer.integrator import Integrator

    out = tmp_path / "a1"
    r = run_cli("assignment", "-o", out, "--size", "32", "--depths", "1-5,20", "--repeat", "1")
    assert r.returncode == 0, r.stderr
    assert {p.name for p in out.iterdir()} == ASSIGNMENT_FILES
    assert "DEPTH  20" in r.stdout and "minray traces" in r.stdout

    scene = load_scene(SCENES / "heckbert_minray.toml")
    # The pictures hold the PPM's numbers, unchanged (minray's are the stored images).
    for depth in (1, 2, 3, 4, 5, 20):
        png = np.asarray(Image.open(out / f"heckbert_depth{depth}.png").convert("RGB"))
        ppm = ppm_values(Integrator(scene.with_overrides(max_depth=depth + 1)).render().image)
        assert png.shape == (32, 32, 3) and np.array_equal(png, ppm), depth

    # The runtimes: one row per DEPTH, the tracer's rays and minray's counted ones.
    rows = [line.split() for line in (out / "heckbert_runtimes1.txt").read_text().splitlines()
            if line.strip() and not line.startswith("#") and not line.split()[0] == "depth"]
    assert [int(row[0]) for row in rows] == [1, 2, 3, 4, 5, 20]
    count = ray_count(scene, 20)
    for row in rows:
        depth, seconds, rays, minray = int(row[0]), float(row[1]), int(row[2]), int(row[3])
        result = Integrator(scene.with_overrides(max_depth=depth + 1)).render()
        assert seconds > 0 and rays == result.rays_total
        assert minray == count.at_depth(depth).total
        assert [int(x) for x in row[5].split(",")] == result.rays_per_level
    for name in ("heckbert_runtimes1.png", "light_paths.png"):
        w, h = Image.open(out / name).size
        assert w >= 600 and h >= 300, name

    # The observations quote this run's numbers.
    text = (out / "observations.md").read_text()
    assert f"{count.total:,}" in text and f"{int(rows[-1][2]):,}" in text
    assert "DEPTH 1 to 5" in text and "deteriorate" in text


def test_the_light_paths_figure_names_all_six_paths(tmp_path):
    from whitted.reference.teaching.assignment import light_paths, scene_at
    from whitted.reference.teaching.paths import example_paths, pick_pixels
    from whitted.tracer.imageio import ppm_values
    from whitted.tracer.integrator import Integrator

    scene = scene_at(64, 5)
    picked = pick_pixels(scene, spread=5)
    assert all(picked[e] is not None for e in ("LE", "LDE", "LSE", "LDSE")), picked
    assert len(set(picked.values())) == 4
    examples = example_paths(scene)
    assert examples["LDDE"].paths == ["LDDE"] and examples["LSDE"].paths[0].endswith("SDE")
    # Their segments: eye -> x, then x -> y -> light (LDDE) or x -> mirror/glass -> light.
    assert [s.kind for s in examples["LDDE"].segments] == ["camera", "indirect", "indirect"]
    picture = ppm_values(Integrator(scene).render().image)
    path = light_paths(tmp_path / "lp.png", 64, picture, mitsuba=False)
    assert path.stat().st_size > 10_000


def test_the_assignment_refuses_depths_that_miss_its_questions(tmp_path):
    r = run_cli("assignment", "-o", tmp_path / "x", "--depths", "1-3")
    assert r.returncode == 2 and "5 or more" in r.stderr
