"""Snakemake adapter: build the tagged breast mesh and its quality report."""

import json
import logging

from meshes.build import MeshSize, write_parametric_mesh
from meshes.parametric import BreastGeometry

logging.basicConfig(filename=snakemake.log[0], level=logging.INFO, force=True)

cfg = snakemake.params.mesh
report = write_parametric_mesh(
    BreastGeometry.from_mapping(cfg.get("geometry", {})),
    MeshSize(**cfg.get("size", {})),
    snakemake.output.xdmf,
)
with open(snakemake.output.quality, "w") as fh:
    json.dump(report, fh, indent=2)
