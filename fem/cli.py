r"""Command line: solve one case outside Snakemake, serially or under MPI.

Example::

    mpirun -n 2 .venv/bin/python -m fem.cli results/mesh/mesh.xdmf --c1 1.0 --phi 180 \
        --out results/cases/c1=1.00_phi=180.0_theta=0.0 --config config.yaml

Only rank 0 logs: each load step and Newton iteration as it happens, then the case's outcome.
The case folder receives the same files as the workflow's ``solve`` rule writes.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path

from mpi4py import MPI

from fem.arguments import angle_deg, c1_kpa, output_folder
from fem.case import run_case
from fem.configfile import read_config_file
from fem.exceptions import FEError
from fem.parameters import SolverSettings
from fem.sweep import Case
from meshes.io import MeshInputError

LOG_FORMAT = "%(asctime)s %(levelname)s %(name)s: %(message)s"
"""The console's lines: when, how grave, which module, what (as a workflow job's log has them)."""


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit status (0 also for a case that did not converge)."""
    parser = argparse.ArgumentParser(prog="python -m fem.cli", description=__doc__.splitlines()[0])
    parser.add_argument("mesh", type=Path, help="mesh XDMF with facet tags")
    parser.add_argument("--c1", type=c1_kpa, required=True, help="C1 in kPa")
    parser.add_argument("--phi", type=angle_deg, required=True,
                        help="gravity elevation Φ in degrees")
    parser.add_argument("--theta", type=angle_deg, default=0.0, help="gravity azimuth θ in degrees")
    parser.add_argument("--out", type=output_folder, required=True, help="case folder to write")
    parser.add_argument(
        "--config", type=Path, help="workflow config (sections fe, material, mesh.fixed)"
    )
    parser.add_argument("--solver", help="solver preset, overriding the config's fe.solver")
    parser.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    args = parser.parse_args(argv)

    comm = MPI.COMM_WORLD
    # force: FFCx, imported with dolfinx, has already given the root logger a handler, which
    # would make basicConfig do nothing and leave the solve silent (its load steps and Newton
    # iterations are logged at INFO, as they happen)
    if comm.rank == 0:
        logging.basicConfig(level=logging.DEBUG if args.verbose else logging.INFO,
                            format=LOG_FORMAT, force=True)
    else:
        logging.basicConfig(level=logging.CRITICAL, force=True)
    try:
        config = read_config_file(args.config) if args.config else {}
        if args.solver:
            config = {**config, "fe": {**config.get("fe", {}), "solver": args.solver}}
        settings = SolverSettings.from_config(config)
        summary = run_case(args.mesh, Case(args.c1, args.phi, args.theta), args.out, settings)
    except (FEError, MeshInputError) as err:
        if comm.rank == 0:
            print(f"error: {err}", file=sys.stderr)
        return 2
    if comm.rank == 0:
        print(
            json.dumps({k: summary[k] for k in ("status", "reason", "load_steps", "max_disp_mm")})
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
