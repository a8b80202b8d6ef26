"""The config file of ``fem``'s commands and of the layers above, with ``fem``'s error type.

The file is read by :func:`meshes.configfile.read_config_file`; its errors are raised here as
:class:`ConfigFileError`, an :class:`~fem.exceptions.InvalidParameterError`, which the
commands of ``fem`` and above catch with their other bad parameters.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from fem.exceptions import InvalidParameterError
from meshes import configfile


class ConfigFileError(InvalidParameterError):
    """A config file that cannot be read, is not YAML or holds no mapping of sections."""


def read_config_file(path: str | Path) -> dict[str, Any]:
    """A config file (YAML) as a mapping; a syntax error names its line and column.

    Raises:
        ConfigFileError: for a file that cannot be read, is not YAML (with the line and column
            where the parser stopped), or does not hold a mapping of sections.
    """
    try:
        return configfile.read_config_file(path)
    except configfile.ConfigFileError as err:
        raise ConfigFileError(str(err)) from None


def check_expansion(data: Any, source: str | Path) -> None:
    """Refuse a config whose YAML aliases expand it beyond bounds (an alias bomb).

    :func:`meshes.configfile.check_expansion`, for a mapping read elsewhere (Snakemake reads a
    ``--configfile`` itself).

    Raises:
        ConfigFileError: naming the key whose value expands beyond the limit.
    """
    try:
        configfile.check_expansion(data, source)
    except configfile.ConfigFileError as err:
        raise ConfigFileError(str(err)) from None
