"""Benchmark: the corpus's cases on one anatomy with the skin membrane and without it.

``python -m benchmarks.skin ANATOMY [--config config.yaml] [--thickness 0.0015] [--ratio 18.5]
[--cases C1:PHI ...] [--settings homogeneous skin skin-plain] [--out DIR] [--limit-s 1800]``

It writes the corpus anatomy (:mod:`meshes.corpus`; imports at ``corpus.import_size``),
meshes it as the corpus study does, and solves the corpus's cases (the clinical ones, then
``corpus.soft_C1`` at every ``corpus.soft_phi``; or ``--cases``) with the config's solver
settings, homogeneous and with the skin as a membrane (``material.skin``, its ratio to the
fat ``material.tissues.skin``; ``skin`` the membrane that wrinkles, ``skin-plain`` the one that
resists compression), each setting in a fresh process one after the other
(``--limit-s`` seconds each). It prints per case and setting the outcome, the load reached,
load steps, wall seconds and max |u|, and where both converged the ratio of the two.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from dataclasses import replace
from pathlib import Path
from typing import Any

from fem.configfile import read_config_file
from fem.materials import DEFAULT_SKIN_THICKNESS, SkinLayer, Tissues
from fem.parameters import SolverSettings
from fem.sweep import Case
from meshes.tags import Tissue

#: homogeneous; the skin membrane that wrinkles (the default); the plain membrane.
SETTINGS = ("homogeneous", "skin", "skin-plain")


def parse_case(text: str) -> Case:
    """``C1:PHI[:THETA]`` as a case."""
    return Case(*(float(v) for v in text.split(":")))


def make_mesh(config: dict[str, Any], anatomy: str, folder: Path) -> Path:
    """The anatomy's mesh, as the corpus study makes it."""
    from meshes.config import MeshConfig
    from meshes.config import make_mesh as build
    from meshes.corpus import write_anatomy

    corpus = config.get("corpus") or {}
    section = write_anatomy(anatomy, folder / "input", config["mesh"],
                            import_size=float(corpus.get("import_size", 0.008)))
    xdmf = folder / "mesh.xdmf"
    build(MeshConfig.from_mapping(section), xdmf, folder / "quality.json", folder / "mesh.png")
    return xdmf


def cases_of(config: dict[str, Any]) -> list[Case]:
    """The corpus's cases: the clinical ones, then the soft C1 at every soft direction."""
    from studies.fe_study.corpus import corpus_cases

    corpus = config.get("corpus") or {}
    return corpus_cases(config["clinical"], corpus.get("soft_C1", 0.8),
                        corpus.get("soft_phi", [-90.0]))


def solve(mesh: Path, config: dict[str, Any], setting: str, skin: SkinLayer, ratio: float,
          cases: list[Case], out: Path) -> None:
    """Child: solve the cases with one setting, writing the rows as they come."""
    from fem.case import CaseRunner

    settings = SolverSettings.from_config(config)
    if setting.startswith("skin"):
        settings = replace(settings, skin=replace(skin, wrinkles=setting == "skin"),
                           tissues=Tissues({Tissue.SKIN: ratio}))
    else:
        settings = replace(settings, skin=None)
    rows = []
    with CaseRunner(mesh, settings) as runner:
        for case in cases:
            result, timings = runner.solve(case)
            s = runner.summary(case, result, timings, measure_unit=False)
            rows.append({"case": case.id, "status": s["status"], "load": s["load_fraction"],
                         "steps": s["load_steps"], "newton": s["total_newton_iterations"],
                         "wall_s": s["wall_s"]["solve"],
                         "max_disp_mm": s["max_disp_mm"]})
            (out / f"{setting}.json").write_text(json.dumps(rows))


def main(argv: list[str] | None = None) -> int:
    """Command line: see the module docstring."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("anatomy", help="a corpus anatomy (meshes.corpus.ANATOMIES)")
    parser.add_argument("--config", type=Path, default=Path("config.yaml"))
    parser.add_argument("--thickness", type=float, default=DEFAULT_SKIN_THICKNESS)
    parser.add_argument("--ratio", type=float, default=Tissues().ratio(Tissue.SKIN))
    parser.add_argument("--cases", type=parse_case, nargs="+")
    parser.add_argument("--out", type=Path)
    parser.add_argument("--limit-s", type=float, default=1800.0)
    parser.add_argument("--settings", nargs="+", choices=SETTINGS, default=list(SETTINGS[:2]))
    parser.add_argument("--child", nargs=2, metavar=("MESH", "SETTING"), help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    out = args.out or Path(tempfile.mkdtemp(prefix="skin_"))
    out.mkdir(parents=True, exist_ok=True)
    config = read_config_file(args.config)
    cases = args.cases or cases_of(config)
    skin = SkinLayer(args.thickness)
    if args.child:
        solve(Path(args.child[0]), config, args.child[1], skin, args.ratio, cases, out)
        return 0
    mesh = out / "mesh.xdmf"
    if not mesh.is_file():
        mesh = make_mesh(config, args.anatomy, out)
    extra = [f"{c.C1}:{c.phi}:{c.theta}" for c in cases]
    results = {}
    for setting in args.settings:
        command = [sys.executable, "-m", "benchmarks.skin", args.anatomy, "--config",
                   str(args.config), "--thickness", str(args.thickness), "--ratio",
                   str(args.ratio), "--out", str(out), "--cases", *extra,
                   "--child", str(mesh), setting]
        try:
            subprocess.run(command, check=True, timeout=args.limit_s, capture_output=True)
        except subprocess.TimeoutExpired:
            print(f"{setting}: stopped after {args.limit_s:.0f} s")
        except subprocess.CalledProcessError as err:
            print(f"{setting}: failed: {err.stderr.decode()[-400:]}")
        path = out / f"{setting}.json"
        results[setting] = {r["case"]: r for r in json.loads(path.read_text())} \
            if path.is_file() else {}
    print(f"{args.anatomy}: skin {1e3 * args.thickness:g} mm at {args.ratio:g} × the fat")
    print(f"{'case':30} {'setting':12} {'status':10} {'λ':>6} {'steps':>5} {'Newton':>6} "
          f"{'wall s':>8} {'max|u| mm':>9} {'skin/hom.':>9}")
    for case in cases:
        for setting in args.settings:
            r = results[setting].get(case.id)
            if r is None:
                print(f"{case.id:30} {setting:12} {'not run':10}")
                continue
            other = results.get("homogeneous", {}).get(case.id)
            ratio = r["max_disp_mm"] / other["max_disp_mm"] if setting != "homogeneous" and other \
                and other["status"] == r["status"] == "converged" else None
            print(f"{case.id:30} {setting:12} {r['status']:10} {r['load']:6.3f} {r['steps']:5d} "
                  f"{r['newton']:6d} {r['wall_s']:8.1f} {r['max_disp_mm']:9.2f} "
                  f"{'-' if ratio is None else format(ratio, '.3f'):>9}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
