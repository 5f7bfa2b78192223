"""``whitted scenes``: list the built-in scenes (the registry :mod:`whitted.scenes`)."""

from __future__ import annotations

from whitted.reference.commands.common import film_summary
from whitted.reference.commands.status import EXIT_OK
from whitted.scenes import builtin_scenes


def add_parser(sub) -> None:
    s = sub.add_parser("scenes", help="list the built-in scenes")
    s.set_defaults(func=run)


def run(args) -> int:
    from whitted.tracer import load_scene

    for p in builtin_scenes():
        s = load_scene(p)
        print(f"{p.stem:<24} {film_summary(s):<44} {s.description}")
    return EXIT_OK

