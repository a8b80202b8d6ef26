"""The FE study's variants: a mesh size x element x solver preset x quadrature degree.

Each variant has a folder-name id (:attr:`FEVariant.id`) that the workflow uses as a
wildcard and that parses back (:meth:`FEVariant.from_id`), so a variant's result file
names its settings.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

from fem.exceptions import InvalidParameterError
from fem.parameters import Discretisation, SolverSettings

#: Element names of the study and the discretisation each stands for.
ELEMENTS: dict[str, dict[str, Any]] = {
    "p1-penalty": {"element": "p1-penalty"},
    "p2p1": {"element": "taylor-hood", "degree": 2},
    "p3p2": {"element": "taylor-hood", "degree": 3},
}


@dataclass(frozen=True, slots=True)
class MeshSpec:
    """Element sizes (m) and geometric order of a study mesh.

    The rest of the mesh configuration (geometry, grading) is the workflow's.

    ``fold_size`` is the element size over the inframammary fold (``None``: no
    refinement there, whatever the workflow's own mesh asks for).
    """

    global_size: float
    mound_size: float
    order: int = 1
    fold_size: float | None = None

    def __post_init__(self) -> None:
        if not (0 < self.mound_size <= self.global_size):
            raise InvalidParameterError(f"need 0 < mound_size <= global_size, got {self}")
        if self.order not in (1, 2):
            raise InvalidParameterError(f"mesh order must be 1 or 2, got {self.order}")
        if self.fold_size is not None and not 0 < self.fold_size <= self.global_size:
            raise InvalidParameterError(f"need 0 < fold_size <= global_size, got {self}")

    @property
    def id(self) -> str:
        """Folder name, e.g. ``g=0.0150_m=0.0100_o=1`` or ``g=0.0150_m=0.0100_f=0.0040_o=1``."""
        fold = "" if self.fold_size is None else f"_f={self.fold_size:.4f}"
        return f"g={self.global_size:.4f}_m={self.mound_size:.4f}{fold}_o={self.order}"

    @classmethod
    def from_id(cls, mesh_id: str) -> MeshSpec:
        """Parse :attr:`id`."""
        parts = dict(p.split("=") for p in mesh_id.split("_"))
        fold = float(parts["f"]) if "f" in parts else None
        return cls(float(parts["g"]), float(parts["m"]), int(parts["o"]), fold)

    @classmethod
    def from_mapping(cls, values: dict[str, Any]) -> MeshSpec:
        """From a config mapping ``{global_size, mound_size[, order][, fold_size]}``."""
        fold = values.get("fold_size")
        return cls(
            float(values["global_size"]),
            float(values["mound_size"]),
            int(values.get("order", 1)),
            None if fold is None else float(fold),
        )

    def size_mapping(self) -> dict[str, Any]:
        """The ``mesh.size`` entries this spec sets (``fold_size`` always, even if null)."""
        return {
            "global_size": self.global_size,
            "mound_size": self.mound_size,
            "order": self.order,
            "fold_size": self.fold_size,
        }


MESH_ID_PATTERN = r"g=[0-9]+\.[0-9]{4}_m=[0-9]+\.[0-9]{4}(?:_f=[0-9]+\.[0-9]{4})?_o=[12]"
FE_VARIANT_ID_PATTERN = MESH_ID_PATTERN + r"_el=(p1-penalty|p2p1|p3p2)_solver=[a-z-]+_q=[0-9]+"


@dataclass(frozen=True, slots=True)
class FEVariant:
    """One point of the speed-accuracy study.

    Attributes:
        mesh: mesh sizes.
        element: a key of :data:`ELEMENTS`.
        solver: a linear-solver preset of :func:`fem.options.default_parameters`.
        quadrature_degree: 0 for the element's default.
    """

    mesh: MeshSpec
    element: str = "p2p1"
    solver: str = "direct"
    quadrature_degree: int = 0

    def __post_init__(self) -> None:
        if self.element not in ELEMENTS:
            raise InvalidParameterError(
                f"unknown element {self.element!r}; expected one of {sorted(ELEMENTS)}"
            )

    @property
    def id(self) -> str:
        """File name stem, e.g. ``g=0.0150_m=0.0100_o=1_el=p2p1_solver=direct_q=0``."""
        return f"{self.mesh.id}_el={self.element}_solver={self.solver}_q={self.quadrature_degree}"

    @classmethod
    def from_id(cls, variant_id: str) -> FEVariant:
        """Parse :attr:`id`."""
        mesh_part, rest = variant_id.split("_el=")
        element, rest = rest.split("_solver=")
        solver, q = rest.split("_q=")
        return cls(MeshSpec.from_id(mesh_part), element, solver, int(q))

    @staticmethod
    def base_config(config: dict[str, Any]) -> dict[str, Any]:
        """The workflow config sections (``fe``, ``material``, ``mesh``) a variant's solve uses.

        Without the default's element, degree, quadrature and solver preset, which
        :meth:`settings` replaces, so that changing them reruns no study solve.
        """
        fe = {key: value for key, value in config.get("fe", {}).items() if key != "solver"}
        fe["discretisation"] = {
            key: value
            for key, value in fe.get("discretisation", {}).items()
            if key not in ("element", "degree", "quadrature_degree")
        }
        return {"fe": fe, "material": config["material"], "mesh": config["mesh"]}

    def settings(self, base: SolverSettings) -> SolverSettings:
        """``base`` with this variant's element, quadrature and solver preset."""
        disc = Discretisation(
            **{**ELEMENTS[self.element], "quadrature_degree": self.quadrature_degree,
               "bulk_ratio": base.discretisation.bulk_ratio,
               "isochoric": base.discretisation.isochoric}
        )
        return replace(base, discretisation=disc, solver=self.solver)


def expand_fe_variants(entries: list[dict[str, Any]]) -> list[FEVariant]:
    """Cross products of the config's ``fe_study.speed_accuracy.variants`` entries.

    Each entry has ``element`` (one name), ``mesh`` (list of ``{global_size,
    mound_size, order, fold_size}``), ``solver`` (list of presets, default ``[direct]``) and
    ``quadrature_degree`` (list, default ``[0]``).
    """
    out: set[FEVariant] = set()
    for entry in entries:
        for mesh in entry["mesh"]:
            spec = MeshSpec.from_mapping(mesh)
            for solver in entry.get("solver", ["direct"]):
                for q in entry.get("quadrature_degree", [0]):
                    out.add(FEVariant(spec, entry["element"], solver, int(q)))

    def key(v: FEVariant) -> tuple:
        m = v.mesh
        return (m.global_size, m.mound_size, m.order, m.fold_size or 0.0, v.element, v.solver,
                v.quadrature_degree)

    return sorted(out, key=key)
