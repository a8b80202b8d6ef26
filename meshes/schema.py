"""The config's JSON schema (``workflow/schemas/config.schema.yaml``) and its check.

One check for every entry point that takes a config: the workflow's typed config
(:mod:`run.config`), and the commands of the lower layers that read only their own section
(``python -m meshes.preview`` checks the ``mesh`` section by it, so that it refuses what the
run would refuse). Besides the schema, a NaN or an infinity anywhere is refused: it passes
every bound of a schema.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import jsonschema
import numpy as np
import yaml

SCHEMA_PATH = Path(__file__).resolve().parent.parent / "workflow" / "schemas" / "config.schema.yaml"


def load_schema(path: str | Path = SCHEMA_PATH) -> dict[str, Any]:
    """The JSON schema of the configuration (YAML)."""
    return yaml.safe_load(Path(path).read_text())


def _specific(error: jsonschema.ValidationError) -> list[jsonschema.ValidationError]:
    """The errors that say what is wrong, for an error of a ``oneOf``/``anyOf`` alternative.

    A value that fits none of the alternatives fails each of them; the alternatives of the
    value's own type (a list for a list of C1 values) name the item at fault, e.g.
    ``sweep.C1_kPa.1``, and the others only say that the type differs.
    """
    if not error.context:
        return [error]
    fitting = [e for e in error.context if not (e.validator == "type" and not e.relative_path)]
    return [s for e in fitting for s in _specific(e)] or [error]


#: Said beside a whole section missing: a user who wrote only the sections she changed.
STANDS_ALONE = (" (a config file stands alone, nothing is taken from config.yaml: start from a "
                "copy of it and change what you need)")


#: Keys a config of an earlier version may still hold, with what replaced them: a config
#: that holds one is told the new name, not only that the key is unexpected.
RENAMED_KEYS: dict[str, str] = {
    "fe_study.stability": "renamed fe_study.convergence_map (the map of where Newton fails)",
    "surrogate_study.variants": "renamed surrogate_study.ablations (one setting undone each)",
    "sweep.refine": ("removed: the adaptive sweep (sweep.adaptive) adds directions where its "
                     "estimate of the surrogate's error is largest"),
}


def renamed_keys(config: Mapping[str, Any]) -> list[str]:
    """``'dotted.key: renamed ...'`` for every key of :data:`RENAMED_KEYS` that ``config`` holds."""
    found = []
    for dotted, what in RENAMED_KEYS.items():
        section, _, key = dotted.partition(".")
        value = config.get(section)
        if isinstance(value, Mapping) and key in value:
            found.append(f"{dotted}: {what}")
    return found


def _only_renamed_keys(error: jsonschema.ValidationError) -> bool:
    """Whether ``error`` is an unexpected key that :func:`renamed_keys` names better."""
    if error.validator != "additionalProperties" or not isinstance(error.instance, Mapping):
        return False
    where = ".".join(map(str, error.absolute_path))
    extra = set(error.instance) - set(error.schema.get("properties", {}))
    return bool(extra) and all(f"{where}.{key}" in RENAMED_KEYS for key in extra)


def schema_errors(config: Mapping[str, Any], schema: dict[str, Any]) -> list[str]:
    """Every schema violation of ``config`` as ``'dotted.key: message'``, sorted by key.

    An item of a list is named by its index (``sweep.C1_kPa.1: -2.0 is less than or equal to
    the minimum of 0``), not the whole list.
    """
    validator = jsonschema.Draft202012Validator(schema)
    errors = [s for e in validator.iter_errors(config) for s in _specific(e)
              if not _only_renamed_keys(s)]
    errors.sort(key=lambda e: [str(p) for p in e.absolute_path])
    return [f"{'.'.join(map(str, e.absolute_path)) or '<top level>'}: {e.message}"
            + (STANDS_ALONE if e.validator == "required" and not e.absolute_path else "")
            for e in errors] + sorted(_non_finite(config)) + renamed_keys(config)


def _non_finite(value: Any, where: tuple[str, ...] = ()) -> Iterator[str]:
    """``'dotted.key: nan is not a finite number'`` for every NaN or infinity in ``value``.

    The schema's bounds do not hold them off: a comparison with NaN is never false.
    """
    if isinstance(value, Mapping):
        for key, item in value.items():
            yield from _non_finite(item, (*where, str(key)))
    elif isinstance(value, list | tuple):
        for index, item in enumerate(value):
            yield from _non_finite(item, (*where, str(index)))
    elif isinstance(value, float) and not np.isfinite(value):
        yield f"{'.'.join(where) or '<top level>'}: {value} is not a finite number"
