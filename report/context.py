"""What every section reads: the workflow's results, loaded once, and where figures go."""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from fem.dataset import read_case_columns, read_dataset
from fem.self_contact_at_rest import MeshRestPairs
from fem.sweep import ClinicalCase, clinical_list
from report.html import figure
from run.run_log import run_time
from studies.fe_study.convergence_map import ConvergenceMap
from studies.fe_study.corpus import CorpusTable
from studies.fe_study.fe_clinical import FEClinical
from studies.fe_study.fe_speed_accuracy import SpeedAccuracy
from studies.fe_study.fold_section import FoldSections
from studies.fe_study.mesh_quality import MeshQuality
from studies.fe_study.skin import SkinStudy
from studies.fe_study.stability_audit import StabilityAudit
from studies.fe_study.sweep_edges import SweepEdges
from studies.reference_state.reference_roundtrip import RoundTripTable
from studies.reference_state.reference_state import ReferenceRecord
from studies.reference_state.stiffness import StiffnessResult
from studies.reference_state.tracking import TrackingResult
from studies.surrogate_study.architecture import AblationComparison, ArchitectureTable
from studies.surrogate_study.held_out import HeldOutEvaluation
from studies.surrogate_study.off_grid import OffGridEvaluation
from studies.surrogate_study.postures import PostureEvaluation
from studies.surrogate_study.surrogate_benchmark import SurrogateBenchmark
from studies.surrogate_study.surrogate_evaluation import ClinicalEvaluation, Extrapolation
from studies.surrogate_study.warning_coverage import WarningCoverage
from studies.sweep.sweep_estimate import SweepEstimateCheck
from studies.sweep.sweep_rounds import SweepRounds
from surrogate.checkpoint import read_history, read_model_card

log = logging.getLogger(__name__)

#: Input names :func:`build_report` reads (the report rule's named inputs).
INPUT_NAMES = (
    "dataset", "quality", "rest_pairs", "mesh_png", "model", "history", "table2", "ablations",
    "clinical", "extrapolation", "surrogate_benchmark", "clinical_fields", "fe_clinical",
    "fe_speed_accuracy", "fe_convergence_map", "corpus", "reference_roundtrip", "reference_record",
    "tracking", "stiffness", "viewer", "held_out", "postures", "off_grid", "fe_failure_edges",
    "fe_stability_audit", "fe_fold_section", "fe_skin", "warning_coverage", "run_log",
    "sweep_rounds", "sweep_estimate",
)


#: The type of each result file among the inputs (:mod:`studies.results`); the model card and
#: the training history are read by their owner, :mod:`surrogate.checkpoint`.
RESULT_TYPES: dict[str, Callable[[Path], Any]] = {
    "quality": MeshQuality.read,
    "rest_pairs": MeshRestPairs.read,
    "model": lambda path: read_model_card(path.parent),
    "history": lambda path: read_history(path.parent),
    "table2": ArchitectureTable.read,
    "ablations": AblationComparison.read,
    "clinical": ClinicalEvaluation.read,
    "extrapolation": Extrapolation.read,
    "surrogate_benchmark": SurrogateBenchmark.read,
    "fe_clinical": FEClinical.read,
    "fe_speed_accuracy": SpeedAccuracy.read,
    "fe_convergence_map": ConvergenceMap.read,
    "fe_failure_edges": SweepEdges.read,
    "fe_stability_audit": StabilityAudit.read,
    "fe_fold_section": FoldSections.read,
    "fe_skin": SkinStudy.read,
    "corpus": CorpusTable.read,
    "reference_roundtrip": RoundTripTable.read,
    "reference_record": ReferenceRecord.read,
    "stiffness": StiffnessResult.read,
    "held_out": HeldOutEvaluation.read,
    "postures": PostureEvaluation.read,
    "off_grid": OffGridEvaluation.read,
    "warning_coverage": WarningCoverage.read,
    # the adaptive sweep's rounds (absent for a fixed design) and the check of its estimate
    "sweep_rounds": SweepRounds.read,
    "sweep_estimate": SweepEstimateCheck.read,
    # this run's own Snakemake log, up to the report (workflow/scripts/report.py)
    "run_log": run_time,
}


def _read_result(name: str, path: Path | None) -> Any:
    """The typed result at ``path``, or None (with a warning) if it was not given or is absent.

    Raises:
        studies.results.ResultFormatError: if the file does not match its type.
    """
    if path is None:
        return None
    if not path.is_file():
        log.warning("report input %s does not exist", path)
        return None
    return RESULT_TYPES[name](path)


def as_path(value: Any) -> Path | None:
    """A report input (a path or a one-element list of paths) as a Path, or None."""
    if value is None or value == "" or (isinstance(value, (list, tuple)) and not value):
        return None
    if isinstance(value, (list, tuple)):
        value = value[0]
    return Path(str(value))


@dataclass
class Context:
    """What every section builder reads: the loaded inputs and where figures go."""

    out_dir: Path
    clinical: list[ClinicalCase]
    paths: dict[str, Path | None]
    clinical_fields: list[Path]
    results: dict[str, Any] = field(default_factory=dict)
    tracking: list[tuple[str, TrackingResult]] = field(default_factory=list)
    _dataset: Any = None
    _cases: dict[str, np.ndarray] | None = None

    def dataset(self) -> Any:
        """The dataset (:func:`fem.dataset.read_dataset`), read once; None if absent."""
        if self._dataset is None and self.paths.get("dataset") is not None:
            if self.paths["dataset"].is_file():
                self._dataset = read_dataset(self.paths["dataset"])
        return self._dataset

    def case_columns(self) -> dict[str, np.ndarray]:
        """Every per-case column under the dataset's ``/cases``, read once; {} if absent.

        Strings come back as ``str`` arrays. A column an older dataset lacks is simply not
        a key, so each section checks for the columns it needs.
        """
        if self._cases is None:
            self._cases = {}
            path = self.paths.get("dataset")
            if path is not None and path.is_file():
                self._cases = read_case_columns(path)
        return self._cases

    def figure(self, name: str, draw: Callable[[Path], None], alt: str, caption: str) -> str:
        """Draw a figure into the report folder and return its HTML."""
        draw(self.out_dir / name)
        return figure(name, alt, caption)

    def case_label(self, cid: str) -> str:
        """The config's label of a clinical case, or its id."""
        return next((item.label for item in self.clinical if item.case.id == cid), cid)

    @classmethod
    def load(
        cls, inputs: Mapping[str, Any], out_dir: Path, clinical: Sequence[Mapping[str, Any]]
    ) -> Context:
        """Read every result among ``inputs`` (paths by :data:`INPUT_NAMES`) once."""
        fields = inputs.get("clinical_fields") or []
        if isinstance(fields, str | Path):
            fields = [fields]
        ctx = cls(
            out_dir=out_dir,
            clinical=clinical_list(clinical),
            paths={name: as_path(inputs.get(name)) for name in INPUT_NAMES
                   if name not in ("clinical_fields", "tracking")},
            clinical_fields=[Path(str(p)) for p in fields],
        )
        ctx.results = {name: _read_result(name, ctx.paths.get(name)) for name in RESULT_TYPES}
        tracked = inputs.get("tracking") or []
        if isinstance(tracked, str | Path):
            tracked = [tracked]
        ctx.tracking = [(Path(str(p)).stem, TrackingResult.read(Path(str(p))))
                        for p in tracked if Path(str(p)).is_file()]
        return ctx
