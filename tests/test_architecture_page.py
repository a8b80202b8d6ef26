"""docs/architecture.md names every module of the layers and every rule file.

The page is the map a newcomer reads to find where a concept lives, and a module it does not
name cannot be found from it. Under "One concept per module" each package has one bullet,
``* **`name/`**: ...``, that names its modules, those of its sub-folders too (``studies/figures``,
``report/sections``, ``report/viewer``), by their stems in backticks (`` `kinematics` ``, or
`` `fe_skin.py` ``); "The workflow" names the rule files of ``workflow/rules/`` the same way. A
stem counts only in its own package's bullet, so `` `config` `` under ``meshes/`` does not name
``run/config.py``.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

pytestmark = pytest.mark.unit

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "architecture.md"
PACKAGES = ("meshes", "fem", "surrogate", "studies", "run", "report", "benchmarks")
"""The layers, bottom up, as the import-linter contract in pyproject.toml lists them."""


def section(text: str, heading: str) -> str:
    """The text under the ``## heading`` up to the next heading of that level."""
    match = re.search(rf"^## {re.escape(heading)}\n(.*?)(?=^## |\Z)", text, re.S | re.M)
    assert match, f"{PAGE.name} has no section '## {heading}'"
    return match.group(1)


def package_bullets(text: str) -> dict[str, str]:
    """Each package's bullet under "One concept per module", by package name."""
    body = section(text, "One concept per module")
    bullets = re.split(r"^\* ", body, flags=re.M)[1:]
    return {m.group(1): bullet for bullet in bullets
            if (m := re.match(r"\*\*`(\w+)/`\*\*", bullet))}


def names(text: str) -> set[str]:
    """Everything the text puts in backticks."""
    return {name.strip() for name in re.findall(r"`([^`]+)`", text)}


def modules(package: str) -> list[Path]:
    """The package's modules, its sub-folders' included, ``__init__.py`` left out."""
    return sorted(p for p in (ROOT / package).rglob("*.py") if p.name != "__init__.py")


def unnamed(files: list[Path], text: str, suffix: str) -> list[str]:
    """Of ``files``, those whose stem (or file name) the text does not put in backticks."""
    named = names(text)
    return [str(f.relative_to(ROOT)) for f in files
            if f.stem not in named and f"{f.stem}{suffix}" not in named]


def missing_modules(text: str, package: str) -> list[str]:
    bullet = package_bullets(text).get(package)
    assert bullet is not None, f"{PAGE.name} has no bullet for `{package}/`"
    return unnamed(modules(package), bullet, ".py")


def missing_rule_files(text: str) -> list[str]:
    rules = sorted((ROOT / "workflow" / "rules").glob("*.smk"))
    return unnamed(rules, section(text, "The workflow"), ".smk")


@pytest.mark.parametrize("package", PACKAGES)
def test_the_architecture_page_names_every_module_of_each_package(package: str) -> None:
    assert modules(package), f"{package}/ has no modules: the test would check nothing"
    missing = missing_modules(PAGE.read_text(), package)
    assert not missing, (f"docs/architecture.md's `{package}/` bullet does not name "
                         f"{missing}: add each with a few words on what it holds")


def test_the_architecture_page_names_every_rule_file() -> None:
    missing = missing_rule_files(PAGE.read_text())
    assert not missing, (f"docs/architecture.md's workflow section does not name {missing}: "
                         "add each with a few words on what it holds")


def test_a_module_dropped_from_its_packages_bullet_is_missed_though_named_in_another() -> None:
    text = PAGE.read_text()
    assert "`kinematics` (pure UFL)" in text and "* **`meshes/`**: " in text
    moved = text.replace("`kinematics` (pure UFL)", "kinematics (pure UFL)").replace(
        "* **`meshes/`**: ", "* **`meshes/`**: `kinematics`, ")
    assert "`kinematics`" in moved
    assert set(missing_modules(moved, "fem")) - set(missing_modules(text, "fem")) == {
        "fem/kinematics.py"}
    workflow = section(text, "The workflow")
    assert "`sweep`" in workflow
    dropped = text.replace(workflow, workflow.replace("`sweep`", "sweep"))
    assert set(missing_rule_files(dropped)) - set(missing_rule_files(text)) == {
        "workflow/rules/sweep.smk"}
