"""The workflow's config file (YAML) read as a mapping, with errors that name the file.

Every command that takes a config file reads it here: the two commands of ``meshes`` through
:func:`meshes.config.read_mesh_config`, and those of ``fem`` and the layers above it through
:mod:`fem.configfile`; the workflow's typed config (:mod:`run.config`) is built from the
same mapping.

YAML's aliases let a few lines stand for a billion values (nine levels of ten aliases): PyYAML
builds them as shared objects at once, but anything that walks the config (the schema's check,
Snakemake's merge of config files) walks every copy and never ends. :func:`check_expansion`
counts the values with every alias written out, each shared object once, and refuses a config
over :data:`MAX_VALUES` before anything walks it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

from meshes.exceptions import MeshInputError

MAX_VALUES = 100_000
"""The most values (mappings, lists, keys and scalars) a config may hold with its YAML aliases
written out. The study's own config holds about a thousand; the schema checks 10^5 in about a
second, and an alias bomb expands to 10^9 and more."""


class ConfigFileError(MeshInputError):
    """A config file that cannot be read, is not YAML or holds no mapping of sections."""


def check_expansion(data: Any, source: str | Path) -> None:
    """Refuse a config whose YAML aliases expand it beyond :data:`MAX_VALUES`, or into itself.

    Each shared object (an anchor's value) is counted once and its size reused, so the check
    takes as long as the file's own nodes, whatever they expand to.

    Args:
        data: the config as read (a mapping from :func:`read_config_file`, or from Snakemake).
        source: the file (or words for where the mapping came from), for the message.

    Raises:
        ConfigFileError: naming the key whose value expands beyond the limit, or that holds
            itself.
    """
    sizes: dict[int, int] = {}
    open_: set[int] = set()

    def size(value: Any, where: tuple[str, ...]) -> int:
        if not isinstance(value, (dict, list)):
            return 1
        known = sizes.get(id(value))
        if known is not None:
            return known
        key = ".".join(where) or "the top level"
        if id(value) in open_:
            raise ConfigFileError(f"{source}: {key} is a YAML alias of a value that holds it: "
                                  "the config would be endless")
        open_.add(id(value))
        is_map = isinstance(value, dict)  # a mapping's keys are values too
        total = 1
        for name, item in value.items() if is_map else enumerate(value):
            total += is_map + size(item, (*where, str(name)))
            if total > MAX_VALUES:
                raise ConfigFileError(
                    f"{source}: {key} expands to more than {MAX_VALUES} values once its YAML "
                    "aliases are written out (an alias bomb?); a config holds a few thousand")
        open_.discard(id(value))
        sizes[id(value)] = total
        return total

    try:
        size(data, ())
    except RecursionError:
        raise ConfigFileError(f"{source}: nested too deeply to read") from None


def read_config_file(path: str | Path) -> dict[str, Any]:
    """A config file (YAML) as a mapping; a syntax error names its line and column.

    Raises:
        ConfigFileError: for a file that cannot be read, is not YAML (with the line and column
            where the parser stopped), does not hold a mapping of sections, or whose aliases
            expand it beyond :data:`MAX_VALUES` (:func:`check_expansion`).
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as err:
        raise ConfigFileError(f"{path}: cannot read the config file ({err})") from None
    try:
        data = yaml.safe_load(text)
    except RecursionError:
        raise ConfigFileError(f"{path}: nested too deeply to read") from None
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        words = [getattr(err, "context", None), getattr(err, "problem", None)]
        what = ", ".join(w for w in words if w) or str(err)
        syntax = (yaml.scanner.ScannerError, yaml.parser.ParserError)
        kind = "syntax error" if isinstance(err, syntax) else "error"
        raise ConfigFileError(f"{path}: YAML {kind}{where}: {what}") from None
    if data is None:
        raise ConfigFileError(f"{path}: the config file is empty")
    check_expansion(data, path)
    if not isinstance(data, dict):
        raise ConfigFileError(
            f"{path}: a config file is a mapping of sections (mesh:, fe:, sweep:, ...), this "
            f"one holds {type(data).__name__}"
        )
    return data
