"""The ``whitted`` command: render with the tracer, render on Mitsuba, compare, export.

One module a command (``render.py``, ``compare.py``, ...), each with its options
(``add_parser``) and what it does (``run``), found through :data:`COMMANDS`;
the options several commands share live in ``options.py``, the exit statuses in
``status.py``, what several commands do alike in ``common.py``. A command module
imports the library (whitted.tracer, whitted.reference's role folders) inside
``run``, so that building the parser stays cheap and ``whitted render`` never
imports Mitsuba; nothing below this package imports it.

Every subcommand is a thin layer over a Python function; exit status 0 on
success (for ``compare``: within the scene's tolerance), 1 when a comparison
fails, 2 on bad input (scene, options, output path, missing libLLVM, a job
beyond the limits of tracer/limits.py) or when the operating system refuses a
file or standard output, always with one line on stderr, never a traceback.
Bad input is refused before any rendering; a job that fails later writes
nothing.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys

from whitted.reference.commands.options import Parser
from whitted.reference.commands.status import (
    EXIT_INTERRUPT,
    EXIT_OK,
    EXIT_USAGE,
    Stdout,
    StdoutError,
    caused_by,
    silence_stdout,
)

#: Each command's name and its module in this package, in the order ``--help`` lists them.
COMMANDS = {
    "render": "render",
    "reference": "reference",
    "compare": "compare",
    "export": "export",
    "import": "import_scene",
    "fresnel": "fresnel",
    "report": "report",
    "mutants": "mutants",
    "depth-sweep": "depth_sweep",
    "paths": "paths",
    "assignment": "assignment",
    "check": "check",
    "suite": "suite",
    "formulas": "formulas",
    "scenes": "scenes",
    "schema": "schema",
}


def command_module(name: str):
    """The module of command ``name`` (a key of :data:`COMMANDS`)."""
    return importlib.import_module(f"{__name__}.{COMMANDS[name]}")


class _VersionAction(argparse.Action):
    """``--version``: the installed version, looked up only when asked for.

    Reading the package metadata costs about 25 ms (importlib.metadata), which
    every other command would pay for nothing when building the parser.
    """

    def __init__(self, option_strings, dest=argparse.SUPPRESS, default=argparse.SUPPRESS,
                 help="show the version and exit"):
        super().__init__(option_strings, dest, nargs=0, default=default, help=help)

    def __call__(self, parser, namespace, values, option_string=None):
        print(_version())
        parser.exit()


def _version() -> str:
    from importlib import metadata

    try:
        return f"whitted {metadata.version('whitted')}"
    except metadata.PackageNotFoundError:
        return "whitted (not installed)"


def build_parser() -> argparse.ArgumentParser:
    """The parser of ``whitted``: each command's module adds its subparser, its
    ``run`` the subparser's ``func``."""
    p = Parser(
        prog="whitted",
        description="A Whitted ray tracer on Dr.Jit that proves itself against Mitsuba 3. "
                    "SCENE is a TOML scene file or the name of a built-in scene "
                    "(see `whitted scenes`).",
        epilog="Exit status: 0 success, 1 comparison outside tolerance, 2 bad input or a "
               "file that cannot be written (one line on stderr). Limits on work and memory: "
               "WHITTED_MAX_SAMPLES, WHITTED_MAX_MEMORY, WHITTED_MAX_DEPTH, "
               "WHITTED_MAX_PRIMITIVES, WHITTED_MAX_SCENE_BYTES, WHITTED_LPE_MAX_STATES.")
    p.add_argument("--version", action=_VersionAction)
    sub = p.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in COMMANDS:
        command_module(name).add_parser(sub)
    return p


def main(argv: list[str] | None = None) -> int:
    """Run ``whitted`` with ``argv`` (default: the process's arguments); its exit status."""
    from whitted.tracer.errors import one_line

    # A name that is not UTF-8 reaches Python as surrogates: print them escaped.
    for stream in (sys.stdout, sys.stderr):
        if hasattr(stream, "reconfigure"):
            stream.reconfigure(errors="backslashreplace")

    def fail(message: str) -> int:
        print(f"whitted: error: {one_line(message)}", file=sys.stderr)
        return EXIT_USAGE

    stdout = sys.stdout
    sys.stdout = Stdout(stdout)
    try:
        parser = build_parser()
        try:
            args = parser.parse_args(argv)
        except SystemExit as e:  # --help, --version, or a one-line parser error
            return e.code if isinstance(e.code, int) else EXIT_USAGE
        from whitted.tracer import backend, llvm
        from whitted.tracer.errors import UserError

        try:
            rc = args.func(args)
            sys.stdout.flush()
            return rc
        except (UserError, llvm.LLVMUnavailable, backend.BackendUnavailable) as e:
            return fail(str(e))
    except KeyboardInterrupt:
        print("whitted: interrupted", file=sys.stderr)
        return EXIT_INTERRUPT
    except RuntimeError as e:
        # Ctrl-C while Dr.Jit traces a symbolic loop or branch (Python called back from
        # C++): Dr.Jit re-raises what the callback raised as a RuntimeError caused by it.
        if not caused_by(e, KeyboardInterrupt):
            raise
        print("whitted: interrupted", file=sys.stderr)
        return EXIT_INTERRUPT
    except BrokenPipeError:  # `whitted scenes | head`: the reader has all it wants
        silence_stdout()
        return EXIT_OK
    except StdoutError as e:
        sys.stdout = stdout
        silence_stdout()
        return fail(f"cannot write to standard output: {e}")
    except OSError as e:
        where = f"{e.filename}: " if getattr(e, "filename", None) else ""
        return fail(f"{where}{e.strerror or e}")
    except RecursionError:
        return fail("input nested too deeply to process")
    except MemoryError:
        return fail("out of memory (lower the limits: WHITTED_MAX_MEMORY)")
    finally:
        sys.stdout = stdout


def entrypoint() -> None:
    """The ``whitted`` console script: :func:`main`, then a quick exit.

    When main returns, every file is written and closed and everything worth
    printing is printed. What the interpreter would still do (free each module,
    then Dr.Jit's arrays, thread pool and caches) only delays the shell: about
    35 ms of a 0.5 s `whitted render` (measured from a script that times its own
    steps against /usr/bin/time). So the streams are flushed and the process
    leaves with os._exit; should a flush fail, Python's own exit reports it.
    """
    from whitted.reference.malloc import keep_freed_memory

    keep_freed_memory()
    rc = main()
    try:
        sys.stdout.flush()
        sys.stderr.flush()
    except (OSError, ValueError):
        sys.exit(rc)
    os._exit(rc)
