"""Light-path expressions (Heckbert's notation) and the images they select."""

import itertools
import re

import numpy as np
import pytest
from conftest import SCENES, run_cli

from whitted.tracer import load_scene, render
from whitted.tracer.lpe import LPEError, compile_lpe

EXPRESSIONS = ["LDE", "LDS+E", "LS*E", "L(D|S)*E", "L.*E", "L[DS]E", "LE|LDE", "L(S|D)?S+E"]


@pytest.mark.parametrize("expr", EXPRESSIONS)
def test_matcher_agrees_with_a_regular_expression_engine(expr):
    dfa = compile_lpe(expr)
    for n in range(7):
        for letters in itertools.product("LDSE", repeat=n):
            path = "".join(letters)
            assert dfa.matches(path) == (re.fullmatch(expr, path) is not None), (expr, path)


def test_whitted_paths_have_the_expected_names():
    dfa = compile_lpe("L(D|S)*E")
    assert dfa.matches("LDSSE") and not dfa.matches("LDDS") and not dfa.matches("EDL")
    # The DFA reads the path from the eye, as the tracer builds it.
    assert compile_lpe("LDS+E").matches_reversed("ESSDL")


@pytest.mark.parametrize("bad", ["", "LXE", "L(DE", "L[]E", "LD)E", "L[DQ]E"])
def test_bad_expressions_are_refused(bad):
    with pytest.raises(LPEError):
        compile_lpe(bad)


@pytest.mark.parametrize("name", ["whitted_mix", "area_lights", "heckbert_physical",
                                  "heckbert_minray"])
def test_a_partition_of_the_paths_sums_to_the_full_render(name):
    scene = load_scene(SCENES / f"{name}.toml").with_overrides(size=(48, 32), spp=4)
    full = render(scene).image
    parts = [render(scene, lpe=e).image for e in ("LE", "LS+E", "LDE", "LDS+E")]
    # Summation in a different order: float32 rounding of the per-sample sums only.
    assert np.allclose(sum(parts), full, rtol=1e-5, atol=1e-7)
    # Every path a Whitted tracer makes: the full render, up to the order in which the
    # rays of one sample that reach the same level add into its pixel (scatter-adds
    # from parallel threads; measured on heckbert_minray: 1 ulp in a few pixels, and
    # different from run to run).
    assert np.allclose(render(scene, lpe="L(D|S)*E").image, full, rtol=1e-6, atol=0)


def test_a_whitted_tracer_makes_no_ldde_or_lsde_paths():
    scene = load_scene(SCENES / "area_lights.toml").with_overrides(size=(48, 32), spp=4)
    assert render(scene, lpe="LDDE").image.max() == 0
    assert render(scene, lpe="LSDE").image.max() == 0
    assert render(scene, lpe="LDE").image.max() > 0


def test_cli_renders_one_expression_and_refuses_a_bad_one(tmp_path):
    r = run_cli("render", "area_lights", "--lpe", "LS+E", "-o", tmp_path / "lse.exr",
                "--size", "32x24", "--spp", "4")
    assert r.returncode == 0 and "only paths LS+E" in r.stdout
    r = run_cli("render", "area_lights", "--lpe", "LQE", "-o", tmp_path / "x.exr")
    assert r.returncode == 2 and "light-path expression" in r.stderr
    assert not (tmp_path / "x.exr").exists()
