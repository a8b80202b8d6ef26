"""The breast's tissues as their own materials: each a stiffness ratio to the fat's C1.

A mesh's cells carry a tissue tag (:class:`meshes.tags.Tissue`: fat, gland, skin, tumour).
The sweep varies one stiffness, the fat's C1, so the dataset and the surrogate keep one
stiffness parameter; every other tissue is stiffer (or softer) by a fixed ratio
(``material.tissues``), and its neo-Hookean C1 is the ratio times the case's C1. The ratios
enter the forms as one cellwise (DG0) field, so one compiled form serves every case and
every tissue map (:func:`fem.materials.mesh_material.stiffness_field`); a mesh whose cells all
have the ratio 1 keeps the homogeneous forms.

What reads C1, and which value it takes:

* the strain energy: the local value, ratio · C1;
* the iterative solver's pressure preconditioner (the Schur complement's −1/μ M_p): the local
  value, since μ is the local shear modulus;
* the contact penalties (:mod:`fem.contact`, :mod:`fem.self_contact`): the case's C1 (the
  fat's), so that their penetration scales with the sag of the bulk, as before.

The skin is 1–2.5 mm thick and the cells 6–25 mm: a mesh rarely resolves it. Where its cells
carry no skin tag, :class:`SkinLayer` carries it as a membrane on the ``skin`` boundary
(:class:`fem.materials.membrane.Membrane`: the skin's neo-Hookean law over its thickness, in
plane stress), its C1 the skin's ratio times the fat's; where a segmentation labelled the skin's
cells, they carry it and no membrane is added.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from fem.exceptions import InvalidParameterError
from meshes.tags import Tissue

__all__ = ["DEFAULT_RATIOS", "DEFAULT_SKIN_THICKNESS", "SkinLayer", "Tissues",
           "skin_from_mapping", "tissues_from_mapping"]

#: The stiffness ratios to fat that apply where the config names none (docs/tissues.md gives
#: each one's source). A tumour has none: its ratio varies too widely between lesions to
#: assume one, so a mesh with tumour cells must be given it.
DEFAULT_RATIOS: dict[Tissue, float] = {
    Tissue.FAT: 1.0,
    Tissue.GLAND: 2.0,
    Tissue.SKIN: 18.5,
}


@dataclass(frozen=True, slots=True)
class Tissues:
    """Stiffness ratios of the tissues to the fat (``material.tissues``).

    Attributes:
        ratios: tissue → its C1 over the fat's; fat is 1 by definition. Tissues missing from
            the map take :data:`DEFAULT_RATIOS` (a tumour has no default).
    """

    ratios: dict[Tissue, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for tissue, ratio in self.ratios.items():
            if not isinstance(tissue, Tissue):
                raise InvalidParameterError(f"material.tissues: {tissue!r} is not a tissue")
            if tissue is Tissue.FAT and ratio != 1.0:
                raise InvalidParameterError(
                    "material.tissues.fat is 1 by definition: the sweep's C1 is the fat's; "
                    f"got {ratio!r}"
                )
            if not (isinstance(ratio, (int, float)) and math.isfinite(ratio) and ratio > 0):
                raise InvalidParameterError(
                    f"material.tissues.{tissue.label} must be a positive number (its C1 over "
                    f"the fat's), got {ratio!r}"
                )

    def ratio(self, tissue: Tissue) -> float:
        """The tissue's stiffness over the fat's.

        Raises:
            InvalidParameterError: for a tissue with no ratio given and no default (tumour).
        """
        if tissue in self.ratios:
            return float(self.ratios[tissue])
        if tissue in DEFAULT_RATIOS:
            return DEFAULT_RATIOS[tissue]
        raise InvalidParameterError(
            f"the mesh has {tissue.label} cells: give material.tissues.{tissue.label}, its C1 "
            "over the fat's (it has no default)"
        )

    def cell_ratios(self, tags: np.ndarray) -> np.ndarray:
        """The ratio of each cell from its tissue tag.

        Raises:
            InvalidParameterError: for a tag that names no tissue, or a tissue without a ratio.
        """
        tags = np.asarray(tags)
        out = np.ones(len(tags))
        for value in np.unique(tags):
            try:
                tissue = Tissue(int(value))
            except ValueError:
                names = ", ".join(f"{t.value} ({t.label})" for t in Tissue)
                raise InvalidParameterError(
                    f"{int(np.sum(tags == value))} cells carry the tag {int(value)}, which names "
                    f"no tissue; the tissues are {names}"
                ) from None
            out[tags == value] = self.ratio(tissue)
        return out

    def describe(self) -> dict[str, float]:
        """The ratios in force, every tissue that has one (JSON-friendly)."""
        known = {**DEFAULT_RATIOS, **self.ratios}
        return {t.label: float(known[t]) for t in Tissue if t in known}


#: The skin's thickness where the config names none, m (docs/tissues.md).
DEFAULT_SKIN_THICKNESS = 0.0015


@dataclass(frozen=True, slots=True)
class SkinLayer:
    """The skin as a membrane on the ``skin`` boundary (``material.skin``).

    Attributes:
        thickness: the skin's thickness, m (1–2.5 mm in the breast; docs/tissues.md).
        wrinkles: the membrane carries no compression (its relaxed, tension-field energy:
            :class:`fem.materials.membrane.Membrane`); False: it resists compression as a bonded
            solid.
    """

    thickness: float = DEFAULT_SKIN_THICKNESS
    wrinkles: bool = True

    def __post_init__(self) -> None:
        if not (isinstance(self.thickness, (int, float)) and math.isfinite(self.thickness)
                and 0.0 < self.thickness <= 0.01):
            raise InvalidParameterError(
                f"material.skin.thickness must be a number in (0, 0.01] m, got {self.thickness!r}")
        if not isinstance(self.wrinkles, bool):
            raise InvalidParameterError(
                f"material.skin.wrinkles must be true or false, got {self.wrinkles!r}")

    def describe(self, tissues: Tissues) -> dict[str, float | bool]:
        """JSON-friendly: the thickness, the skin's ratio to the fat, whether it wrinkles."""
        return {"thickness": float(self.thickness), "ratio": tissues.ratio(Tissue.SKIN),
                "wrinkles": self.wrinkles}


