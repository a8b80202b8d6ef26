"""Benchmark: how well each error estimate ranks the data's own error at FE cases left out.

The adaptive sweep (:mod:`fem.adaptive`) chooses its cases by an estimate of the error between
the cases solved so far. Here the estimates are built from one set of solved case folders (a
sweep's, e.g. the start design's) and judged at another set that none of them was built from
(e.g. cases of another design, solved by the same workflow on the same mesh): the *true* error
there is that of the load-space interpolant of the first set, the error no model of those data
can be sure to beat. For each estimate (:data:`studies.sweep.sweep_estimate.ESTIMATORS`), Spearman's
rank correlation with the true worst-point error and the share of the true worst tenth it finds,
over all the held-out cases and over those at or below ``--soft`` kPa.

``python -m benchmarks.estimate_ranking --built DIR... --held-out DIR... [--soft 1.2]
[--json OUT]``: each DIR a case folder (``summary.json``, ``points.h5``); failed cases are
left out of both sets, and held-out cases whose direction and C1 are already built are dropped.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from fem.adaptive import load_points, read_cases
from studies.sweep.sweep_estimate import ESTIMATORS, EstimateRow, estimates_at, rank_score


def rank(built: list[Path], held_out: list[Path], soft_kpa: float) -> dict:
    """The estimates from ``built`` at ``held_out`` against the interpolant's true error."""
    cases, ok, fields = read_cases([d / "summary.json" for d in built],
                                   [d / "points.h5" for d in built])
    tests, test_ok, test_fields = read_cases([d / "summary.json" for d in held_out],
                                             [d / "points.h5" for d in held_out])
    built_cases = set(cases)
    keep = [i for i, c in enumerate(tests) if test_ok[i] and c not in built_cases]
    x = load_points(np.array([c.C1 for c in cases]), np.array([c.phi for c in cases]),
                    np.array([c.theta for c in cases]))[ok]
    chosen = [tests[i] for i in keep]
    y = load_points(np.array([c.C1 for c in chosen]), np.array([c.phi for c in chosen]),
                    np.array([c.theta for c in chosen]))
    estimates, true = estimates_at(x, fields[ok], y, test_fields[keep])
    rows = [EstimateRow("held_out", c.id, c.C1, c.phi, c.theta, float(true[k]),
                        float(true[k]), {n: float(v[k]) for n, v in estimates.items()})
            for k, c in enumerate(chosen)]
    soft = [r for r in rows if r.C1 <= soft_kpa + 1e-9]
    scores = [rank_score(name, e, part) for name, part in (("all", rows), (f"C1 <= {soft_kpa:g}",
                                                                       soft))
              for e in ESTIMATORS if len(part) > 2]
    return {"built": int(ok.sum()), "held_out": len(rows),
            "scores": [s.to_json() for s in scores], "rows": [r.to_json() for r in rows]}


def main(argv: list[str] | None = None) -> int:
    """Command line: see the module's docstring."""
    parser = argparse.ArgumentParser(prog="python -m benchmarks.estimate_ranking",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("--built", type=Path, nargs="+", required=True)
    parser.add_argument("--held-out", type=Path, nargs="+", required=True)
    parser.add_argument("--soft", type=float, default=1.2, help="the soft end's largest C1, kPa")
    parser.add_argument("--json", type=Path)
    args = parser.parse_args(argv)
    result = rank(args.built, args.held_out, args.soft)
    print(f"built from {result['built']} converged cases; {result['held_out']} held out")
    print(f"{'set':<12}{'estimator':<11}{'cases':>6}{'rank corr.':>11}{'worst tenth':>12}")
    for s in result["scores"]:
        print(f"{s['set']:<12}{s['estimator']:<11}{s['cases']:>6}{s['rank_correlation']:>11.3f}"
              f"{s['worst_tenth_found']:>12.2f}")
    true = np.array([r["true_mm"] for r in result["rows"]])
    if true.size:
        print(f"the interpolant's true worst-point error: median {np.median(true):.3f} mm, "
              f"largest {true.max():.3f} mm")
    if args.json:
        args.json.write_text(json.dumps(result, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
