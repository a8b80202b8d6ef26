"""Snakemake adapter: the skin's self-contact pairs at rest on the mesh the cases solve on."""

from fem.parameters import SolverSettings
from fem.self_contact_at_rest import rest_pairs_of_mesh
from run.joblog import job_log

job_log(snakemake.log[0])

settings = SolverSettings.from_config({"fe": snakemake.params.fe})
rest_pairs_of_mesh(snakemake.input.mesh, settings.self_contact,
                   settings.discretisation).write(snakemake.output.json)
