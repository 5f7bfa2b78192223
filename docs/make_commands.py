"""Print docs/commands.md, the command reference, from whitted's own argparse parser.

    python docs/make_commands.py > docs/commands.md

Each command's usage and options come from ``reference.cli.build_parser()``; what a
command does, in a paragraph, and the page's introduction are written here by hand.
``tests/e2e/test_robustness.py`` fails when docs/commands.md is not what this prints, so a
change to an option is followed by running the line above.
"""

from __future__ import annotations

import argparse
import sys
import textwrap
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

WIDTH = 88

INTRO = """\
# The command line

Every command has `--help`, which prints its options as the tables below list them.
This page is generated from the parser by `python docs/make_commands.py > docs/commands.md`; edit
that script (or the options' help, each command's in `reference/commands/<name>.py`), not this page.

`SCENE` is a `.toml` file, the name of a built-in scene (`whitted scenes` lists them),
or a Mitsuba 3 `.xml` scene (read without Mitsuba; see
[Importing Mitsuba scenes](importing.md)).

## Exit status

0 success, 1 a comparison outside its tolerance, 2 bad input (scene, options, paths, no
usable libLLVM, a job beyond the [limits](install.md#limits-and-how-to-change-them)) or
a file, folder or standard output the system cannot write, with one line on stderr
saying why, never a traceback. Bad input is refused before anything renders, and a
command that exits 2 before its outputs are complete leaves none of them (`depth-sweep`
moves its images into the folder only when the sweep has finished; an interrupt,
Ctrl-C, exits 130 the same way). Option errors are one line too, pointing to `--help`.

`tests/e2e/test_fuzz.py` fuzzes the scene loader, the light-path expressions and the command
line with Hypothesis and checks this contract: exit 0 with a finite image, or exit 2
with one line and nothing written. The default run is derandomized and takes about
15 s; `python -m pytest -m slow tests/e2e/test_fuzz.py` runs thousands of random cases,
Mitsuba's commands included (about 2 minutes).

## Common options

`--backend auto|llvm|cuda` (default `WHITTED_BACKEND` or `auto`: CUDA when a GPU
answers, else LLVM on the CPU). Wherever `--max-depth D` is taken, `--depth N`
(Heckbert's DEPTH, trace calls) may stand for `--max-depth N+1`, never both. Progress
bars appear on a terminal. `--seed` takes any integer: 0 to 2^32 - 1 as it is, others
hashed to 32 bits. Wherever SCENE is taken, `--approximate` lets a Mitsuba `.xml` scene
replace what lies outside the Whitted subset by its nearest equivalent, one warning per
kind (see [Importing Mitsuba scenes](importing.md)).
"""

