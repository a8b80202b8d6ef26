"""Snakemake adapter: solve one (C1, Phi, theta) case."""

from pathlib import Path

from fem.case import run_case
from fem.sweep import Case
from run.config import solver_settings
from run.joblog import job_log

job_log(snakemake.log[0])

folder = Path(snakemake.output.summary).parent
# the case asked for is its folder's (a rule's pattern of Case.id)
run_case(snakemake.input.mesh, Case.from_id(folder.name), folder, solver_settings(snakemake.params))
