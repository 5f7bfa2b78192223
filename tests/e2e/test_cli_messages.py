"""Option errors echo a long value cut to about ECHO_LIMIT characters, in one short line."""

import pytest

from whitted.reference.cli import ECHO_LIMIT, main, shorten


def test_shorten_keeps_short_text_and_cuts_long_text_keeping_both_ends():
    assert shorten("x" * ECHO_LIMIT) == "x" * ECHO_LIMIT
    cut = shorten("1" + "5" * 4998 + "9")
    assert cut.startswith("15") and "...5" in cut and cut.endswith("9 (5,000 characters)")
    assert len(cut) < ECHO_LIMIT + 25


@pytest.mark.parametrize("option, value", [
    ("--seed", "9" * 5000),               # an int beyond Python's 4300 digits
    ("--size", "1" * 300 + "x2"),         # a side beyond 32-bit indices
    ("--size", "1" * 5000 + "x2"),
    ("--backend", "z" * 300),             # an invalid choice
])
def test_a_long_option_value_is_echoed_cut_in_one_short_line(capsys, tmp_path, option, value):
    code = main(["render", "sphere_point", "-o", str(tmp_path / "x.png"), option, value])
    err = capsys.readouterr().err
    assert code == 2
    assert err.count("\n") == 1 and len(err) < 250, err
    assert f"({len(value) + 2:,} characters)" in err   # the value as echoed: quoted
    assert not list(tmp_path.iterdir())
