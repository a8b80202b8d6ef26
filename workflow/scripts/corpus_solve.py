"""Snakemake adapter: solve one anatomy's cases with the config's solver and exact Newton."""

from pathlib import Path

import yaml

from fem.parameters import SolverSettings
from meshes.corpus import ANATOMIES
from run.joblog import job_log
from studies.fe_study.corpus import corpus_cases, solve_anatomy
from studies.fe_study.mesh_quality import MeshQuality

job_log(snakemake.log[0])

name = snakemake.wildcards.anatomy
mesh = yaml.safe_load(Path(snakemake.input.section).read_text())
# the anatomy's mesh section decides the contact (the parametric chest, or off on an import)
settings = SolverSettings.from_config({**snakemake.params.config, "mesh": mesh})
run = solve_anatomy(name, ANATOMIES[name].description, snakemake.input.mesh,
                    MeshQuality.read(snakemake.input.quality), settings,
                    corpus_cases(snakemake.params.clinical, snakemake.params.soft_C1,
                                 snakemake.params.soft_phi),
                    progress=snakemake.params.progress)
run.write(snakemake.output[0])
