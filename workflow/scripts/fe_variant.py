"""Snakemake adapter: one point of the speed-accuracy study on the clinical cases."""

import json
import logging

from fem.benchmark import Variant, clinical_cases, limit_blas_threads, load_displacement, run_variant
from fem.parameters import SolverSettings

logging.basicConfig(filename=snakemake.log[0], level=logging.INFO, force=True)
logging.info("single-threaded BLAS: %s", limit_blas_threads(1))

cases = clinical_cases(snakemake.params.clinical)
references = {
    case.id: load_displacement(path, snakemake.input.reference_mesh)
    for case, path in zip(cases, snakemake.input.references)
}
record = run_variant(
    snakemake.input.mesh,
    Variant.from_id(snakemake.wildcards.variant),
    SolverSettings.from_config(snakemake.params.config),
    cases,
    references,
    max_dofs=snakemake.params.max_dofs,
)
with open(snakemake.output[0], "w") as fh:
    json.dump(record, fh, indent=2, default=float)
