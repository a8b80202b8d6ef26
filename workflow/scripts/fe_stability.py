"""Snakemake adapter: stability maps over (C1, Phi) for adaptive and fixed-step loading."""

from fem.parameters import SolverSettings
from run.joblog import job_log
from studies.fe_study.stability import loading_schemes, stability_map

job_log(snakemake.log[0])

study = snakemake.params.stability
settings = SolverSettings.from_config(snakemake.params.config)
result = stability_map(
    snakemake.input.mesh,
    settings,
    study["C1_kPa"],
    study["phi_deg"],
    loading_schemes(settings.loading, study["fixed_steps"]),
)
result.write(snakemake.output[0])
