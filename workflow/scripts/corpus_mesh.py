"""Snakemake adapter: write one anatomy of the corpus as a user's file and import it."""

from pathlib import Path

import yaml

from meshes.config import MeshConfig, make_mesh
from meshes.corpus import write_anatomy
from run.joblog import job_log

job_log(snakemake.log[0])

section = write_anatomy(snakemake.wildcards.anatomy, snakemake.output.inputs,
                        snakemake.params.mesh, snakemake.params.import_size)
make_mesh(MeshConfig.from_mapping(section), snakemake.output.xdmf, snakemake.output.quality,
          snakemake.output.png)
Path(snakemake.output.section).write_text(yaml.safe_dump(section, sort_keys=False))
