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
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
LOG = ROOT / "docs" / "results-log.md"
TOPICS = sorted((ROOT / "docs" / "results-log").glob("*.md"))
LONGEST_PAGE = 1000
"""Lines a page of ``docs/`` may hold: a results-log topic that passes it is split."""


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
    """The log's contents number every entry of its topic files once, in each file's order."""
    listed = re.findall(r"^(\d+)\. \[(.+?)\]\((results-log/[\w\-]+\.md)#(.+?)\)$",
                        _prose(LOG.read_text()), re.M)
    assert [int(n) for n, *_ in listed] == list(range(1, len(listed) + 1))
    assert all(target == anchor(title) for _, title, _, target in listed)
    assert TOPICS
    for topic in TOPICS:
        entries = re.findall(r"^## (.+)$", _prose(topic.read_text()), re.M)
        named = [title for _, title, path, _ in listed if path == f"results-log/{topic.name}"]
        assert named == entries, topic.name


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_no_page_of_the_docs_passes_a_thousand_lines(page: Path) -> None:
    assert len(page.read_text().splitlines()) <= LONGEST_PAGE


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


def test_the_readme_stays_a_guide_of_at_most_three_hundred_lines() -> None:
    """Reference detail belongs to a page of ``docs/`` that the README links (issue 60)."""
    assert len((ROOT / "README.md").read_text().splitlines()) <= 300


def test_the_readme_links_every_page_of_the_docs() -> None:
    linked = {link.partition("#")[0] for link in local_links(ROOT / "README.md")}
    pages = {f"docs/{page.name}" for page in (ROOT / "docs").glob("*.md")}
    assert pages <= linked, sorted(pages - linked)
