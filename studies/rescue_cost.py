"""Benchmark: the last resort's stall test, on and off, on the cases that need the last resort.

The soft cases that fail, or converge only after the last resort, are most of a sweep's cost:
their last resort runs attempts of up to 60 Newton iterations, many of them on a plateau of the
residual (``fe.loading.stall_window`` gives those up, :func:`fem.solver._stalled`). This runs
the given directions' chains (the C1 values stiffest first, each case from its stiffer
neighbours as in the sweep: :mod:`fem.chain`) twice at once, each way in its own process per
direction, pinned to its own core with BLAS on one thread: with the config's loading (the stall
test on) and with ``stall_window: 0``. The cost of a way is the kernel's CPU count of its
processes, so the other way's load does not enter it. Per case it reports the outcome,
Newton iterations and solve CPU both ways, and the largest distance between the two answers.

``python -m studies.rescue_cost MESH --direction -90 0 --direction 91.8 -104.2 --c1 1.2 1.0 0.8
[--config config.yaml] [--out DIR]`` prints the table and writes ``DIR/rescue_cost.json``.
"""

from __future__ import annotations

import argparse
import json
import sys
import threading
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from fem.dataset import read_points
from fem.exceptions import InvalidParameterError
from fem.parameters import Loading
from fem.sweep import Case
from studies.machine import MachineState, machine_state, run_pinned
from studies.results import Record, Result

#: The two ways, and the core each runs on.
WAYS = {"on": 0, "off": 1}


@dataclass(frozen=True, slots=True)
class CaseCost(Record):
    """One case solved both ways."""

    case: str
    status_on: str
    status_off: str
    load_fraction_on: float
    load_fraction_off: float
    newton_on: int
    newton_off: int
    stalled_attempts_on: int
    solve_cpu_on_s: float
    solve_cpu_off_s: float
    difference_mm: float | None


@dataclass(frozen=True, slots=True)
class RescueCost(Result):
    """The stall test on against off: every case, and the processes' CPU both ways."""

    stall_window: int
    directions: list[list[float]]
    c1_kpa: list[float]
    cases: list[CaseCost]
    cpu_on_s: float
    cpu_off_s: float
    cpu_ratio: float
    returncodes: list[int]
    machine_before: MachineState
    machine_after: MachineState


def run(mesh: Path, config: dict, directions: list[tuple[float, float]], c1_values: list[float],
        out: Path) -> RescueCost:
    """Solve the chains both ways at once and compare them."""
    window = Loading.from_mapping(config.get("fe", {}).get("loading", {})).stall_window
    if window == 0:
        raise InvalidParameterError(
            "the config's fe.loading.stall_window is 0: there is no stall test to compare")
    cpu = {way: 0.0 for way in WAYS}
    codes: list[int] = []

    def way(name: str) -> None:
        folder = out / name
        folder.mkdir(parents=True, exist_ok=True)
        fe = config.get("fe", {})
        loading = {**fe.get("loading", {}), "stall_window": window if name == "on" else 0}
        values = {**config, "fe": {**fe, "loading": loading}}
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
        stall_window=window,
        directions=[[phi, theta] for phi, theta in directions],
        c1_kpa=list(c1_values),
        cases=rows,
        cpu_on_s=cpu["on"],
        cpu_off_s=cpu["off"],
        cpu_ratio=cpu["on"] / cpu["off"] if cpu["off"] else float("nan"),
        returncodes=codes,
        machine_before=before,
        machine_after=after,
    )


def _compare(case: Case, out: Path) -> CaseCost:
    summaries = {name: json.loads((out / name / "cases" / case.id / "summary.json").read_text())
                 for name in WAYS}
    on, off = summaries["on"], summaries["off"]
    difference = None
    if on["status"] == off["status"] == "converged":
        u_on, u_off = (read_points(out / name / "cases" / case.id / "points.h5")["u"]
                       for name in WAYS)
        difference = 1e3 * float(np.linalg.norm(u_on - u_off, axis=1).max())
    return CaseCost(
        case=case.id,
        status_on=on["status"],
        status_off=off["status"],
        load_fraction_on=on["load_fraction"],
        load_fraction_off=off["load_fraction"],
        newton_on=on["total_newton_iterations"],
        newton_off=off["total_newton_iterations"],
        stalled_attempts_on=on["failure_kinds"].get("stalled", 0),
        solve_cpu_on_s=on["cpu_s"]["solve"],
        solve_cpu_off_s=off["cpu_s"]["solve"],
        difference_mm=difference,
    )


def main(argv: list[str] | None = None) -> int:
    """Entry point (see the module docstring)."""
    from studies.config import read_config_file

    parser = argparse.ArgumentParser(prog="python -m studies.rescue_cost",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("mesh", type=Path, help="mesh XDMF with facet tags")
    parser.add_argument("--direction", type=float, nargs=2, action="append", required=True,
                        metavar=("PHI", "THETA"), help="a gravity direction (degrees); repeat")
    parser.add_argument("--c1", type=float, nargs="+", required=True,
                        help="C1 values (kPa) of each chain, e.g. the case and two stiffer ones")
    parser.add_argument("--config", type=Path, default=Path("config.yaml"))
    parser.add_argument("--out", type=Path, default=Path("results/benchmarks/rescue_cost"))
    args = parser.parse_args(argv)
    config = read_config_file(args.config)
    try:
        result = run(args.mesh.resolve(), config, args.direction, args.c1, args.out.resolve())
    except (InvalidParameterError, RuntimeError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    result.write(args.out / "rescue_cost.json")
    print(f"stall window {result.stall_window}; {result.machine_before.cpu}, load before "
          f"{result.machine_before.load_average_1_5_15min}, after "
          f"{result.machine_after.load_average_1_5_15min}")
    print(f"{'case':<32}{'on':>11}{'off':>11}{'Newton on/off':>15}{'stalled':>8}"
          f"{'CPU on/off s':>15}{'Δu mm':>10}")
    for r in result.cases:
        diff = "" if r.difference_mm is None else f"{r.difference_mm:.1e}"
        print(f"{r.case:<32}{r.status_on:>11}{r.status_off:>11}"
              f"{f'{r.newton_on}/{r.newton_off}':>15}{r.stalled_attempts_on:>8}"
              f"{f'{r.solve_cpu_on_s:.0f}/{r.solve_cpu_off_s:.0f}':>15}{diff:>10}")
    print(f"CPU of the processes, on / off: {result.cpu_on_s:.0f} s / {result.cpu_off_s:.0f} s "
          f"= {result.cpu_ratio:.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
