"""Snakemake adapter: the reference state's round trips on the config's mesh."""

from fem.parameters import SolverSettings
from run.joblog import job_log
from studies.reference_state.reference_roundtrip import round_trips

job_log(snakemake.log[0])

p = snakemake.params
settings = SolverSettings.from_config(
    {"fe": p.fe, "material": p.material, "mesh": {"fixed": p.fixed}}
)
round_trips(
    snakemake.input.mesh, settings, list(p.reference_state["C1_kPa"]),
    list(p.reference_state["observed_phi"]), 1e-3 * p.reference_state["tolerance_mm"],
).write(snakemake.output[0])