def skin_from_mapping(values: dict[str, Any] | None) -> SkinLayer | None:
    """:class:`SkinLayer` from ``material.skin`` (None: no skin membrane), naming bad keys."""
    if values is None:
        return None
    if not isinstance(values, dict):
        raise InvalidParameterError(f"material.skin must be a mapping or null, got {values!r}")
    unknown = sorted(set(values) - {"thickness", "wrinkles"})
    if unknown:
        raise InvalidParameterError(f"unknown material.skin key(s): {', '.join(unknown)}; "
                                    "known: thickness, wrinkles")
    thickness = values.get("thickness", DEFAULT_SKIN_THICKNESS)
    if isinstance(thickness, bool) or not isinstance(thickness, (int, float)):
        raise InvalidParameterError(
            f"material.skin.thickness must be a number in (0, 0.01] m, got {thickness!r}")
    return SkinLayer(float(thickness), values.get("wrinkles", True))


def tissues_from_mapping(values: dict[str, Any] | None) -> Tissues:
    """:class:`Tissues` from ``material.tissues`` (tissue name → ratio), naming bad entries."""
    if values is None:
        return Tissues()
    if not isinstance(values, dict):
        raise InvalidParameterError(f"material.tissues must be a mapping, got {values!r}")
    ratios: dict[Tissue, float] = {}
    for name, ratio in values.items():
        try:
            tissue = Tissue.from_label(name)
        except ValueError as err:
            raise InvalidParameterError(f"material.tissues: {err}") from None
        if isinstance(ratio, bool) or not isinstance(ratio, (int, float)):
            raise InvalidParameterError(
                f"material.tissues.{name} must be a positive number, got {ratio!r}")
        ratios[tissue] = float(ratio)
    return Tissues(ratios)
