"""Benchmark: the last resort's settings against other ones, on the cases that need it.

The soft cases that fail, or converge only after the last resort, are most of a sweep's cost:
their last resort runs attempts of up to 60 Newton iterations, many of them on a plateau of the
residual (``fe.loading.stall_window`` gives those up, :func:`fem.convergence.stalled`), and cuts its
steps back down to ``fe.loading.rescue_min_step``. This runs the given directions' chains (the
C1 values stiffest first, each case from its stiffer neighbours as in the sweep:
:mod:`fem.chain`) twice at once, each way in its own process per direction, pinned to its own
core with BLAS on one thread: with the config's loading (``config``) and with the config's
loading changed by ``--against`` (``against``; by default ``rescue_after_neighbours=true``, the
last resort after a start from the neighbours, which the config's chains skip). The cost of a
way is the kernel's CPU count of its processes, so the other way's load does not enter it. Per
case it reports the outcome, Newton iterations and solve CPU both ways, and the largest distance
between the two answers.

``python -m benchmarks.rescue_settings MESH --direction -90 0 --direction 91.8 -104.2
--c1 1.2 1.0 0.8 [--against rescue_min_step=0.015625 ...] [--config config.yaml] [--out DIR]``
prints the table and writes ``DIR/rescue_settings.json``.
"""

from __future__ import annotations

import argparse
import json
import sys
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from fem.case_files import read_points
from fem.exceptions import InvalidParameterError
from fem.parameters import Loading, as_dict
from fem.sweep import Case
from studies.results import Record, Result
from studies.timing_hygiene import MachineState, machine_state, run_pinned

#: The two ways, and the core each runs on.
WAYS = {"config": 0, "against": 1}

#: What the config's loading is compared against unless told otherwise: the last resort for a
#: chain's cases too (the config's chains take none).
DEFAULT_AGAINST = {"rescue_after_neighbours": True}


@dataclass(frozen=True, slots=True)
class CaseCost(Record):
    """One case solved both ways."""

    case: str
    status_config: str
    status_against: str
    load_fraction_config: float
    load_fraction_against: float
    newton_config: int
    newton_against: int
    stalled_attempts_config: int
    stalled_attempts_against: int
    solve_cpu_config_s: float
    solve_cpu_against_s: float
    difference_mm: float | None


@dataclass(frozen=True, slots=True)
class RescueCost(Result):
    """The config's loading against other settings: every case, and the processes' CPU."""

    loading: dict[str, Any]
    against: dict[str, Any]
    directions: list[list[float]]
    c1_kpa: list[float]
    cases: list[CaseCost]
    cpu_config_s: float
    cpu_against_s: float
    cpu_ratio: float
    machine_before: MachineState
    machine_after: MachineState


def run(mesh: Path, config: dict, directions: list[tuple[float, float]], c1_values: list[float],
        out: Path, against: dict[str, Any] | None = None) -> RescueCost:
    """Solve the chains both ways at once and compare them.

    Raises:
        InvalidParameterError: for ``against`` keys that are no loading parameter or values
            that :class:`fem.parameters.Loading` refuses, and for ``against`` settings that
            are the config's own (nothing to compare).
    """
    fe = config.get("fe", {})
    mine = Loading.from_mapping(fe.get("loading", {}))
    against = dict(DEFAULT_AGAINST if against is None else against)
    other = Loading.from_mapping({**fe.get("loading", {}), **against})
    if other == mine:
        raise InvalidParameterError(
            f"--against {_describe(against)} is the config's own fe.loading: nothing to compare")
    loadings = {"config": as_dict(mine), "against": as_dict(other)}
    cpu = {way: 0.0 for way in WAYS}
    codes: list[int] = []

    def way(name: str) -> None:
        folder = out / name
        folder.mkdir(parents=True, exist_ok=True)
        values = {**config, "fe": {**fe, "loading": loadings[name]}}
        (folder / "config.yaml").write_text(yaml.safe_dump(values))
        for phi, theta in directions:
            command = [sys.executable, "-m", "fem.chain", str(mesh), "--c1",
                       *map(str, c1_values), "--phi", str(phi), "--theta", str(theta),
                       "--cases", str(folder / "cases"), "--config", str(folder / "config.yaml")]
            _, seconds, code = run_pinned(command, WAYS[name], folder / f"chain_{phi}_{theta}.log")
            cpu[name] += seconds
            codes.append(code)

    before = machine_state()
    threads = [threading.Thread(target=way, args=(name,)) for name in WAYS]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    after = machine_state()
    if any(codes):
        raise RuntimeError(f"a chain process failed (exit statuses {codes}): see the chain_*.log "
                           f"files under {out}")
    rows = [_compare(Case(c1, phi, theta), out) for phi, theta in directions for c1 in c1_values]
    return RescueCost(
        loading=loadings["config"],
        against=against,
        directions=[[phi, theta] for phi, theta in directions],
        c1_kpa=list(c1_values),
        cases=rows,
        cpu_config_s=cpu["config"],
        cpu_against_s=cpu["against"],
        cpu_ratio=cpu["config"] / cpu["against"] if cpu["against"] else float("nan"),
        machine_before=before,
        machine_after=after,
    )


