"""What every part of the workflow's config parsing shares: its error, and naming the key.

:class:`ConfigError` lists every problem as ``dotted.key: message``; :func:`config_section`
turns a parsing error of one section (a library's ``ValueError``, a missing key) into one that
names the section's dotted key. :mod:`run.config` and the sections it builds from
(:mod:`studies.fe_study.config`, :mod:`studies.surrogate_study.config`) raise it.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

from fem.exceptions import FEError


class ConfigError(ValueError):
    """The configuration is invalid; the message names each offending key (dotted path).

    Attributes:
        problems: one ``dotted.key: message`` (or ``dotted.key message``) per problem.
    """

    def __init__(self, *problems: str) -> None:
        super().__init__(*problems)
        self.problems = problems

    def __str__(self) -> str:
        if len(self.problems) == 1:
            return self.problems[0]
        return f"{len(self.problems)} problems:" + "".join(f"\n  {p}" for p in self.problems)


def _named(key: str, text: str, subkeys: tuple[str, ...] = ()) -> str:
    """``text``, an error of config key ``key``, beginning with its full dotted key.

    The libraries' messages mostly name their key already, from the section down
    ("surrogate.width must ...") or from a sub-section ("geometry.axilla_angle must ..." of
    ``mesh.geometry``, "loading.min_step must ..." of ``fe`` with sub-key ``loading``): those
    are completed, the others prefixed with ``key``.
    """
    if text.startswith(key):
        return text
    parent, _, last = key.rpartition(".")
    if parent and text.startswith(f"{last}."):
        return f"{parent}.{text}"
    if any(text.startswith(f"{sub}.") for sub in subkeys):
        return f"{key}.{text}"
    return f"{key}: {text}"


@contextmanager
def config_section(key: str, subkeys: tuple[str, ...] = ()) -> Iterator[None]:
    """Turn a parsing error of config key ``key`` into a :class:`ConfigError` that names it."""
    try:
        yield
    except ConfigError:
        raise
    except (FEError, ValueError, KeyError, TypeError) as err:
        text = f"missing key {err}" if isinstance(err, KeyError) else str(err)
        raise ConfigError(_named(key, text, subkeys)) from None
