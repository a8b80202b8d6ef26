"""A config file read by every command: YAML aliases that expand it beyond bounds are refused.

Nine levels of ten aliases (a "billion laughs") load in milliseconds as shared objects; the
schema's check walked every copy and never ended (issue 70). Each reader must refuse it within
seconds, naming the key.
"""

from __future__ import annotations

import signal
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest
import yaml

from fem.configfile import ConfigFileError as FEConfigFileError
from fem.configfile import read_config_file as fem_read_config_file
from meshes.configfile import ConfigFileError, read_config_file
from run.config import ConfigError, WorkflowConfig
from run.config import read_config_file as studies_read_config_file
from tests.conftest import REPO

pytestmark = pytest.mark.unit

REFUSED = (ConfigFileError, FEConfigFileError, ConfigError)


@contextmanager
def within(seconds: int) -> Iterator[None]:
    """Fail a check that takes longer than ``seconds`` (a walk of the expanded config hangs)."""
    def late(*_: object) -> None:
        raise TimeoutError(f"still reading the config after {seconds} s")

    previous = signal.signal(signal.SIGALRM, late)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


def alias_bomb(levels: int = 9, mapping: bool = False) -> str:
    """The ``sweep`` section as ``levels`` anchors, each ten aliases of the one before."""
    def body(i: int) -> str:
        items = ["lol"] * 10 if i == 0 else [f"*a{i - 1}"] * 10
        if mapping:
            return "{" + ", ".join(f"k{j}: {item}" for j, item in enumerate(items)) + "}"
        return "[" + ", ".join(items) + "]"

    return "sweep:\n" + "".join(f"  a{i}: &a{i} {body(i)}\n" for i in range(levels))


@pytest.mark.parametrize("mapping", [False, True], ids=["lists", "mappings"])
@pytest.mark.parametrize("reader", [read_config_file, fem_read_config_file,
                                    studies_read_config_file],
                         ids=["meshes", "fem", "studies"])
def test_an_alias_bomb_is_refused_quickly_by_every_reader(
    tmp_path: Path, reader, mapping: bool
) -> None:
    path = tmp_path / "bomb.yaml"
    path.write_text(alias_bomb(mapping=mapping))
    with within(10), pytest.raises(
            REFUSED, match=r"bomb\.yaml: sweep\.a4 expands to more than 100000 values"):
        WorkflowConfig.from_mapping(reader(path))


def test_an_alias_bomb_handed_over_as_a_mapping_is_refused_before_the_schema() -> None:
    """Snakemake reads a --configfile itself: the workflow's config object refuses its mapping."""
    bomb = yaml.safe_load(alias_bomb())
    config = {**yaml.safe_load((REPO / "tests" / "config.yaml").read_text()), **bomb}
    with within(10), pytest.raises(ConfigError,
                                   match=r"the config: sweep\.a4 expands to more than"):
        WorkflowConfig.from_mapping(config)


def test_a_config_that_holds_itself_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "loop.yaml"
    path.write_text("sweep:\n  phi_deg: &x [0.0, *x]\n")
    with within(10), pytest.raises(
            REFUSED, match=r"loop\.yaml: sweep\.phi_deg\.1 is a YAML alias of a value that holds"):
        WorkflowConfig.from_mapping(read_config_file(path))


def test_a_config_nested_too_deeply_is_refused_by_name(tmp_path: Path) -> None:
    path = tmp_path / "deep.yaml"
    path.write_text("sweep: " + "[" * 5000 + "]" * 5000 + "\n")
    with pytest.raises(REFUSED, match=r"deep\.yaml: nested too deeply to read"):
        WorkflowConfig.from_mapping(read_config_file(path))


def test_aliases_within_bounds_are_read_as_written(tmp_path: Path) -> None:
    """An anchor used a few times (and one just under the limit) is an ordinary config."""
    path = tmp_path / "anchors.yaml"
    path.write_text("base: &b {width: 8, depth: 2}\nsurrogate_study:\n  ablations:\n"
                    "    a: *b\n    b: *b\n")
    assert read_config_file(path)["surrogate_study"]["ablations"]["b"] == {"width": 8, "depth": 2}
    from meshes.configfile import check_expansion

    check_expansion({"x": [[0] * 999] * 99}, "near the limit")  # 99 × 1000 + 3 values
    with pytest.raises(ConfigFileError, match=r"here: x expands to more than"):
        check_expansion({"x": [[0] * 999] * 101}, "here")
