"""The house stays small enough for a newcomer: no module over 500 lines (issue 60).

A module that grows past it holds more than one concept; split it where the concepts part (a
type that two modules share lives in a module below both: ``tests/test_import_cycles.py``).
"""

from __future__ import annotations

from pathlib import Path

import pytest

pytestmark = pytest.mark.unit

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("meshes", "fem", "surrogate", "studies", "report")
LONGEST_MODULE = 500


def test_no_module_of_the_layers_passes_five_hundred_lines() -> None:
    long = {str(path.relative_to(ROOT)): n for package in PACKAGES
            for path in sorted((ROOT / package).rglob("*.py"))
            if (n := len(path.read_text().splitlines())) > LONGEST_MODULE}
    assert not long, long


def test_each_report_section_lives_in_a_module_named_like_its_page_id() -> None:
    """A reader who sees #scene-needs on the page finds it in report/sections/scene_needs.py."""
    from report.build import SECTIONS

    misplaced = {page_id: builder.__module__ for page_id, _, builder in SECTIONS
                 if builder.__module__ != "report.sections." + page_id.replace("-", "_")}
    assert not misplaced, misplaced
