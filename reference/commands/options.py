"""The options several commands share, and how their values are read.

The argument types (a size, a positive integer), the scene options of the commands
that render one scene, ``--backend``, the thresholds of ``whitted check`` and
``whitted suite check``, and :class:`Parser`, argparse with its errors on one line.
"""

from __future__ import annotations

import argparse

from whitted.reference.commands.status import EXIT_USAGE

#: The longest value an option error echoes whole (a 5000-digit --seed is cut).
ECHO_LIMIT = 60

#: How an 8-bit image may encode light (``--encoding`` of check and suite).
ENCODINGS = ("srgb", "linear", "minray")


def parse_size(text: str) -> tuple[int, int]:
    """``--size``: WIDTHxHEIGHT, both positive."""
    try:
        w, h = text.lower().split("x")
        size = int(w), int(h)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT such as 320x240, got {text!r}") \
            from None
    if size[0] < 1 or size[1] < 1:
        raise argparse.ArgumentTypeError(f"expected a positive size, got {text!r}")
    if max(size) > 2 ** 32 - 1:  # no image side beyond 32-bit indices; not echoed whole later
        raise argparse.ArgumentTypeError(f"expected sides of at most 4,294,967,295 pixels, "
                                         f"got {text!r}")
    return size


def parse_positive(text: str) -> int:
    """A positive integer (``--spp``, ``--max-depth``, ``--depth``)."""
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}")
    return v


def max_depth(args) -> int | None:
    """``--max-depth``, or ``--depth`` in Heckbert's numbering: max_depth = DEPTH + 1."""
    depth = getattr(args, "depth", None)
    if depth is None:
        return args.max_depth
    if args.max_depth is not None:
        from whitted.tracer.errors import UserError

        raise UserError("give either --depth (Heckbert's DEPTH) or --max-depth "
                        "(= DEPTH + 1), not both")
    return depth + 1


def backend_opt(sp, help: str = "Dr.Jit backend") -> None:
    """``--backend``: the Dr.Jit backend (tracer/backend.py chooses it when not given)."""
    sp.add_argument("--backend", choices=("auto", "llvm", "cuda"), default=None, help=help)


def scene_opts(sp, output_help=None, output_required=True, seed=True) -> None:
    """SCENE and the options of a command that renders it: size, samples, depth, backend."""
    sp.add_argument("scene", metavar="SCENE",
                    help="scene file (.toml), built-in name, or Mitsuba 3 scene (.xml)")
    sp.add_argument("--approximate", action="store_true",
                    help="Mitsuba XML: replace what lies outside the Whitted subset (rough "
                         "BSDFs, ...) by its nearest equivalent, warning once per kind")
    if output_help:
        sp.add_argument("-o", "--output", required=output_required, help=output_help)
    sp.add_argument("--spp", type=parse_positive,
                    help="samples per pixel (rounded up to a square)")
    sp.add_argument("--max-depth", type=parse_positive, dest="max_depth",
                    help="path segments, as Mitsuba counts them (2 = direct light)")
    sp.add_argument("--depth", type=parse_positive, dest="depth",
                    help="Heckbert's DEPTH: trace calls (1 = the camera rays' hits "
                         "shaded); the same as --max-depth DEPTH+1")
    sp.add_argument("--size", type=parse_size, metavar="WxH", help="image size, e.g. 320x240")
    backend_opt(sp, "Dr.Jit backend (default: WHITTED_BACKEND or auto: CUDA if there is a "
                    "GPU, else LLVM)")
    if seed:
        sp.add_argument("--seed", type=int, default=0,
                        help="seed of the random numbers (area-light samples, the "
                             "reference's lobe choices): any integer, hashed to 32 bits "
                             "beyond 0..2^32-1")


def threshold_opts(sp) -> None:
    """OpenImageIO idiff's thresholds, as options of ``check`` and ``suite``."""
    g = sp.add_argument_group(
        "thresholds (OpenImageIO idiff's meanings)",
        "A pixel fails when the difference of any channel exceeds the fail threshold; the "
        "image fails when more than --fail-percent of its pixels fail, or when any pixel's "
        "difference exceeds --hard-fail. By default the threshold is statistical (the "
        "Sidak level, about 5 sigma of each pixel's noise) and 0.25 %% of the pixels may "
        "exceed it; --fail replaces it by an absolute difference. Either way the image "
        "must also pass the region sums, which see a small bias over many pixels and "
        "which these options leave as they are. --warn, --warn-percent and --hard-warn "
        "do the same for a warning (exit status 0).")
    for name, what in (("fail", "absolute difference beyond which a pixel fails "
                                "(default: the statistical threshold)"),
                       ("fail-percent", "percentage of pixels allowed to fail (default "
                                        "0.25)"),
                       ("hard-fail", "fail if any pixel's difference exceeds this "
                                     "(default: none)"),
                       ("warn", "absolute difference beyond which a pixel warns (default: "
                                "the statistical threshold)"),
                       ("warn-percent", "percentage of pixels allowed to warn (default 0 "
                                        "once a --warn option is given)"),
                       ("hard-warn", "warn if any pixel's difference exceeds this")):
        g.add_argument(f"--{name}", type=float, default=None, metavar="X", help=what)


def thresholds(args):
    """OpenImageIO idiff's thresholds from the options (None where not given), checked."""
    from whitted.reference.check.judge import Thresholds
    from whitted.tracer.errors import UserError

    th = Thresholds(**{k: getattr(args, k, None) for k in
                       ("fail", "fail_percent", "hard_fail", "warn", "warn_percent", "hard_warn")})
    for k, v in vars(th).items():
        if v is None:
            continue
        opt = "--" + k.replace("_", "-")
        if not v >= 0:
            raise UserError(f"{opt}: expected a number >= 0, got {v}")
        if k.endswith("percent") and v > 100:
            raise UserError(f"{opt}: expected a percentage from 0 to 100, got {v}")
    return th


def shorten(text: str, limit: int = ECHO_LIMIT) -> str:
    """``text`` cut to about ``limit`` characters, its start and end kept and its length
    said: ``'99999...99999' (5,002 characters)``."""
    if len(text) <= limit:
        return text
    keep = max(limit - 3, 2)
    return f"{text[:keep - keep // 3]}...{text[-(keep // 3):]} ({len(text):,} characters)"


class Parser(argparse.ArgumentParser):
    """argparse, with its errors in one line that points to --help (not usage + error);
    each word of the message longer than ECHO_LIMIT (a value echoed back) is shortened."""

    def error(self, message: str):
        import re

        from whitted.tracer.errors import one_line

        message = re.sub(rf"\S{{{ECHO_LIMIT + 1},}}", lambda m: shorten(m.group()),
                         one_line(message, 1 << 20))
        self.exit(EXIT_USAGE, f"{self.prog}: error: {one_line(message)} "
                              f"(see {self.prog} --help)\n")
