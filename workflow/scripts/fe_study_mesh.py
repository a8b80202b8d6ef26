"""Snakemake adapter: build one mesh of the FE study (the workflow's geometry at other sizes)."""

import logging

from meshes.config import MeshConfig, make_mesh
from studies.fe_variants import MeshSpec

logging.basicConfig(filename=snakemake.log[0], level=logging.INFO, force=True)

spec = MeshSpec.from_id(snakemake.wildcards.fe_mesh)
mesh = dict(snakemake.params.mesh)
mesh["size"] = {**mesh.get("size", {}), **spec.size_mapping()}
make_mesh(
    MeshConfig.from_mapping(mesh),
    snakemake.output.xdmf,
    snakemake.output.quality,
    snakemake.output.png,
)
