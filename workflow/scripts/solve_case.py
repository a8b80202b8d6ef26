"""Snakemake adapter: solve one (C1, Phi, theta) case."""

from pathlib import Path

from fem.case import run_case
from fem.parameters import SolverSettings
from fem.sweep import Case
from run.joblog import job_log

job_log(snakemake.log[0])

w = snakemake.wildcards
settings = SolverSettings.from_config(
    {"fe": snakemake.params.fe, "material": snakemake.params.material,
     "mesh": {"fixed": snakemake.params.fixed}}
)
run_case(
    snakemake.input.mesh,
    Case(float(w.c1), float(w.phi), float(w.theta)),
    Path(snakemake.output.summary).parent,
    settings,
)
