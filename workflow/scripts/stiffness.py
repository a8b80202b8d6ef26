"""Snakemake adapter: C1 from the second observation of the skin."""

from pathlib import Path

from run.config import solver_settings
from run.joblog import job_log
from studies.reference_state.stiffness import estimate_file

job_log(snakemake.log[0])

p = snakemake.params
settings = solver_settings(p)
estimate_file(
    Path(snakemake.input.observation), Path(snakemake.input.reference),
    Path(snakemake.input.model).parent, p.posture[0], p.posture[1],
    settings, p.mesh, Path(snakemake.output.json).parent,
)
