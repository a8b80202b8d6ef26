"""Snakemake adapter: the reference state of the imaged mesh, the workflow's mesh from here on."""

from run.config import solver_settings
from run.joblog import job_log
from studies.reference_state.reference_state import reference_of_imaged

job_log(snakemake.log[0])

p = snakemake.params
settings = solver_settings(p)
imaged = p.imaged
reference_of_imaged(
    snakemake.input.imaged, settings, imaged["C1_kPa"], imaged["phi"], imaged.get("theta", 0.0),
    1e-3 * p.tolerance_mm, snakemake.output.xdmf, snakemake.output.record,
)
