"""Snakemake adapter: a points file tracked from the imaged shape by FE and by the surrogate."""

from pathlib import Path

from run.config import solver_settings
from run.joblog import job_log
from studies.reference_state.tracking import track_file

job_log(snakemake.log[0])

p = snakemake.params
settings = solver_settings(p)
track_file(
    Path(snakemake.input.points), Path(snakemake.input.imaged), Path(snakemake.input.reference),
    Path(snakemake.input.model).parent, p.target["C1"], p.target["phi"], p.target["theta"],
    settings, p.mesh, Path(snakemake.output.csv),
)
