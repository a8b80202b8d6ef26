"""Snakemake adapter: the surrogate's goals measured in one job, FE and surrogate on one core."""

import logging
from pathlib import Path

from fem.sweep import clinical_cases
from run.config import solver_settings
from run.joblog import job_log
from studies.surrogate_study.architecture import AblationComparison, ArchitectureTable
from studies.surrogate_study.surrogate_benchmark import (
    SurrogateBenchmark,
    format_benchmark,
    run_benchmark,
)
from studies.surrogate_study.surrogate_evaluation import ClinicalEvaluation

job_log(snakemake.log[0])

cases = clinical_cases(snakemake.params.clinical)
bench = run_benchmark(
    Path(snakemake.input.model).parent,
    snakemake.input.mesh,
    cases,
    solver_settings(snakemake.params),
    ArchitectureTable.read(snakemake.input.table),
    ClinicalEvaluation.read(snakemake.input.clinical),
    repeats=snakemake.params.repeats,
)
bench["ablations"] = AblationComparison.read(snakemake.input.ablations).to_json()
SurrogateBenchmark.from_json(bench).write(snakemake.output[0])
text = format_benchmark(bench)
logging.getLogger("surrogate_benchmark").info("\n%s", text)
print(text, flush=True)
