"""The README is a manual: no dated figures in it (they live in docs/results.md), and every
link it gives lands on a file and, where it names one, a heading there."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
README = ROOT / "README.md"
DATE = re.compile(r"\b20\d\d-\d\d-\d\d\b|\b(?:Jan|Feb|Mar|Apr|May|Jun|Jul|Aug|Sep|Oct|Nov|Dec)"
                  r"[a-z]* 20\d\d\b")
LINK = re.compile(r"\]\(([^)#\s]+)(?:#([^)\s]+))?\)")


def slug(heading: str) -> str:
    """A heading's anchor as GitHub makes it: lower case, punctuation dropped, spaces to
    hyphens."""
    kept = re.sub(r"[^\w\- ]", "", heading.strip().lower())
    return kept.replace(" ", "-")


def anchors(path: Path) -> set[str]:
    return {slug(line.lstrip("#")) for line in path.read_text().splitlines()
            if line.startswith("#")}


def test_the_readme_holds_no_date() -> None:
    found = [(n, line) for n, line in enumerate(README.read_text().splitlines(), 1)
             if DATE.search(line)]
    assert not found, f"dated lines in README.md (figures go to docs/results.md): {found}"


def test_every_link_of_the_readme_lands() -> None:
    for target, anchor in LINK.findall(README.read_text()):
        if target.startswith("http"):
            continue
        path = ROOT / target
        assert path.exists(), f"README links to {target}, which does not exist"
        if anchor:
            assert anchor in anchors(path), f"README links to {target}#{anchor}: no such heading"


def test_slugs_are_githubs() -> None:
    assert slug("Learning: `pipeline demo --quick`, the per-fold protocol") == \
        "learning-pipeline-demo---quick-the-per-fold-protocol"
