"""Snakemake adapter: solve one clinical case on the reference discretisation, store the field."""

import logging

from fem.parameters import SolverSettings
from fem.sweep import Case
from run.joblog import job_log
from studies.fe_study.fe_reference import solve_reference
from studies.fe_study.fe_variants import FEVariant, MeshSpec
from studies.timing_hygiene import limit_blas_threads

job_log(snakemake.log[0])
logging.info("BLAS on %d threads: %s", snakemake.threads, limit_blas_threads(snakemake.threads))

ref = snakemake.params.reference
variant = FEVariant(
    MeshSpec.from_mapping(ref["mesh"]), ref["element"], ref["solver"], ref["quadrature_degree"]
)
w = snakemake.wildcards
solve_reference(
    snakemake.input.mesh,
    variant.settings(SolverSettings.from_config(snakemake.params.config)),
    Case(float(w.c1), float(w.phi), float(w.theta)),
    snakemake.output[0],
)
