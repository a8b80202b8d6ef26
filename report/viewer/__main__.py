"""The interactive 3D view of any surrogate model, built outside the workflow.

    .venv/bin/python -m report.viewer MODEL -o page.html [--mesh results/mesh/mesh.xdmf]
        [--dataset results/dataset/dataset.h5] [--config config.yaml] [--points tumour.csv]

``MODEL`` is a model folder (the workflow's ``results/surrogate/model``, or one trained with
``python -m surrogate.cli train --out``); ``--mesh`` the mesh it was trained on. With
``--dataset`` (the sweep's, of the same material points) the page can show FE solutions beside
the surrogate's; with ``--config`` (a whole workflow config, checked as a run checks it) it
offers the config's postures as buttons (and, with ``reference_state.imaged``, measures
movement from the imaged posture first) and labels its clinical cases; with ``--points`` (a
``name,x,y,z`` CSV of material points inside the body, in the model's reference frame, m, as
``surrogate.cli predict --points`` reads) it draws where the surrogate moves them. The page
opens from the file system, as the workflow's does. Exit status 2 names a model, mesh,
dataset, config or point that cannot be used, or an output that would overwrite an input (a file
of the model folder, the mesh or its HDF5 data, any file given); nothing is written then.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from fem.arguments import output_file, refuse_overwriting
from fem.exceptions import DatasetError
from fem.sweep import clinical_list
from meshes.exceptions import MeshInputError
from meshes.points import read_points
from report.viewer import LICENCE, ViewerError, build_viewer
from run.config import ConfigError, WorkflowConfig, read_config_file
from surrogate.exceptions import SurrogateError


def _checked(path: Path) -> WorkflowConfig:
    """The config at ``path``, validated as a run validates it.

    Raises:
        ConfigError: naming the file, and the key for a value out of its bounds.
    """
    values = read_config_file(path)  # its errors name the file
    try:
        return WorkflowConfig.from_mapping(values)
    except ConfigError as err:
        raise ConfigError(f"{path}: invalid configuration: {err}") from None


def main(argv: list[str] | None = None) -> int:
    """Build the page; returns the exit status."""
    parser = argparse.ArgumentParser(prog="python -m report.viewer",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("model", type=Path, help="the surrogate's model folder")
    parser.add_argument("-o", "--output", type=output_file, required=True,
                        help="the page to write")
    parser.add_argument("--mesh", type=Path, default=Path("results/mesh/mesh.xdmf"),
                        help="the mesh the model was trained on")
    parser.add_argument("--dataset", type=Path,
                        help="the sweep's dataset, to show FE solutions beside the surrogate's")
    parser.add_argument("--config", type=Path,
                        help="a config: its postures become buttons, its clinical cases labels")
    parser.add_argument("--points", type=Path, metavar="CSV",
                        help="named material points inside the body (name,x,y,z, m) to draw")
    args = parser.parse_args(argv)
    model = args.model.parent if args.model.suffix == ".json" else args.model  # or its model.json
    refuse_overwriting(parser, "-o/--output", [args.output, args.output.parent / LICENCE], [
        ("MODEL", model), ("--mesh", args.mesh), ("--dataset", args.dataset),
        ("--config", args.config), ("--points", args.points)])
    try:
        clinical, postures, start, initial = [], [], None, None
        if args.config:  # checked as a run checks it
            config = _checked(args.config)
            clinical = clinical_list(config.section("clinical"))
            postures = config.section("surrogate_study", "postures", "directions")
            if config.imaged:  # movement from the image, opened at the tracked posture
                start, initial = config.imaged.posture(), config.imaged.view_query()
        names, X = read_points(args.points) if args.points else ([], [])
        named = list(zip(names, X, strict=True))
        info = build_viewer(args.model, args.mesh, args.dataset, args.output, clinical,
                            postures, named, start, initial)
    except (ConfigError, SurrogateError, DatasetError, ViewerError, MeshInputError,
            OSError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    print(f"wrote {args.output}: {info['points']} material points, {info['surface_vertices']} "
          f"surface vertices, {info['fe_cases']} FE cases, {len(postures)} postures, "
          f"{info['named_points']} named points")
    return 0


if __name__ == "__main__":
    sys.exit(main())