def _describe(values: dict[str, Any]) -> str:
    return " ".join(f"{k}={v}" for k, v in values.items())


def parse_against(items: list[str]) -> dict[str, Any]:
    """``KEY=VALUE`` items (values read as YAML scalars) as a mapping of loading overrides.

    Raises:
        InvalidParameterError: for an item without ``=``.
    """
    values: dict[str, Any] = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise InvalidParameterError(
                f"--against takes KEY=VALUE of fe.loading, e.g. rescue_min_step=0.015625; "
                f"got {item!r}")
        values[key] = yaml.safe_load(value)
    return values


def _compare(case: Case, out: Path) -> CaseCost:
    summaries = {name: json.loads((out / name / "cases" / case.id / "summary.json").read_text())
                 for name in WAYS}
    mine, other = summaries["config"], summaries["against"]
    difference = None
    if mine["status"] == other["status"] == "converged":
        u_mine, u_other = (read_points(out / name / "cases" / case.id / "points.h5")["u"]
                           for name in WAYS)
        difference = 1e3 * float(np.linalg.norm(u_mine - u_other, axis=1).max())
    return CaseCost(
        case=case.id,
        status_config=mine["status"],
        status_against=other["status"],
        load_fraction_config=mine["load_fraction"],
        load_fraction_against=other["load_fraction"],
        newton_config=mine["total_newton_iterations"],
        newton_against=other["total_newton_iterations"],
        stalled_attempts_config=mine["failure_kinds"].get("stalled", 0),
        stalled_attempts_against=other["failure_kinds"].get("stalled", 0),
        solve_cpu_config_s=mine["cpu_s"]["solve"],
        solve_cpu_against_s=other["cpu_s"]["solve"],
        difference_mm=difference,
    )


def main(argv: list[str] | None = None) -> int:
    """Entry point (see the module docstring)."""
    from run.config import ConfigError, read_config_file

    parser = argparse.ArgumentParser(prog="python -m benchmarks.rescue_settings",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("mesh", type=Path, help="mesh XDMF with facet tags")
    parser.add_argument("--direction", type=float, nargs=2, action="append", required=True,
                        metavar=("PHI", "THETA"), help="a gravity direction (degrees); repeat")
    parser.add_argument("--c1", type=float, nargs="+", required=True,
                        help="C1 values (kPa) of each chain, e.g. the case and two stiffer ones")
    parser.add_argument("--against", nargs="+", metavar="KEY=VALUE", default=None,
                        help="fe.loading settings the config's are compared against "
                             "(default: rescue_after_neighbours=true)")
    parser.add_argument("--config", type=Path, default=Path("config.yaml"))
    parser.add_argument("--out", type=Path, default=Path("results/benchmarks/rescue_settings"))
    args = parser.parse_args(argv)
    try:
        config = read_config_file(args.config)
        against = None if args.against is None else parse_against(args.against)
        result = run(args.mesh.resolve(), config, args.direction, args.c1, args.out.resolve(),
                     against)
    except (InvalidParameterError, ConfigError, RuntimeError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    result.write(args.out / "rescue_settings.json")
    print(f"the config's fe.loading against {_describe(result.against)}; "
          f"{result.machine_before.cpu}, load before "
          f"{result.machine_before.load_average_1_5_15min}, after "
          f"{result.machine_after.load_average_1_5_15min}")
    print(f"{'case':<32}{'config':>11}{'against':>11}{'λ':>13}{'Newton':>11}{'stalled':>8}"
          f"{'CPU s':>11}{'Δu mm':>10}")
    for r in result.cases:
        diff = "" if r.difference_mm is None else f"{r.difference_mm:.1e}"
        fractions = f"{r.load_fraction_config:.3f}/{r.load_fraction_against:.3f}"
        print(f"{r.case:<32}{r.status_config:>11}{r.status_against:>11}{fractions:>13}"
              f"{f'{r.newton_config}/{r.newton_against}':>11}"
              f"{f'{r.stalled_attempts_config}/{r.stalled_attempts_against}':>8}"
              f"{f'{r.solve_cpu_config_s:.0f}/{r.solve_cpu_against_s:.0f}':>11}{diff:>10}")
    print(f"CPU of the processes, config / against: {result.cpu_config_s:.0f} s / "
          f"{result.cpu_against_s:.0f} s = {result.cpu_ratio:.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
