"""Typed result files: a frozen dataclass per JSON file that a study writes, one way to write it.

A study's result crosses the workflow as a JSON file and is read back by the report (and by
the tests). Each file has a dataclass in the module that writes it, deriving from
:class:`Result`: :meth:`Result.to_json` gives the JSON-able mapping, :meth:`Result.from_json`
rebuilds the object and checks the mapping against the declared fields, recursively (nested
dataclasses, lists, mappings, optional values), so that a key that is missing or renamed is an
error naming the file and the key, not an "n/a" on the report page. :meth:`Result.write`
writes atomically (a temporary file renamed into place), :meth:`Result.read` reads a file.

A field with a default may be absent from a file (a record that only some runs produce, such
as a skipped variant's reason); every other field must be present, and a key that no field
declares is refused, unless the record is open (a field named ``extras`` keeps such keys).
A field typed ``dict[str, Any]`` or ``Any`` is carried as it is (the solver settings, a
machine description): the report shows it without reading into it.
"""

from __future__ import annotations

import dataclasses
import json
import math
import numbers
import os
import types
import typing
from pathlib import Path
from typing import Any, TypeVar, Union

R = TypeVar("R", bound="Record")

#: A record with a field of this name is open: keys it does not declare are kept there (a
#: file written by a lower layer with keys that depend on the input, such as the mesh's
#: quality report); the declared keys are still required and checked.
EXTRAS = "extras"


class ResultFormatError(ValueError):
    """A result file whose content does not match its declared fields."""


def write_json(path: str | Path, payload: Any) -> None:
    """Write ``payload`` as indented JSON, atomically (a temporary file renamed into place).

    Non-finite floats are written as JSON's ``NaN``/``Infinity`` extensions, which Python's
    reader accepts; numpy scalars are converted.
    """
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = target.with_name(f".{target.name}.{os.getpid()}.tmp")
    tmp.write_text(json.dumps(payload, indent=2, default=_jsonable) + "\n")
    os.replace(tmp, target)


def _jsonable(value: Any) -> Any:
    if hasattr(value, "item"):  # numpy scalar
        return value.item()
    if hasattr(value, "tolist"):  # numpy array
        return value.tolist()
    raise TypeError(f"{type(value).__name__} is not JSON serialisable")


def _convert(tp: Any, value: Any, where: str) -> Any:
    """``value`` (parsed JSON) as type ``tp``, checked; ``where`` names it in errors."""
    if tp is Any:
        return value
    origin = typing.get_origin(tp)
    if origin in (Union, types.UnionType):
        args = typing.get_args(tp)
        if value is None and type(None) in args:
            return None
        inner = [a for a in args if a is not type(None)]
        errors = []
        for arg in inner:
            try:
                return _convert(arg, value, where)
            except ResultFormatError as err:
                errors.append(str(err))
        raise ResultFormatError(errors[0] if len(errors) == 1 else f"{where}: {'; '.join(errors)}")
    if dataclasses.is_dataclass(tp):
        return _from_mapping(tp, value, where)
    if origin in (list, tuple) or tp in (list, tuple):
        if not isinstance(value, list | tuple):
            raise ResultFormatError(f"{where}: expected a list, got {type(value).__name__}")
        args = typing.get_args(tp)
        if origin is tuple and args and args[-1] is not Ellipsis:
            if len(args) != len(value):
                raise ResultFormatError(f"{where}: expected {len(args)} items, got {len(value)}")
            pairs = zip(args, value, strict=True)
            return tuple(_convert(a, v, f"{where}[{i}]") for i, (a, v) in enumerate(pairs))
        item = args[0] if args else Any
        items = [_convert(item, v, f"{where}[{i}]") for i, v in enumerate(value)]
        return tuple(items) if origin is tuple else items
    if origin is dict or tp is dict:
        if not isinstance(value, dict):
            raise ResultFormatError(f"{where}: expected a mapping, got {type(value).__name__}")
        args = typing.get_args(tp)
        item = args[1] if args else Any
        return {k: _convert(item, v, f"{where}.{k}") for k, v in value.items()}
    # numbers as numpy gives them (np.float64, np.int64, np.bool_) become Python's
    is_bool = isinstance(value, bool) or type(value).__name__ == "bool_"
    if tp is float:
        if is_bool or not isinstance(value, numbers.Real):
            raise ResultFormatError(f"{where}: expected a number, got {value!r}")
        return float(value)
    if tp is int:
        if is_bool or not isinstance(value, numbers.Integral):
            raise ResultFormatError(f"{where}: expected an integer, got {value!r}")
        return int(value)
    if tp is bool:
        if not is_bool:
            raise ResultFormatError(f"{where}: expected true or false, got {value!r}")
        return bool(value)
    if tp is str:
        if not isinstance(value, str):
            raise ResultFormatError(f"{where}: expected a string, got {value!r}")
        return value
    raise TypeError(f"{where}: unsupported field type {tp!r}")


