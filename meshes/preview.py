"""See what the boundary rules of an import select, before meshing for the solver or solving.

    .venv/bin/python -m meshes.preview config.yaml [--png rules.png]

Reads the config's ``mesh`` section (``source: file``), reads and checks the file, and prints,
for each rule, the facets it selects, their area and their share of the boundary's area; then
whether the import would stop (two rules claim a facet, the rib is more than 70 % or less than
2 % of the boundary). The ``mesh`` section is checked by the config's schema first, as a run
checks it. ``--png`` draws the boundary coloured by rule, in the project's frame.
Exit status: 0 if the rules would do, 1 if not, 2 for a config or file that cannot be read.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from meshes.config import read_mesh_config
from meshes.configfile import read_config_file
from meshes.exceptions import GeometryError, MeshInputError
from meshes.importing import preview_rules
from meshes.schema import load_schema, schema_errors


def main(argv: list[str] | None = None) -> int:
    """Print what each rule selects (and draw it with ``--png``)."""
    parser = argparse.ArgumentParser(prog="python -m meshes.preview",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("config", type=Path, help="a config file whose mesh.source is file")
    parser.add_argument("--png", type=Path, help="draw the boundary, coloured by rule")
    args = parser.parse_args(argv)
    try:
        # the mesh section checked as the run checks it (the schema), then read
        problems = [p for p in schema_errors(read_config_file(args.config), load_schema())
                    if p.startswith(("mesh.", "mesh:"))]
        if problems:
            raise GeometryError(f"{args.config}: invalid mesh section: " + "; ".join(problems))
        config = read_mesh_config(args.config)
        if config.file is None:
            raise GeometryError(f"{args.config}: mesh.source is not file: there is no import")
        summary, problem = preview_rules(config.file, config.size, args.png)
    except (OSError, GeometryError, MeshInputError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    print(f"{'boundary':<10} {'facets':>7} {'area cm²':>10} {'share':>7}  rule")
    for boundary, rule in config.file.surfaces.items():
        row = summary[boundary.label]
        print(f"{boundary.label:<10} {row['facets']:>7d} {1e4 * row['area_m2']:>10.1f} "
              f"{100 * row['share']:>6.1f}%  {rule.describe()}")
    if args.png:
        print(f"picture: {args.png}")
    if problem:
        print(f"the import would stop: {problem}")
        return 1
    print("the rules would do")
    return 0


if __name__ == "__main__":
    sys.exit(main())
