"""Snakemake adapter: each variant of the surrogate settings against the selected runs."""

from pathlib import Path

from run.joblog import job_log
from studies.surrogate_study.architecture import (
    ArchitectureTable,
    VariantComparison,
    compare_variants,
    read_run,
)

job_log(snakemake.log[0])

selected = ArchitectureTable.read(snakemake.input.table).selected_architecture
baseline = [read_run(p) for p in snakemake.input.study_runs]
baseline = [r for r in baseline if r["architecture"] == selected]
variants = {}
for path in snakemake.input.variant_runs:
    name = Path(path).parent.parent.name
    variants.setdefault(name, []).append(read_run(path))
result = compare_variants(baseline, variants)
result["architecture"] = selected
VariantComparison.from_json(result).write(snakemake.output[0])
