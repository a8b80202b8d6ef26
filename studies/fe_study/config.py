"""The FE study's config (``fe_study``): the reference, the variants and the sweep's studies.

Parsed from the validated config by :meth:`FEStudyConfig.from_sections`
(:meth:`run.config.WorkflowConfig.from_mapping` calls it).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from meshes.config import size_for_source
from studies.config_errors import config_section
from studies.fe_study.fe_variants import FEVariant, MeshSpec, expand_fe_variants


def default_variant(mesh: Mapping[str, Any], fe: Mapping[str, Any]) -> FEVariant:
    """The FE-study variant that the workflow's own ``mesh`` and ``fe`` sections amount to."""
    disc = fe["discretisation"]
    degree = disc["degree"]
    element = "p1-penalty" if disc["element"] == "p1-penalty" else f"p{degree}p{degree - 1}"
    size = size_for_source(mesh.get("source", "parametric"), mesh["size"])
    return FEVariant(MeshSpec.from_mapping(size), element, fe["solver"], disc["quadrature_degree"])


@dataclass(frozen=True, slots=True)
class FailureEdgesConfig:
    """The sweep's failed cases traced (``fe_study.failure_edges``).

    Traced by :mod:`studies.fe_study.failure_edge`.

    Attributes:
        n: how many failed cases to trace (0: none).
        step_deg: the turn's longest step (degrees).
        resolution_deg: its shortest step before the edge is called (degrees, at most the step).
    """

    n: int
    step_deg: float
    resolution_deg: float

    def __post_init__(self) -> None:
        if self.n < 0:
            raise ValueError(f"n must be 0 or more, got {self.n}")
        if not 0 < self.resolution_deg <= self.step_deg:
            raise ValueError(f"resolution_deg ({self.resolution_deg}) must be positive and at "
                             f"most step_deg ({self.step_deg})")


@dataclass(frozen=True, slots=True)
class StabilityAuditConfig:
    """The sweep's converged cases judged (``fe_study.stability_audit``).

    See :mod:`studies.fe_study.stability_audit`.

    Attributes:
        softest: how many of the sweep's C1 values to audit, softest first (0: none).
        jobs: how many one-core jobs share the audit's cases, side by side.
    """

    softest: int
    jobs: int = 2

    def __post_init__(self) -> None:
        if self.softest < 0:
            raise ValueError(f"softest must be 0 or more, got {self.softest}")
        if self.jobs < 1:
            raise ValueError(f"jobs must be 1 or more, got {self.jobs}")


@dataclass(frozen=True, slots=True)
class FoldSectionConfig:
    """The fold cut with and without self-contact (``fe_study.fold_section``).

    See :mod:`studies.fe_study.fold_section`.

    Attributes:
        cases: the named cases, each (C1 kPa, Φ deg, θ deg).
        largest: how many of the sweep's cases with the largest self-contact force to add.
    """

    cases: tuple[tuple[float, float, float], ...]
    largest: int

    def __post_init__(self) -> None:
        if self.largest < 0:
            raise ValueError(f"largest must be 0 or more, got {self.largest}")
        for case in self.cases:
            if len(case) != 3 or not np.all(np.isfinite(case)) or case[0] <= 0:
                raise ValueError(f"a case is [C1 > 0, Φ] or [C1, Φ, θ], finite; got {case}")

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any]) -> FoldSectionConfig:
        """From the validated section (θ defaults to 0)."""
        return cls(tuple((float(c[0]), float(c[1]), float(c[2]) if len(c) > 2 else 0.0)
                         for c in values["cases"]), int(values["largest"]))


