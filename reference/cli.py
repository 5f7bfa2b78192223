"""The ``whitted`` command, kept under its older name: the commands live in
:mod:`whitted.reference.commands` (one module a command).

``python -m whitted.reference.cli`` runs the command, and what scripts and tests
import from here (main, build_parser, resolve_scene, the option types, the exit
statuses) is re-exported.
"""

from whitted.reference.commands import COMMANDS, build_parser, entrypoint, main  # noqa: F401
from whitted.reference.commands.common import resolve_scene  # noqa: F401
from whitted.reference.commands.options import (  # noqa: F401
    ECHO_LIMIT,
    Parser,
    shorten,
)
from whitted.reference.commands.options import parse_positive as _positive  # noqa: F401
from whitted.reference.commands.options import parse_size as _size  # noqa: F401
from whitted.reference.commands.status import (  # noqa: F401
    EXIT_FAIL,
    EXIT_INTERRUPT,
    EXIT_OK,
    EXIT_USAGE,
)
from whitted.scenes import SCENES_DIR, builtin_scenes  # noqa: F401

if __name__ == "__main__":
    entrypoint()
