"""Check that every relative link in README.md, docs/*.md and benchmarks/*.md points to a
file, and to a heading of it where the link names one (GitHub's anchors).

    python docs/check_links.py [ROOT]

Prints each broken link and exits 1 if there is one.
"""

import re
import sys
from pathlib import Path


def slug(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces as hyphens."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def _prose(path: Path) -> str:
    return re.sub(r"```.*?```", "", path.read_text(), flags=re.S)


def anchors(path: Path) -> set[str]:
    seen: dict[str, int] = {}
    out = set()
    for m in re.finditer(r"^#{1,6} (.*)$", _prose(path), re.M):
        s = slug(m.group(1))
        n = seen.get(s, 0)
        seen[s] = n + 1
        out.add(s if n == 0 else f"{s}-{n}")
    return out


def broken_links(root: Path) -> list[str]:
    pages = [root / "README.md", *sorted((root / "docs").glob("*.md")),
             *sorted((root / "benchmarks").glob("*.md"))]
    bad = []
    for page in pages:
        for m in re.finditer(r"\]\(([^)\s]+)\)", _prose(page)):
            target = m.group(1)
            if re.match(r"[a-z]+:", target):
                continue
            file, _, anchor = target.partition("#")
            dest = (page.parent / file).resolve() if file else page
            if not dest.exists():
                bad.append(f"{page}: no file {target}")
            elif anchor and dest.suffix == ".md" and anchor not in anchors(dest):
                bad.append(f"{page}: no heading {target}")
    return bad


if __name__ == "__main__":
    problems = broken_links(Path(sys.argv[1] if len(sys.argv) > 1 else "."))
    print("\n".join(problems) or "every relative link resolves")
    sys.exit(1 if problems else 0)
