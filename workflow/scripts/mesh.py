"""Snakemake adapter: build (or import) the tagged breast mesh, its quality report and picture."""

import logging

from meshes.config import MeshConfig, make_mesh

logging.basicConfig(filename=snakemake.log[0], level=logging.INFO, force=True)

make_mesh(
    MeshConfig.from_mapping(snakemake.params.mesh),
    snakemake.output.xdmf,
    snakemake.output.quality,
    snakemake.output.png,
)
