"""Snakemake adapter: solve one gravity direction's chain of cases (fem.chain)."""

from pathlib import Path

from fem.chain import solve_chain
from fem.sweep import Case
from run.config import solver_settings
from run.joblog import job_log

job_log(snakemake.log[0])

# the cases asked for are their folders' (the chain rule's outputs, Case.id's pattern)
folders = {Case.from_id(Path(s).parent.name): Path(s).parent for s in snakemake.output.summaries}
solve_chain(snakemake.input.mesh, folders, folders.__getitem__, solver_settings(snakemake.params))
