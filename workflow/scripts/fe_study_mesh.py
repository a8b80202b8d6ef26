"""Snakemake adapter: build one mesh of the FE study (the workflow's geometry at other sizes)."""

from meshes.config import MeshConfig, make_mesh
from run.joblog import job_log
from studies.fe_study.fe_variants import MeshSpec

job_log(snakemake.log[0])

spec = MeshSpec.from_id(snakemake.wildcards.fe_mesh)
mesh = dict(snakemake.params.mesh)
mesh["size"] = {**mesh.get("size", {}), **spec.size_mapping()}
make_mesh(
    MeshConfig.from_mapping(mesh),
    snakemake.output.xdmf,
    snakemake.output.quality,
    snakemake.output.png,
)
