"""Heckbert's minray reproduced: its own images and its own ray counts (tests/data/minray/).

The stored images are what minray prints at DEPTH 1-5, 10 and 20 for 32 x 32
and 256 x 256 pixels (SOURCE.md says how they were made). The tracer must
print the same numbers: at least 99.5 % of the values equal or one step of
255 apart (float32 against minray's double precision rounds a value near
k + 1/2 either way), and every value further apart explained
(:func:`reference.teaching.minray.explain`): it must come out as minray's number
when the tracer's ray offset (rays leave surfaces 1500 float32 ulps of
1 + max |p| off, Mitsuba's RayEpsilon, about 8e-4 here, where minray starts
on the surface in double precision) is made 16 or 2 ulps, i.e. where that
offset moved a ray across a silhouette or a shadow edge of minray's ray
tree, or lie where minray's tree passes such an edge closer than float32
resolves (16 ulps of the scene's extent; none at the stored sizes, 3 values
at 512 x 512 DEPTH 3). The default run checks every depth at 32 x 32 and
DEPTH 3 at 256 x 256; the other 256 x 256 depths are marked slow.
"""

import gzip
import math

import numpy as np
import pytest
from conftest import ROOT, SCENES, run_cli

from whitted.reference.teaching.minray import agreement, explain, ray_count, summary
from whitted.tracer import load_scene
from whitted.tracer.imageio import ppm_values, read_ppm, write_ppm

DATA = ROOT / "tests" / "data" / "minray"
DEPTHS = (1, 2, 3, 4, 5, 10, 20)
#: The share of values that must be equal or one step apart (the required 99.5 %).
WITHIN_ONE = 0.995


def stored(size: int, depth: int) -> np.ndarray:
    return read_ppm(DATA / (f"minray_{size}_depth{depth}.ppm" if size == 32 else
                            f"minray_{size}_depth{depth}.ppm.gz"))


def minray_scene(size: int, depth: int):
    return load_scene(SCENES / "heckbert_minray.toml").with_overrides(size=(size, size),
                                                                      max_depth=depth + 1)


def check_reproduced(size: int, depth: int):
    from whitted.tracer.integrator import Integrator

    s = minray_scene(size, depth)
    ours = ppm_values(Integrator(s).render().image)
    theirs = stored(size, depth)
    a = agreement(ours, theirs)
    assert a.within_one >= WITHIN_ONE, a.line()
    differences = explain(s, depth, theirs, ours)
    assert len(differences) == a.beyond_one
    # Each is caused by the tracer's ray offset: with it made smaller the tracer prints
    # minray's number (the kind says which discontinuity minray's tree passes nearest).
    unexplained = [d for d in differences if d.cause is None]
    assert not unexplained, summary(differences)
    return a


@pytest.mark.parametrize("depth", DEPTHS)
def test_minrays_32_pixel_images_are_reproduced(depth):
    # The same law as at 256 x 256, not "no value beyond one step": values beyond one
    # step come from minray's trees passing a discontinuity within the offset's reach,
    # which at 256 x 256 happens to 0.007 % (DEPTH 1) to 0.11 % (DEPTH 20) of the values,
    # 0.2 to 3.4 of the 3072 values at 32 x 32 on average. At DEPTH 10 and 20 one pixel
    # (3 values) is such a case; with 1024 ulps instead of Mitsuba's 1500 none was, as a
    # count of mean 2.3 is 0 one time in ten.
    check_reproduced(32, depth)


@pytest.mark.parametrize("depth", [pytest.param(d, marks=() if d == 3 else pytest.mark.slow)
                                   for d in DEPTHS])
def test_minrays_256_pixel_images_are_reproduced(depth):
    check_reproduced(256, depth)


def test_minrays_refraction_is_needed_to_reproduce_its_glass():
    # Read with the normal pointing outwards, minray's code would enter glass with
    # n1 / n2 = ir (an inside index of 1 / ir). Rendered so, the DEPTH 3 image is
    # far from minray's: the convention the classic material follows is the one
    # minray's images show.
    from dataclasses import replace

    from whitted.tracer.integrator import Integrator

    s = minray_scene(32, 3)
    glass = s.materials["glass"]
    inverted = replace(s, materials={**s.materials, "glass": replace(glass, ir=1 / glass.ir)})
    a = agreement(ppm_values(Integrator(inverted).render().image), stored(32, 3))
    assert a.within_one < 0.9, a.line()