DESCRIPTIONS = {
    "render": """\
Render with the tracer; `-o` ending `.exr` (linear float32 RGB), `.png` (sRGB 8-bit) or
`.ppm` (plain-text P3 with the pixel lines of Heckbert's minray: 255 x linear, rounded
as `%.0f`, no gamma, values above 255 not clamped). `--depth N` is Heckbert's DEPTH
(trace calls), the same as `--max-depth N+1`. `--lpe` keeps only the light on paths
matching a light-path expression. Never touches Mitsuba. Prints the rays traced per
recursion level. Large meshes are read, given vertex normals and a BVH once: the results
are kept in `~/.cache/whitted` (checked data, [docs/safety.md](safety.md#caches)), so
the next render of the same mesh skips that work.
""",
    "reference": """\
Render the converted scene on Mitsuba (`deterministic`: the harness's reference of
`compare`, both lobes, the tracer's light samples of `--seed`; Mitsuba has no light-path
expressions, so there is no `--lpe` here); `--renderer luxcore`: on LuxCoreRender
instead ([LuxCore](luxcore.md)), `spp` jittered samples per pixel.
""",
    "compare": """\
Render both, write `tracer.exr`, `mitsuba.exr`, `diff.png` (false-colour relative
difference with a scale bar) and `metrics.json` (strict JSON: an undefined number is
`null`), print the checks as a table; exit 0 within the scene's tolerance, 1 outside.
The reference ([What is compared, and how strictly](verdicts.md)) is the deterministic
one unless `--reference` says otherwise (`--integrator whitted` still means `onelobe`);
scenes with area lights also get the one-lobe reference's z-test. `direct` is refused
for scenes with mirrors, glass or area lights (their test needs a reference's variance).
`--renderer luxcore`: the tracer, Mitsuba and LuxCore at a small size, each pair judged,
the three-way verdict printed and `luxcore.json` written, exit status the tracer's
against LuxCore; `--renderer all`: the comparison above, then the three-way verdict
(exit status the tracer's against Mitsuba).
""",
    "export": """\
Write the scene as Mitsuba 3 XML (triangles as `meshes/scene_*.obj` beside it, named
after the XML file so that scenes exported into one folder keep their own).
""",
    "import": """\
Read a Mitsuba 3 XML scene and write it as a TOML scene (meshes referenced by paths
relative to the TOML, not copied), with a comment wherever something was approximated;
an element outside the Whitted subset exits 2 naming it and its line, `--approximate`
maps it to its nearest equivalent with one warning per kind; `-D` gives `$NAME`
parameters; `--verify` loads the file with Mitsuba too and checks that the camera and
film agree.
""",
    "fresnel": """\
Fresnel curves, both sides of the boundary: our exact and Schlick against `mi.fresnel`
and Mitsuba's `dielectric` plugin; `fresnel.csv`, `fresnel.png`, `fresnel.json`.
""",
    "mutants": """\
The harness's power check: every bug of the catalog (`reference/mutants.py`, 64
plausible bugs in the lectures' formulas, the scene's reading, the XML importer and the
image writer) switched into the tracer in turn and judged on every scene as `compare`
judges it, and the importer's on Mitsuba's own reading of XML files; prints per bug
the scenes whose verdict fails and by what margin; exit 0 when the tracer as written
passes every scene and every bug is caught, 1 otherwise; `-o` writes `mutants.json`
and `mutants.md` ([Formula bugs the comparison catches](mutants.md)).
""",
    "report": """\
All of the above for every scene, the "imported" group (Mitsuba scenes imported and
compared with Mitsuba's render of the originals; see [Importing Mitsuba
scenes](importing.md)), as `index.html`, `report.md`, `report.json` ([its
schema](report-json.md)), with each scene's light-path decomposition, and the
formula-bug sweep of `whitted mutants` over the same scenes (at its quick sizes in a
`--quick` report; not with `--scenes`, which leaves bugs uncaught).
""",
    "depth-sweep": """\
Render at each DEPTH (Heckbert's numbering, `max_depth` = DEPTH + 1, DEPTH up to 200,
`--repeat` up to 100), timing the tracer and Mitsuba; `depth_NN.png`, `runtimes.txt`,
`runtimes.png` and a plain-words answer to "does runtime deteriorate with depth, and
why".
""",
    "paths": """\
The ray trees of chosen pixels (`--pixel 1,2 3,4`, or the option repeated; at most 64)
drawn over the image, each light path labelled (`LDE`, `LDSE`, ...); without `--pixel`
it picks pixels showing LE, LDE, LSE and LDSE (a scene where none does gets the image
and a note); beside it, where Mitsuba's path tracer finds the LDDE and LSDE paths a
Whitted tracer cannot make.
""",
    "assignment": """\
The first lecture's assignment in one run, under its file names ([The first lecture's
assignment](teaching.md)).
""",
    "scenes": """\
List the built-in scenes.
""",
    "schema": """\
Print (or write) the JSON Schema of the TOML scene format, derived from the loader's own
parsers, for editors: a `#:schema` line at the top of a scene gives completion and
inline errors in TOML language servers such as Taplo / Even Better TOML
([scene-format.md](scene-format.md#editors-the-json-schema-of-this-format)).
""",
    "check": """\
Judge another renderer's image (OpenEXR, PFM, Radiance HDR, PNG, PPM P3/P6) against the
scene's reference ([Is your ray tracer right?](check.md)); writes `diff.png`,
`side_by_side.png`, `reference.exr`, `check.json` and `check.html`, prints a table, and
for a failing image where the difference sits (light paths, materials) and the suspects
(the catalog's formula bugs whose image explains it best; [Naming the
suspect](check.md#naming-the-suspect)); exit 0 agrees, 1 does not, 2 bad input (a size
other than the film's, an unreadable file, not an image).
""",
    "suite": """\
`export`: every built-in scene into DIR as TOML and Mitsuba XML with its reference (EXR,
PNG) and a manifest; `check`: grade a folder of images named after the scenes against
`--suite`'s stored references (or references rendered now): one table, `index.html`,
`suite.json`, a Gradescope autograder `results.json` and a JUnit `junit.xml` for CI,
exit 1 if any scene fails or has no image; `--update` stores the images as the suite's
references unless the run fails.
""",
    "formulas": """\
The catalog at the level of one function ([Testing formulas one at a
time](formulas.md)): each formula's inputs sent to an adapter (a program speaking JSON
lines, or a Python callable), its answers compared with Mitsuba's function or the
tracer's within a stated float32 tolerance; per formula pass or fail, the first failing
input, the expected and given outputs and the catalog bug they match; exit 0 all pass,
1 any fails, 2 the adapter crashed, timed out or answered garbage.
""",
}


def _subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(action.choices)


def _metavar(action: argparse.Action) -> str:
    """The value an option takes, as argparse names it (choices as a|b|c)."""
    if action.nargs == 0:
        return ""
    if action.metavar is not None:
        name = action.metavar if isinstance(action.metavar, str) else " ".join(action.metavar)
    elif action.choices is not None:
        name = "|".join(str(c) for c in action.choices)
    elif action.option_strings:
        name = action.dest.upper()
    else:
        name = action.dest
    if action.nargs == "+":
        return f"{name} [{name} ...]"
    if action.nargs == "*":
        return f"[{name} ...]"
    if action.nargs == "?":
        return f"[{name}]"
    return name


