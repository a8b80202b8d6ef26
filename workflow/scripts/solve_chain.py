"""Snakemake adapter: solve one gravity direction's chain of cases (fem.chain)."""

from pathlib import Path

from fem.chain import solve_chain
from fem.parameters import SolverSettings
from fem.sweep import Case
from run.joblog import job_log

job_log(snakemake.log[0])

settings = SolverSettings.from_config(
    {"fe": snakemake.params.fe, "material": snakemake.params.material,
     "mesh": {"fixed": snakemake.params.fixed}}
)
folders = {Case.from_id(Path(s).parent.name): Path(s).parent for s in snakemake.output.summaries}
solve_chain(snakemake.input.mesh, folders, folders.__getitem__, settings)
