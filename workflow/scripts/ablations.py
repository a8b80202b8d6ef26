"""Snakemake adapter: each ablation of the surrogate settings against the selected runs."""

from pathlib import Path

from run.joblog import job_log
from studies.surrogate_study.architecture import (
    AblationComparison,
    ArchitectureTable,
    compare_ablations,
    read_run,
)

job_log(snakemake.log[0])

selected = ArchitectureTable.read(snakemake.input.table).selected_architecture
baseline = [read_run(p) for p in snakemake.input.study_runs]
baseline = [r for r in baseline if r["architecture"] == selected]
ablations = {}
for path in snakemake.input.ablation_runs:
    name = Path(path).parent.parent.name
    ablations.setdefault(name, []).append(read_run(path))
result = compare_ablations(baseline, ablations)
result["architecture"] = selected
AblationComparison.from_json(result).write(snakemake.output[0])