def _from_mapping(cls: type, value: Any, where: str) -> Any:
    if not isinstance(value, dict):
        raise ResultFormatError(f"{where}: expected a mapping, got {type(value).__name__}")
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.name != EXTRAS}
    unknown = sorted(set(value) - set(fields))
    kwargs = {}
    if EXTRAS in hints:  # an open record: keys it does not declare are kept as they are
        kwargs[EXTRAS] = {k: value[k] for k in unknown}
        unknown = []
    missing = [name for name, f in fields.items() if name not in value and not _optional(f)]
    if missing or unknown:  # a renamed key is both: say both
        problems = [f"missing key {name!r}" for name in missing]
        if unknown:
            problems.append(f"unknown key(s) {', '.join(unknown)}")
        raise ResultFormatError(
            f"{where}: {'; '.join(problems)} (a {cls.__name__} has {', '.join(fields)})"
        )
    for name in fields:
        if name in value:
            kwargs[name] = _convert(hints[name], value[name], f"{where}.{name}")
    return cls(**kwargs)


def _optional(f: dataclasses.Field) -> bool:
    return f.default is not dataclasses.MISSING or f.default_factory is not dataclasses.MISSING


def _to_jsonable(value: Any) -> Any:
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        # an optional field (one with a default) that is None is left out, as the writers
        # of these files leave out keys that only some runs have
        out = {f.name: _to_jsonable(getattr(value, f.name)) for f in dataclasses.fields(value)
               if f.name != EXTRAS and not (getattr(value, f.name) is None and _optional(f))}
        out.update(_to_jsonable(getattr(value, EXTRAS, None) or {}))
        return out
    if isinstance(value, dict):
        return {k: _to_jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_to_jsonable(v) for v in value]
    return value


@dataclasses.dataclass(frozen=True, slots=True)
class Record:
    """A nested part of a result file: checked by :func:`_from_mapping` like the file itself."""

    def to_json(self) -> dict[str, Any]:
        """The JSON-able mapping (nested records as mappings, tuples as lists)."""
        return _to_jsonable(self)

    @classmethod
    def from_json(cls: type[R], data: Any, where: str | None = None) -> R:
        """Rebuild from a parsed mapping, checking every key.

        Raises:
            ResultFormatError: naming the key that is missing, unknown or of the wrong type.
        """
        return _from_mapping(cls, data, where or cls.__name__)


@dataclasses.dataclass(frozen=True, slots=True)
class Result(Record):
    """A whole result file."""

    def write(self, path: str | Path) -> None:
        """Write the file atomically."""
        write_json(path, self.to_json())

    @classmethod
    def read(cls: type[R], path: str | Path) -> R:
        """Read and check a file written by :meth:`write`.

        Raises:
            ResultFormatError: naming the file and the key that does not match.
        """
        path = Path(path)
        try:
            data = json.loads(path.read_text())
        except json.JSONDecodeError as err:
            raise ResultFormatError(f"{path}: not JSON ({err})") from err
        return _from_mapping(cls, data, str(path))


def finite(value: float | None) -> bool:
    """Whether ``value`` is a finite number (not None, NaN or infinite)."""
    return value is not None and math.isfinite(value)
