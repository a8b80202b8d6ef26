"""The user's guide and the docs: their links lead somewhere, the results log's contents are whole.

A link into another page of ``docs/`` names a heading by its anchor (GitHub's rule: lower case,
punctuation dropped, spaces to hyphens, a repeated heading numbered ``-1``, ``-2``, ...), and a
heading reworded later breaks it silently; so does a results-log entry missing from the log's
numbered contents, where a reader looks first.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
LOG = ROOT / "docs" / "results-log.md"


def anchor(heading: str) -> str:
    """GitHub's anchor of a Markdown heading's text."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def anchors(page: Path) -> set[str]:
    seen: dict[str, int] = {}
    out = set()
    for heading in re.findall(r"^#{1,6} (.+)$", _prose(page.read_text()), re.M):
        a = anchor(heading)
        n = seen.get(a, 0)
        seen[a] = n + 1
        out.add(a if n == 0 else f"{a}-{n}")
    return out


def _prose(text: str) -> str:
    """The text without its fenced code blocks (a shell comment there is no heading)."""
    return re.sub(r"^```.*?^```", "", text, flags=re.S | re.M)


def local_links(page: Path) -> list[str]:
    links = re.findall(r"\]\(([^)\s]+)\)", _prose(page.read_text()))
    return [link for link in links if not re.match(r"[a-z]+:", link)]


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_local_link_finds_its_file_and_heading(page: Path) -> None:
    broken = []
    for link in local_links(page):
        path, _, fragment = link.partition("#")
        target = (page.parent / path).resolve() if path else page
        if not target.exists():
            broken.append(f"{link}: no such file")
        elif fragment and target.suffix == ".md" and fragment not in anchors(target):
            broken.append(f"{link}: no heading with that anchor in {target.name}")
    assert not broken, f"{page.name}: " + "; ".join(broken)


def test_the_results_logs_contents_list_every_entry_in_order() -> None:
    text = _prose(LOG.read_text())
    entries = re.findall(r"^## (.+)$", text, re.M)
    listed = re.findall(r"^(\d+)\. \[(.+?)\]\(#(.+?)\)$", text, re.M)
    assert [title for _, title, _ in listed] == entries
    assert [int(n) for n, _, _ in listed] == list(range(1, len(entries) + 1))
    assert all(target == anchor(title) for _, title, target in listed)


def test_a_reworded_heading_breaks_its_links(tmp_path: Path) -> None:
    """The check itself: the anchors GitHub gives, and a link to a heading that is gone."""
    page = tmp_path / "page.md"
    page.write_text("# Title\n\n## 2026-11-28: a tumour's way, by FE\n\n## Notes\n\n## Notes\n\n"
                    "```\n# not a heading\n```\n")
    assert anchors(page) == {"title", "2026-11-28-a-tumours-way-by-fe", "notes", "notes-1"}
    other = tmp_path / "other.md"
    other.write_text("[ok](page.md#notes-1) [gone](page.md#not-a-heading) [web](https://x.org)\n")
    assert local_links(other) == ["page.md#notes-1", "page.md#not-a-heading"]
    assert "not-a-heading" not in anchors(page)
