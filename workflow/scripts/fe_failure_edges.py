"""Snakemake adapter: the sweep's failed cases traced from their nearest converged direction."""

from fem.dataset import read_case_columns
from fem.parameters import SolverSettings
from run.joblog import job_log
from studies.fe_study.sweep_edges import sweep_edges

job_log(snakemake.log[0])

result = sweep_edges(
    snakemake.input.mesh,
    SolverSettings.from_config(snakemake.params.config),
    read_case_columns(snakemake.input.dataset),
    snakemake.params.n,
    snakemake.params.step_deg,
    snakemake.params.resolution_deg,
)
result.write(snakemake.output[0])
