"""The workflow's config file (YAML) read as a mapping, with errors that name the file.

Every command that takes a config file reads it here: the two commands of ``meshes`` through
:func:`meshes.config.read_mesh_config`, and those of ``fem`` and the layers above it through
:mod:`fem.configfile`; the workflow's typed config (:mod:`studies.config`) is built from the
same mapping.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

from meshes.exceptions import MeshInputError


class ConfigFileError(MeshInputError):
    """A config file that cannot be read, is not YAML or holds no mapping of sections."""


def read_config_file(path: str | Path) -> dict[str, Any]:
    """A config file (YAML) as a mapping; a syntax error names its line and column.

    Raises:
        ConfigFileError: for a file that cannot be read, is not YAML (with the line and column
            where the parser stopped), or does not hold a mapping of sections.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as err:
        raise ConfigFileError(f"{path}: cannot read the config file ({err})") from None
    try:
        data = yaml.safe_load(text)
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
    if not isinstance(data, dict):
        raise ConfigFileError(
            f"{path}: a config file is a mapping of sections (mesh:, fe:, sweep:, ...), this "
            f"one holds {type(data).__name__}"
        )
    return data
