"""The surrogate's structures, one module each, chosen by name once: :func:`structure_for`.

A structure is how a model maps a material point and a case (C1, ĝ) to a displacement, and
everything that follows from it: its networks and their parameters, its forward pass, how it
trains, what its checkpoint holds beside the weights and what the web page's forward pass
reads (the interface, :class:`surrogate.structures.base.Structure`):

* :mod:`~surrogate.structures.pointwise`: the paper's, each network maps a point and the
  case to its displacement;
* :mod:`~surrogate.structures.separable`: point networks give ``modes`` fields of the point
  alone, a branch network weighs them per case;
* :mod:`~surrogate.structures.pod`: the fields are the training data's own POD modes, and the
  branch weighs them.

This module is the registry and stays light: :class:`surrogate.config.SurrogateConfig` reads
the names and the rules a config must keep from :data:`STRUCTURES` without importing JAX; a
structure's own module is imported when a model of it is first built. A new structure is a
module here, its entry in :data:`STRUCTURES`, the schema's enum
(``workflow/schemas/config.schema.yaml``) and the web page's forward pass
(``report/viewer/app.js``).
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from functools import cache
from typing import Any

# The registry imports no module of the package, not even for its types: the config reads it
# (surrogate.config), and the structures' code reads the config and the modules that call
# structure_for (checkpoint, predict, export), so a type import here would close a circle.


@dataclass(frozen=True)
class Entry:
    """A structure as the registry knows it: where its class is, the settings it refuses.

    Attributes:
        cls: ``module:Class`` of its :class:`~surrogate.structures.base.Structure`, the module
            under :mod:`surrogate.structures`.
        refused_boundaries: ``surrogate.boundary`` modes that do not apply to it.
        refusal: why, as the config's error says it after the structure's name.
        point_features: whether its point networks take Fourier features
            (``surrogate.point_features``).
    """

    cls: str
    refused_boundaries: tuple[str, ...] = ()
    refusal: str = ""
    point_features: bool = False


STRUCTURES: dict[str, Entry] = {
    "pointwise": Entry("pointwise:Pointwise"),
    "separable": Entry("separable:Separable", point_features=True),
    "pod": Entry("pod:Pod", refused_boundaries=("exact",),
                 refusal="(its modes vanish on the rib as the FE fields do); leave boundary at "
                         "network"),
}
"""Every structure by its name in ``surrogate.structure``."""


@cache
def structure_class(name: str) -> Any:
    """The class of the structure ``name`` (its module imported on first use).

    A subclass of :class:`surrogate.structures.base.Structure`.

    Raises:
        ValueError: if no structure has that name.
    """
    try:
        module, cls = STRUCTURES[name].cls.split(":")
    except KeyError:
        raise ValueError(f"no surrogate structure is named {name!r}: one of "
                         f"{tuple(STRUCTURES)}") from None
    return getattr(importlib.import_module(f"{__name__}.{module}"), cls)


@cache
def structure_for(config: Any) -> Any:
    """The structure of a model of ``config``, bound to it (one object per config).

    ``config`` is a :class:`surrogate.config.SurrogateConfig`; the answer a
    :class:`surrogate.structures.base.Structure`.

    Hashable, as the config is: jitted code takes the config as a static argument and asks for
    its structure while it traces, so that the choice is made in Python, once per compilation.
    """
    return structure_class(config.structure)(config)
