"""The hand-written pages' links resolve: every relative link names a file of the checkout, and
every ``#anchor`` a heading of the page it points to (GitHub's heading slugs).

docs/results*.md and docs/leaderboard.md are generated (``make results``) and left out: their prose
comes from docs/results-notes.md, checked here, and a stale link there is fixed by regenerating them.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
GENERATED = {"results.md", "results-ablations.md", "results-runs.md", "results-tuning.md", "leaderboard.md"}
PAGES = sorted(p for p in [ROOT / "README.md", *(ROOT / "docs").glob("*.md")] if p.name not in GENERATED)
LINK = re.compile(r"\]\(([^)\s#]*)(?:#([^)\s]+))?\)")


def slug(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces to hyphens."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def anchors(page: Path) -> set[str]:
    text = re.sub(r"```.*?```", "", page.read_text(), flags=re.S)  # no headings inside code blocks
    return {slug(m.group(1)) for m in re.finditer(r"^#+\s+(.*)$", text, flags=re.M)}


def broken_links(page: Path) -> list[str]:
    problems = []
    for target, anchor in LINK.findall(page.read_text()):
        if re.match(r"[a-z]+:", target):  # https:, mailto:
            continue
        linked = (page.parent / target).resolve() if target else page
        if not linked.exists():
            problems.append(f"{target}: no such file")
        elif anchor and linked.suffix == ".md" and anchor not in anchors(linked):
            problems.append(f"{target}#{anchor}: no such heading in {linked.name}")
    return problems


def test_slug_follows_githubs_rule():
    assert slug("On a GPU machine (a recipe, not yet run)") == "on-a-gpu-machine-a-recipe-not-yet-run"
    assert slug("`fast-tactile` (`tactile`): the paper's terms") == "fast-tactile-tactile-the-papers-terms"


def test_a_broken_link_is_found(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("# Title\n\n[here](#title) [there](#nowhere) [file](missing.md)\n")
    assert broken_links(page) == ["#nowhere: no such heading in page.md", "missing.md: no such file"]


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_the_pages_links_resolve(page):
    assert broken_links(page) == []
