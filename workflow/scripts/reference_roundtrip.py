"""Snakemake adapter: the reference state's round trips on the config's mesh."""

from run.config import solver_settings
from run.joblog import job_log
from studies.reference_state.reference_roundtrip import round_trips

job_log(snakemake.log[0])

p = snakemake.params
settings = solver_settings(p)
round_trips(
    snakemake.input.mesh, settings, list(p.reference_state["C1_kPa"]),
    list(p.reference_state["observed_phi"]), 1e-3 * p.reference_state["tolerance_mm"],
).write(snakemake.output[0])
