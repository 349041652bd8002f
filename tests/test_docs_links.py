"""The README and the docs pages link to each other's sections and to files of the repository:
every relative link resolves (the file exists; the #anchor is a heading of that file)."""

from __future__ import annotations

import re
import unicodedata
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
_LINK = re.compile(r"\]\(([^)\s]+)\)")


def _anchor(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces to hyphens."""
    text = heading.strip().lower()
    kept = (c for c in text if c.isalnum() or c in " -_" or unicodedata.category(c).startswith("L"))
    return "".join(kept).replace(" ", "-")


def _anchors(page: Path) -> set[str]:
    out, fence = set(), False
    for line in page.read_text(encoding="utf-8").splitlines():
        if line.startswith("```"):
            fence = not fence
        elif not fence and (m := re.match(r"^#{1,6} (.*)$", line)):
            out.add(_anchor(m.group(1)))
    return out


def _links(page: Path) -> list[str]:
    text, fence, kept = page.read_text(encoding="utf-8"), False, []
    for line in text.splitlines():
        if line.startswith("```"):
            fence = not fence
        elif not fence:
            kept += _LINK.findall(line)
    return [t for t in kept if not re.match(r"^[a-z]+:", t)]


def test_the_anchor_rule_matches_githubs_on_headings_with_punctuation():
    assert _anchor("The fruit's size, and a covariance that tells the truth") == (
        "the-fruits-size-and-a-covariance-that-tells-the-truth"
    )
    assert _anchor("A view that errs ten times its σ") == "a-view-that-errs-ten-times-its-σ"


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.relative_to(ROOT).as_posix())
def test_every_relative_link_of_a_page_resolves(page):
    broken = []
    for target in _links(page):
        path, _, anchor = target.partition("#")
        file = page if not path else (page.parent / path).resolve()
        if not file.exists():
            broken.append(f"{target}: no such file")
        elif anchor and file.suffix == ".md" and anchor not in _anchors(file):
            broken.append(f"{target}: no such heading")
    assert not broken, broken