def _usage_item(action: argparse.Action) -> str:
    if not action.option_strings:
        return _metavar(action)
    item = f"{action.option_strings[0]} {_metavar(action)}".strip()
    if isinstance(action, (argparse._AppendAction, argparse._ExtendAction)) and action.nargs != "+":
        item += " ..."
    return item if action.required else f"[{item}]"


def _help(action: argparse.Action, prog: str) -> str:
    """The option's help as `--help` prints it (argparse's %-expansion)."""
    if not action.help or action.help == argparse.SUPPRESS:
        return ""
    params = {k: v for k, v in vars(action).items() if v is not argparse.SUPPRESS}
    params["prog"] = prog
    if params.get("choices") is not None:
        params["choices"] = ", ".join(str(c) for c in params["choices"])
    return action.help % params


def _group_text(text: str, prog: str) -> str:
    """A group's description as `--help` prints it (argparse expands only %(prog))."""
    return text % {"prog": prog} if "%(prog)" in text else text


def _cell(text: str) -> str:
    return " ".join(text.split()).replace("|", "\\|")


def _default(action: argparse.Action) -> str:
    d = action.default
    if d is None or d is False or d is argparse.SUPPRESS or action.nargs == 0:
        return ""
    if isinstance(d, (list, tuple)):
        return "`" + " ".join(str(x) for x in d) + "`"
    return f"`{d}`"


def _usage(name: str, sp: argparse.ArgumentParser) -> str:
    actions = [a for a in sp._actions if not isinstance(a, argparse._HelpAction)]
    # Positionals first, then required options, then the rest, each in the parser's order.
    order = ([a for a in actions if not a.option_strings]
             + [a for a in actions if a.option_strings and a.required]
             + [a for a in actions if a.option_strings and not a.required])
    lines = [f"whitted {name}"]
    for item in (_usage_item(a) for a in order):  # wrapped between items, never inside one
        if len(lines[-1]) + 1 + len(item) > WIDTH:
            lines.append("   ")
        lines[-1] += " " + item
    return "\n".join(lines)


def _table(actions: list[argparse.Action], prog: str) -> list[str]:
    rows = ["| option | default | what it does |", "|---|---|---|"]
    for a in actions:
        mv = _metavar(a)
        names = ", ".join(f"`{(o + ' ' + mv).strip()}`" for o in a.option_strings) \
            if a.option_strings else f"`{mv}`"
        help_ = _help(a, prog)
        if a.required and a.option_strings:
            help_ += " (required)"
        rows.append(f"| {_cell(names)} | {_cell(_default(a))} | {_cell(help_)} |")
    return rows


def _section(name: str, sp: argparse.ArgumentParser) -> list[str]:
    if name not in DESCRIPTIONS:
        raise SystemExit(f"docs/make_commands.py: no description of `whitted {name}`; "
                         "add one to DESCRIPTIONS")
    out = [f"## `whitted {name}`", "", DESCRIPTIONS[name].strip(), ""]
    out += ["```text", _usage(name, sp), "```", ""]
    if sp.description:
        out += [f"`whitted {name} --help` says:", ""]
        out += [textwrap.fill(_group_text(sp.description, sp.prog), WIDTH,
                              break_long_words=False, break_on_hyphens=False), ""]
    for group in sp._action_groups:
        actions = [a for a in group._group_actions if not isinstance(a, argparse._HelpAction)]
        if not actions:
            continue
        if group is sp._positionals:
            title = "Arguments"
        elif group is sp._optionals:
            title = "Options"
        else:
            title = group.title[:1].upper() + group.title[1:]
        out += [f"**{title}**", ""]
        if group.description:
            out += [textwrap.fill(_group_text(group.description, sp.prog), WIDTH,
                                  break_long_words=False, break_on_hyphens=False), ""]
        out += _table(actions, sp.prog) + [""]
    return out


def render() -> str:
    """The text of docs/commands.md."""
    from whitted.reference.cli import build_parser

    parser = build_parser()
    subs = _subcommands(parser)
    out = [INTRO.rstrip(), "", "## Commands", ""]
    out += [f"- [`whitted {n}`](#whitted-{n}): {h}" for n, h in _summaries(parser).items()]
    out.append("")
    top = [a for a in parser._actions
           if a.option_strings and not isinstance(a, argparse._HelpAction)]
    out += ["`whitted` itself takes " + ", ".join(f"`{max(a.option_strings, key=len)}`"
                                                  for a in top)
            + " and prints, under `whitted --help`:", ""]
    if parser.epilog:
        out += ["> " + textwrap.fill(parser.epilog, WIDTH - 2, subsequent_indent="> ",
                                     break_long_words=False, break_on_hyphens=False), ""]
    for name, sp in subs.items():
        out += _section(name, sp)
    return "\n".join(out).rstrip() + "\n"


def _summaries(parser: argparse.ArgumentParser) -> dict[str, str]:
    """Each command's one-line help, as `whitted --help` lists it."""
    action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return {a.dest: a.help or "" for a in action._get_subactions()}


if __name__ == "__main__":
    sys.stdout.write(render())
