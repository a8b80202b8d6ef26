"""The surrogate's command line: predict one setup, or train one model outside the workflow.

Examples::

    python -m surrogate.cli predict results/surrogate/model --c1 1.0 --phi 180 -o u.xdmf
    python -m surrogate.cli predict results/surrogate/model --c1 1.0 --phi 0 \
        --points tumour.csv -o tumour_supine.csv
    python -m surrogate.cli train results/dataset/dataset.h5 --set activation=tanh --out /tmp/m

``predict`` prints the largest and mean displacement and writes the field with ``-o``:
``.npy`` (the (N, 3) array in mm) or ``.xdmf`` (on the mesh of ``--mesh``, for ParaView).
With ``--points`` (a ``name,x,y,z`` CSV of material points, in the model's reference frame, m:
the project's frame) it predicts at those points instead, prints each one's displacement and
position (up to :data:`PRINTED_POINTS` of them; for more, the summary of the whole field), and
writes their positions in that posture with ``-o`` as a ``name,x,y,z`` CSV, which
``python -m meshes.frame --to file`` carries into an imported file's frame. With
``--from-phi`` (and ``--from-theta``) it also gives each point's movement from that posture to
this one at the same C1 (a tumour seen prone, at supine: ``--phi 0 --from-phi 180``): printed
for named points, and for the whole field its largest and mean, written to an ``.xdmf`` as the
fields ``movement_mm`` and ``movement_magnitude_mm`` beside the displacement.
``train`` trains the ``surrogate`` settings of ``--config`` with the ``--set`` overrides on
one core, saves the model with ``--out`` and prints one JSON line (validation error, best
epoch, training time). Bad input exits with status 2 and a message naming it. A setup the
model warns at (an extrapolation: no FE solution of its sweep backs it) prints ``warning: ...``
on stderr and is still answered; with ``--strict`` it is refused instead (status 3, nothing
written), for scripts that must not use such an answer.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from fem.arguments import angle_deg, c1_kpa, overwritten
from fem.configfile import read_config_file
from fem.exceptions import DatasetError
from meshes.points import moved_table, movement_table, read_points, write_points
from surrogate.config import SurrogateConfig
from surrogate.exceptions import ExtrapolationWarning, OutsideMeshError, SurrogateError

PRINTED_POINTS = 50
"""Up to this many named points are printed one per line; more get the whole field's summary
(their table goes to ``--output``)."""


def predict(args: argparse.Namespace) -> int:
    """``predict``: one whole-field prediction, printed and optionally written."""
    from surrogate.fields import write_prediction_xdmf
    from surrogate.predict import Surrogate

    output = Path(args.output) if args.output else None
    suffixes = (".csv",) if args.points else (".npy", ".xdmf")
    if output is not None and output.suffix not in suffixes:
        what = "with --points" if args.points else "for the whole field"
        print(f"error: --output {output} must end in {' or '.join(suffixes)} ({what})",
              file=sys.stderr)
        return 2
    if output is not None and not output.parent.is_dir():
        print(f"error: --output {output}: the folder {output.parent} does not exist",
              file=sys.stderr)
        return 2
    if output is not None:
        model = Path(args.model)
        inputs = [("MODEL", model.parent if model.suffix == ".json" else model),
                  ("--points", args.points and Path(args.points)), ("--mesh", Path(args.mesh))]
        written = [output] + ([output.with_suffix(".h5")] if output.suffix == ".xdmf" else [])
        why = next(filter(None, (overwritten(path, inputs) for path in written)), None)
        if why is not None:
            print(f"error: --output {why}: it would be overwritten; write elsewhere",
                  file=sys.stderr)
            return 2
    if args.from_phi is None and args.from_theta is not None:
        print("error: --from-theta needs --from-phi", file=sys.stderr)
        return 2
    if args.from_phi is not None and output is not None and output.suffix == ".npy":
        print(f"error: --output {output}: an .npy holds the displacement alone; write an .xdmf "
              "for the movement from --from-phi beside it", file=sys.stderr)
        return 2
    names: list[str] = []
    since = None if args.from_phi is None else (args.from_phi, args.from_theta or 0.0)
    try:
        model = Surrogate.load(args.model)
        if args.points:
            names, points = read_points(Path(args.points))
            try:
                model = model.at(points)
            except OutsideMeshError as err:
                raise OutsideMeshError(err.naming(names), err.gaps_m, err.limit_m) from None
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", ExtrapolationWarning)
            u = model.predict(args.c1, args.phi, args.theta)
        with warnings.catch_warnings(record=True) as caught_since:
            warnings.simplefilter("always", ExtrapolationWarning)
            u_since = None if since is None else model.predict(args.c1, *since)
        extrapolated = False
        # one line each, as a user reads it (not Python's source line)
        for prefix, warning in [("", w) for w in caught] + [
                (f"from Φ = {since[0]:g}°, θ = {since[1]:g}°: ", w) for w in caught_since]:
            if issubclass(warning.category, ExtrapolationWarning):
                extrapolated = True
                print(f"{'error' if args.strict else 'warning'}: {prefix}{warning.message}",
                      file=sys.stderr)
            else:
                warnings.showwarning(warning.message, warning.category, warning.filename,
                                     warning.lineno)
        if extrapolated and args.strict:
            return 3
        if output is not None and output.suffix == ".xdmf":
            write_prediction_xdmf(output, args.mesh, model, u,
                                  None if u_since is None else u - u_since)
    except (SurrogateError, OSError, ValueError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    norms = np.linalg.norm(u, axis=1)
    if args.points and len(names) <= PRINTED_POINTS:
        print(moved_table(names, model.X, u))
        if u_since is not None:
            print(f"\nmoved from Φ = {since[0]:g}°, θ = {since[1]:g}° (at the same C1):")
            print(movement_table(names, u - u_since))
    else:
        print(f"{u.shape[0]} points: max |u| = {norms.max():.3f} mm, "
              f"mean |u| = {norms.mean():.3f} mm")
        if u_since is not None:
            way = np.linalg.norm(u - u_since, axis=1)
            print(f"moved from Φ = {since[0]:g}°, θ = {since[1]:g}° (at the same C1): max |Δx| "
                  f"= {way.max():.3f} mm, mean |Δx| = {way.mean():.3f} mm")
        if args.points and output is None:
            print(f"(more than {PRINTED_POINTS} points: --output FILE.csv writes each one's "
                  "position in that posture)")
    if args.points and output is not None:
        write_points(output, names, model.X + 1e-3 * u)
    if output is not None and output.suffix == ".npy":
        np.save(output, u)
    if output is not None:
        print(f"wrote {output}")
    return 0


def settings(path: str | Path, items: list[str]) -> tuple[SurrogateConfig, dict[str, Any]]:
    """The ``surrogate`` section of the config at ``path`` with ``KEY=VALUE`` overrides (YAML).

    Returns:
        The settings, and the overrides as parsed.

    Raises:
        SurrogateError: if an override is not ``KEY=VALUE`` or a setting is invalid.
        fem.configfile.ConfigFileError: if the config cannot be read.
    """
    import yaml

    overrides = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep:
            raise SurrogateError(f"--set {item!r} is not KEY=VALUE")
        overrides[key.strip()] = yaml.safe_load(value)
    base = read_config_file(path).get("surrogate") or {}
    return SurrogateConfig.from_mapping({**base, **overrides}), overrides


def train(args: argparse.Namespace) -> int:
    """``train``: one model with the config's settings and the overrides, on one core."""
    from surrogate.runtime import configure_cpu

    configure_cpu(single_thread=True)  # before JAX's first computation: one core
    from fem.dataset import read_dataset
    from surrogate.checkpoint import save_model
    from surrogate.structures import structure_for
    from surrogate.train import train_and_evaluate

    try:
        config, overrides = settings(args.config, args.set)
        dataset = read_dataset(args.dataset, nodes=structure_for(config).reads_nodes)
        result = train_and_evaluate(dataset, config, progress=args.progress)
    except (OSError, SurrogateError, DatasetError, ValueError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    if args.out:
        save_model(args.out, result, dataset)
    print(json.dumps({"overrides": overrides, "architecture": config.architecture,
                      "validation_error_mm": result.validation_error_mm,
                      "best_epoch": result.best_epoch, "epochs": len(result.history),
                      "train_s": result.train_s}))
    return 0


def parser() -> argparse.ArgumentParser:
    """The argument parser with the ``predict`` and ``train`` subcommands."""
    top = argparse.ArgumentParser(prog="python -m surrogate.cli",
                                  description=__doc__.splitlines()[0])
    sub = top.add_subparsers(dest="command", required=True)
    p = sub.add_parser("predict", help="predict the displacement of one setup")
    p.add_argument("model", help="model folder (or its model.json)")
    p.add_argument("--c1", type=c1_kpa, required=True, help="C1 in kPa")
    p.add_argument("--phi", type=angle_deg, required=True, help="gravity elevation angle, degrees")
    p.add_argument("--theta", type=angle_deg, default=0.0, help="gravity azimuth angle, degrees")
    p.add_argument("-o", "--output",
                   help="write the displacement: .npy (array, mm) or .xdmf (on the mesh)")
    p.add_argument("--mesh", default="results/mesh/mesh.xdmf", help="mesh for an .xdmf output")
    p.add_argument("--points", metavar="CSV",
                   help="predict at these material points instead (name,x,y,z in the model's "
                        "reference frame, m); -o then writes their positions as a CSV")
    p.add_argument("--from-phi", type=angle_deg, metavar="PHI",
                   help="also give the movement from the posture at this Φ (degrees) to the "
                        "one asked, at the same C1: per named point, or the field's (.xdmf)")
    p.add_argument("--from-theta", type=angle_deg, metavar="THETA",
                   help="θ of the --from-phi posture, degrees (default 0)")
    p.add_argument("--strict", action="store_true",
                   help="refuse a setup the model warns at (no FE solution backs it): exit "
                        "status 3, nothing written")
    p.set_defaults(run=predict)
    t = sub.add_parser("train", help="train one model outside the workflow")
    t.add_argument("dataset", help="the sweep's HDF5 dataset")
    t.add_argument("--config", default="config.yaml",
                   help="config whose `surrogate` section is the base")
    t.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override one surrogate setting (YAML value), e.g. lr_schedule=cosine")
    t.add_argument("--out", help="save the model in this folder")
    t.add_argument("--progress", action="store_true", help="show a progress bar")
    t.set_defaults(run=train)
    return top


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point; returns the exit status."""
    args = parser().parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    logging.getLogger("jax").setLevel(logging.WARNING)  # its search for accelerators is noise
    return args.run(args)


if __name__ == "__main__":
    sys.exit(main())
