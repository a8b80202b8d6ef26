"""Snakemake adapter: convergence maps over (C1, Phi) for adaptive and fixed-step loading."""

from fem.parameters import SolverSettings
from run.joblog import job_log
from studies.fe_study.convergence_map import convergence_map, loading_schemes

job_log(snakemake.log[0])

study = snakemake.params.convergence_map
settings = SolverSettings.from_config(snakemake.params.config)
result = convergence_map(
    snakemake.input.mesh,
    settings,
    study["C1_kPa"],
    study["phi_deg"],
    loading_schemes(settings.loading, study["fixed_steps"]),
)
result.write(snakemake.output[0])
