#!/usr/bin/env python3
"""Check the relative links of the documentation.

Every Markdown link `[text](target)` in README.md, CHANGELOG.md,
host-tests/README.md and docs/*.md whose target is not a URL must name a
file or folder that exists, and, when it has a `#anchor` into a Markdown
file, a heading (GitHub's slug) or an explicit `<a id="...">` of that
file. Links inside code blocks and code spans are not links. Prints each
broken link as `file:line: target (why)` and exits 1 if there is one.
"""

import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
FILES = ["README.md", "CHANGELOG.md", "host-tests/README.md", *sorted(
    str(p.relative_to(ROOT)) for p in (ROOT / "docs").glob("*.md"))]
LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")
FENCE = re.compile(r"^\s*(```|~~~)")
CODE_SPAN = re.compile(r"`[^`]*`")


def slug(heading: str) -> str:
    """GitHub's anchor for a heading: lower case, punctuation dropped,
    spaces made hyphens."""
    text = CODE_SPAN.sub(lambda m: m.group(0)[1:-1], heading.strip())
    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", text).lower()
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def anchors(path: Path, cache={}) -> set:
    if path not in cache:
        found, seen, in_code = set(), {}, False
        for line in path.read_text(encoding="utf-8").splitlines():
            if FENCE.match(line):
                in_code = not in_code
                continue
            if in_code:
                continue
            m = re.match(r"#{1,6}\s+(.*)", line)
            if m:
                s = slug(m.group(1))
                n = seen.get(s, 0)
                seen[s] = n + 1
                found.add(s if n == 0 else f"{s}-{n}")
            found.update(re.findall(r'<a id="([^"]+)"', line))
        cache[path] = found
    return cache[path]


def main() -> int:
    broken = 0
    for name in FILES:
        path = ROOT / name
        if not path.exists():
            continue
        in_code = False
        for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            if FENCE.match(line):
                in_code = not in_code
                continue
            if in_code:
                continue
            for target in LINK.findall(CODE_SPAN.sub("", line)):
                if re.match(r"[a-z][a-z0-9+.-]*:", target):
                    continue  # a URL (https:, mailto:)
                file_part, _, anchor = target.partition("#")
                dest = (path.parent / file_part).resolve() if file_part else path
                why = None
                if not dest.exists():
                    why = "no such file"
                elif anchor and dest.suffix == ".md" and anchor not in anchors(dest):
                    why = "no such anchor"
                if why:
                    print(f"{name}:{number}: {target} ({why})")
                    broken += 1
    return 1 if broken else 0


if __name__ == "__main__":
    sys.exit(main())