def test_whitted_render_depth_prints_minrays_numbers(tmp_path):
    out = tmp_path / "out.ppm"
    r = run_cli("render", "heckbert_minray", "--depth", "2", "-o", out)
    assert r.returncode == 0, r.stderr
    assert "DEPTH 2" in r.stdout
    assert read_ppm(out).tolist() == stored(32, 2).tolist()  # exact at DEPTH 2
    assert out.read_text().splitlines()[:3] == ["P3", "32 32", "255"]


# ------------------------------------------------------------------------- PPM


def test_the_ppm_writer_prints_what_minrays_printf_prints(tmp_path):
    # 255 x the value, "%.0f" (round half to even on the exact double), no gamma,
    # no clamp above 255, lines of three numbers, top row first.
    v = np.array([[[0.5 / 255, 1.5 / 255, 2.5 / 255], [0.2, 1.0, 1.5]],
                  [[0.0, 1e-9, 0.999], [np.nan, -0.0, 4.0]]], dtype=np.float32)
    path = tmp_path / "x.ppm"
    write_ppm(path, v)
    expected = [" ".join("%.0f" % (255.0 * float(x)) if x == x and x > 0 else "0"
                         for x in px) for row in v for px in row]
    lines = path.read_text().splitlines()
    assert lines[:3] == ["P3", "2 2", "255"] and lines[3:] == expected
    assert lines[4] == "51 255 382" and lines[6] == "0 0 1020"   # not clamped
    assert read_ppm(path).tolist() == [[[int(x) for x in line.split()] for line in lines[3:5]],
                                       [[int(x) for x in line.split()] for line in lines[5:7]]]


def test_the_ppm_reader_reads_plain_binary_compressed_and_commented_files(tmp_path):
    a = np.arange(12).reshape(2, 2, 3)
    plain = "P3\n# a comment\n2 2 # size\n255\n" + " ".join(map(str, a.ravel())) + "\n"
    (tmp_path / "a.ppm").write_text(plain)
    (tmp_path / "b.ppm.gz").write_bytes(gzip.compress(plain.encode()))
    (tmp_path / "c.ppm").write_bytes(b"P6\n2 2\n255\n" + bytes(a.ravel().tolist()))
    for name in ("a.ppm", "b.ppm.gz", "c.ppm"):
        assert read_ppm(tmp_path / name).tolist() == a.tolist(), name


# -------------------------------------------------------------------- ray counts


def stored_counts() -> dict[tuple[int, int], tuple[list[int], list[int]]]:
    out = {}
    for line in (DATA / "ray_counts.txt").read_text().splitlines():
        if line.startswith("#") or not line.strip():
            continue
        head, trace, shadow = line.split("|")
        size, depth = (int(x) for x in head.split())
        out[(size, depth)] = ([int(x) for x in trace.split()], [int(x) for x in shadow.split()])
    return out


def test_minrays_rays_are_counted_exactly_at_32_pixels():
    counts = stored_counts()
    c = ray_count(minray_scene(32, 20), 20)
    for depth in DEPTHS:
        got = c.at_depth(depth)
        assert (got.trace, got.shadow) == counts[(32, depth)], depth
    # Exponential: the deepest levels grow by a constant factor (about 1.3 here).
    growth = [b / a for a, b in zip(c.trace[-6:], c.trace[-5:], strict=False)]
    assert all(1.2 < g < 1.5 for g in growth), growth


@pytest.mark.parametrize("depth", [pytest.param(5), pytest.param(20, marks=pytest.mark.slow)])
def test_minrays_rays_are_counted_exactly_at_256_pixels(depth):
    c = ray_count(minray_scene(256, depth), depth)
    assert (c.trace, c.shadow) == stored_counts()[(256, depth)]


def test_the_tracer_traces_fewer_rays_than_minray_by_dropping_zero_weights():
    from whitted.tracer.integrator import Integrator

    for depth in (1, 5):
        r = Integrator(minray_scene(32, depth)).render()
        c = ray_count(minray_scene(32, depth), depth)
        # The same camera rays and, at DEPTH 1, the same shadow rays (one per facing light).
        assert r.rays_per_level[0] == c.trace[0] == 32 * 32
        assert r.shadow_rays_per_level[0] == c.shadow[0]
        if depth > 1:
            assert r.rays_total < c.total and sum(r.rays_per_level) < sum(c.trace)
    assert math.isclose(ray_count(minray_scene(32, 1), 1).total, 1024 + 1224)
