"""Snakemake adapter: build (or import) the tagged breast mesh, its quality report and picture."""

from meshes.config import MeshConfig, make_mesh
from run.joblog import job_log

job_log(snakemake.log[0])

make_mesh(
    MeshConfig.from_mapping(snakemake.params.mesh),
    snakemake.output.xdmf,
    snakemake.output.quality,
    snakemake.output.png,
)