@dataclass(frozen=True, slots=True)
class SkinStudyConfig:
    """What the skin changes (``fe_study.skin``): see :mod:`studies.fe_study.skin`.

    Attributes:
        ratios: the skin's C1 over the fat's, each solved at the default thickness.
        thicknesses: the skin's thicknesses (m), each solved at the default ratio.
        tumour: the point whose prone-to-supine path is followed ([x, y, z] m, the project's
            frame); None: the mesh's volume centroid.
    """

    ratios: tuple[float, ...] = (7.0, 18.5, 100.0)
    thicknesses: tuple[float, ...] = (0.001, 0.0015, 0.0025)
    tumour: tuple[float, float, float] | None = None

    def __post_init__(self) -> None:
        for name, values in (("ratios", self.ratios), ("thicknesses", self.thicknesses)):
            if not all(np.isfinite(v) and v > 0 for v in values):
                raise ValueError(f"{name} must be positive numbers, got {list(values)}")
        if self.tumour is not None and (len(self.tumour) != 3
                                        or not np.all(np.isfinite(self.tumour))):
            raise ValueError(f"tumour is [x, y, z] in m, finite, or null; got {self.tumour}")

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any]) -> SkinStudyConfig:
        """From the validated section."""
        tumour = values["tumour"]
        return cls(tuple(float(r) for r in values["ratios"]),
                   tuple(float(t) for t in values["thicknesses"]),
                   None if tumour is None else tuple(float(x) for x in tumour))


@dataclass(frozen=True, slots=True)
class FEStudyConfig:
    """The FE study (``fe_study``): what is compared with what.

    Attributes:
        reference: the refined discretisation every other one is compared with.
        variants: the speed-accuracy variants, sorted, each once.
        target: the accuracy target of the speed-accuracy study (relative error).
        max_dofs: variants with more unknowns are skipped, not solved.
        convergence_map_mesh: the mesh sizes of the convergence maps.
        failure_edges: how the sweep's failed cases are traced.
        stability_audit: which of the sweep's converged cases are judged for stability.
        fold_section: which cases are cut at the fold with and without self-contact.
        skin: the skin's settings the clinical cases are solved with (:mod:`studies.fe_study.skin`).
        default_variant: the variant the workflow's own mesh and ``fe`` settings amount to.
        base_config: the ``fe``, ``material`` and ``mesh`` sections that the reference and the
            variants depend on, without the default's discretisation and solver preset, which
            each variant sets (so changing those re-solves no study case).
    """

    reference: FEVariant
    variants: tuple[FEVariant, ...]
    target: float
    max_dofs: int
    convergence_map_mesh: MeshSpec
    failure_edges: FailureEdgesConfig
    stability_audit: StabilityAuditConfig
    fold_section: FoldSectionConfig
    skin: SkinStudyConfig
    default_variant: FEVariant
    base_config: dict[str, Any]

    @classmethod
    def from_sections(cls, sections: Mapping[str, Any]) -> FEStudyConfig:
        """Build from the validated config (``fe_study``, ``fe``, ``material``, ``mesh``)."""
        study = sections["fe_study"]
        ref = study["reference"]
        with config_section("fe_study.reference"):
            reference = FEVariant(MeshSpec.from_mapping(ref["mesh"]), ref["element"], ref["solver"],
                                ref["quadrature_degree"])
        with config_section("fe_study.speed_accuracy.variants"):
            variants = tuple(expand_fe_variants(study["speed_accuracy"]["variants"]))
        with config_section("fe_study.convergence_map.mesh"):
            convergence_map_mesh = MeshSpec.from_mapping(study["convergence_map"]["mesh"])
        with config_section("fe_study.failure_edges"):
            edges = study["failure_edges"]
            failure_edges = FailureEdgesConfig(edges["n"], edges["step_deg"],
                                               edges["resolution_deg"])
        with config_section("fe_study.stability_audit"):
            audit = StabilityAuditConfig(study["stability_audit"]["softest"],
                                         study["stability_audit"]["jobs"])
        with config_section("fe_study.fold_section"):
            fold = FoldSectionConfig.from_mapping(study["fold_section"])
        with config_section("fe_study.skin"):
            skin = SkinStudyConfig.from_mapping(study["skin"])
        with config_section("mesh.size"):
            default = default_variant(sections["mesh"], sections["fe"])
        speed_accuracy = study["speed_accuracy"]
        return cls(reference, variants, speed_accuracy["target"], speed_accuracy["max_dofs"],
                   convergence_map_mesh, failure_edges, audit, fold, skin, default,
                   FEVariant.base_config(sections))
