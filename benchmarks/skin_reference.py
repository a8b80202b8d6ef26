"""Benchmark: the skin membrane against a skin resolved by cells, on the config's anatomy.

``python -m benchmarks.skin_reference [--config config.yaml] [--thickness 0.0015]
[--ratio 18.5] [--in-plane 0.006] [--cases C1:PHI ...] [--settings resolved membrane ...]
[--finer-in-plane 0.004] [--point X Y Z] [--work DIR] [--out FILE] [--limit-s 1800]``

The config's ``mesh`` section (a parametric breast, at its own size) is meshed twice: as the
workflow meshes it (the *default mesh*), and with the skin as a layer of cells ``--thickness``
thick under the ``skin`` boundary (:mod:`meshes.skin_layer`: one cell across, in-plane
``--in-plane`` m under the skin, growing into the body by the mesh's grading; straight-sided),
once with the layer's cells tagged skin and once with every cell fat. It then solves the
config's clinical cases (or ``--cases``) with the config's solver settings, each setting in a
fresh process one after the other (``--limit-s`` seconds each, its log WORK/SETTING.log):

* ``resolved``: the layer's cells are skin, ``--ratio`` times the fat's C1, no membrane;
* ``membrane``: the same cells all fat, the skin membrane (``material.skin``, wrinkling) on the
  skin facets: the same discretisation, so the difference is the membrane model's alone;
* ``default-membrane``: the default mesh with the membrane (what a user runs);
* ``default-none``: the default mesh without skin (today's default);
* ``resolved-2``: the layer two cells across (is the layer resolved?);
* optional: ``plain-membrane`` (the membrane that resists compression, on the layer's fat
  cells) and ``fat-none`` (the layer's fat cells, no skin); with ``--finer-in-plane`` H,
  ``resolved-fine`` and ``membrane-fine`` on a layer of in-plane size H (the body refined
  with it, so the two are compared with each other).

Per case and setting it prints the outcome, load steps, Newton iterations, solve seconds,
unknowns, max |u| and its ratio to ``resolved`` (``-fine``: to ``resolved-fine``), |u| at an
interior point (``--point``, else the centre of the mound's ellipsoid) and its ratio, the
share of the skin's area pressed narrower than it would contract of itself, where the wrinkling
membrane carries nothing (``relaxed``), the share pressed narrower by more than a bonded film
of the skin's ratio takes before it wrinkles (``beyond``: :func:`wrinkling_strain`), and the
least width over the natural one (``width``; :func:`skin_compression`). The JSON (``--out``,
default WORK/skin_reference.json) holds every row, the meshes' figures and the point.
"""

from __future__ import annotations

import argparse
import json
import logging
import subprocess
import sys
import tempfile
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.skin import parse_case
from fem.configfile import read_config_file
from fem.materials import DEFAULT_SKIN_THICKNESS, SkinLayer, Tissues
from fem.parameters import SolverSettings
from fem.sweep import Case, clinical_cases
from meshes.tags import Tissue

#: setting -> (its mesh, the membrane: None, "wrinkling" or "plain"), in the order solved.
SETTINGS: dict[str, tuple[str, str | None]] = {
    "resolved": ("layer", None),
    "membrane": ("layer-fat", "wrinkling"),
    "default-membrane": ("default", "wrinkling"),
    "default-none": ("default", None),
    "resolved-2": ("layer-2", None),
    "plain-membrane": ("layer-fat", "plain"),
    "fat-none": ("layer-fat", None),
    "resolved-fine": ("layer-fine", None),
    "membrane-fine": ("layer-fine-fat", "wrinkling"),
}
DEFAULT_SETTINGS = ("resolved", "membrane", "default-membrane", "default-none", "resolved-2")
#: how close the membrane is asked to be to the resolved layer (issue 69): 5 % of max |u|
TOLERANCE = 0.05


def reference_of(setting: str) -> str:
    """The setting each one is compared with: the resolved layer on its own cells."""
    return "resolved-fine" if setting.endswith("-fine") else "resolved"


def make_meshes(config: dict[str, Any], work: Path, thickness: float, in_plane: float,
                finer_in_plane: float | None, needed: set[str]) -> dict[str, Any]:
    """Write the meshes ``needed`` (names of :data:`SETTINGS`) under ``work``; their reports."""
    from meshes.config import MeshConfig, make_mesh
    from meshes.skin_layer import SkinLayerSpec, write_skin_layer_mesh

    mesh = MeshConfig.from_mapping(config["mesh"])
    if mesh.source != "parametric":
        raise SystemExit("the skin layer is meshed on the parametric breast: mesh.source must "
                         f"be parametric, not {mesh.source}")
    straight = replace(mesh.size, order=1)
    layers = {"layer": SkinLayerSpec(thickness, 1, in_plane),
              "layer-2": SkinLayerSpec(thickness, 2, in_plane)}
    if finer_in_plane is not None:
        layers["layer-fine"] = SkinLayerSpec(thickness, 1, finer_in_plane)
    reports = {}
    if "default" in needed:
        folder = work / "default"
        folder.mkdir(parents=True, exist_ok=True)
        reports["default"] = make_mesh(mesh, folder / "mesh.xdmf", folder / "quality.json",
                                       folder / "mesh.png")
    for name, spec in layers.items():
        if name not in needed and f"{name}-fat" not in needed:
            continue
        folder = work / name
        folder.mkdir(parents=True, exist_ok=True)
        reports[name] = write_skin_layer_mesh(mesh.geometry, straight, spec,
                                              folder / "mesh.xdmf", folder / "fat.xdmf")
    return reports


def mesh_path(work: Path, name: str) -> Path:
    """The XDMF of mesh ``name`` (``-fat``: the layer's mesh with every cell fat)."""
    if name.endswith("-fat"):
        return work / name.removesuffix("-fat") / "fat.xdmf"
    return work / name / "mesh.xdmf"


def wrinkling_strain(ratio: float) -> float:
    """The compression at which a stiff film bonded to a thick soft substrate wrinkles.

    ε_c = (3 E_s / E_f)^(2/3) / 4 for a film on a half-space of the same Poisson's ratio
    (Allen 1969; Chen & Hutchinson 2004), E_f / E_s the skin's ratio to the fat: below it a
    bonded skin stays flat and carries the compression; the wrinkling membrane carries none.
    """
    return 0.25 * (3.0 / ratio) ** (2.0 / 3.0)


def skin_compression(runner: Any, critical: float) -> dict[str, float]:
    """Where the skin is pressed narrower than it would contract of itself.

    From the corners of the ``skin`` facets (their straight triangles, before and after),
    with λ1 ≥ λ2 each triangle's principal in-plane stretches: a sheet stretched by λ1 along
    one direction contracts to λ1^(-1/2) across it of itself; the wrinkling membrane carries
    no load where λ2 is below that (or λ1 ≤ 1), where a resolved layer, or the plain membrane,
    resists. Returns the share of the skin's area where it is so (``relaxed_area_fraction``),
    the share pressed narrower by more than ``critical`` (``beyond_critical_area_fraction``:
    :func:`wrinkling_strain`, where a real skin would wrinkle) and the least λ2 λ1^(1/2)
    (``least_width_ratio``: 1 at the natural width).
    """
    from dolfinx.cpp.mesh import entities_to_geometry

    from fem.interpolation import evaluate
    from meshes.tags import Boundary

    mesh = runner.mesh
    facets = runner.facet_tags.find(int(Boundary.SKIN))
    nodes = entities_to_geometry(mesh._mesh, 2, facets, False)[:, :3]
    X = mesh.geometry.x[nodes]  # (facets, 3 corners, 3)
    u, _ = evaluate(runner.problem.displacement(), X.reshape(-1, 3))
    x = X + u.reshape(X.shape)

    def metric(p: np.ndarray) -> np.ndarray:
        e = np.stack([p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]], axis=1)  # (facets, 2, 3)
        return np.einsum("fik,fjk->fij", e, e)

    G, g = metric(X), metric(x)
    stretch2 = np.sort(np.linalg.eigvals(np.linalg.solve(G, g)).real, axis=1)
    width = np.sqrt(stretch2[:, 0]) * stretch2[:, 1] ** 0.25  # λ2 λ1^(1/2)
    relaxed = (width < 1.0) | (stretch2[:, 1] <= 1.0)
    area = 0.5 * np.sqrt(np.linalg.det(G))
    return {"relaxed_area_fraction": float(area[relaxed].sum() / area.sum()),
            "beyond_critical_area_fraction": float(area[width < 1.0 - critical].sum()
                                                   / area.sum()),
            "least_width_ratio": float(width.min())}


def solve(config: dict[str, Any], work: Path, setting: str, thickness: float, ratio: float,
          cases: list[Case], point: np.ndarray) -> None:
    """Child: solve the cases with one setting, writing its rows as they come."""
    from fem.case import CaseRunner
    from fem.interpolation import evaluate

    mesh, membrane = SETTINGS[setting]
    settings = replace(SolverSettings.from_config(config),
                       tissues=Tissues({Tissue.SKIN: ratio}),
                       skin=None if membrane is None
                       else SkinLayer(thickness, wrinkles=membrane == "wrinkling"))
    rows = []
    with CaseRunner(mesh_path(work, mesh), settings) as runner:
        for case in cases:
            result, timings = runner.solve(case)
            s = runner.summary(case, result, timings, measure_unit=False)
            at_point, distance = evaluate(runner.problem.displacement(), point[None, :])
            rows.append({"setting": setting, "case": case.id, "status": s["status"],
                         "load": s["load_fraction"], "steps": s["load_steps"],
                         "newton": s["total_newton_iterations"], "wall_s": s["wall_s"]["solve"],
                         "setup_s": s["wall_s"]["setup"], "dofs": s["dofs"],
                         "max_disp_mm": s["max_disp_mm"],
                         "point_disp_mm": float(1e3 * np.linalg.norm(at_point[0])),
                         "point_outside_m": float(distance[0]),
                         **skin_compression(runner, wrinkling_strain(ratio))})
            (work / f"{setting}.json").write_text(json.dumps(rows))


def mound_centre(config: dict[str, Any]) -> np.ndarray:
    """The centre of the mound's ellipsoid: an interior point where a tumour may lie."""
    from meshes.parametric import BreastGeometry

    geometry = BreastGeometry.from_mapping(config["mesh"].get("geometry") or {})
    base, axis = geometry.mound_frame()
    return base + geometry.mound_offset * axis


def table(results: dict[str, dict[str, dict]], cases: list[Case]) -> list[str]:
    """The printed rows: per case and setting, with the ratios to the resolved layer."""
    lines = [f"{'case':28} {'setting':17} {'status':9} {'steps':>5} {'Newton':>6} "
             f"{'solve s':>7} {'unknowns':>8} {'max|u| mm':>9} {'/resolved':>9} "
             f"{'point mm':>8} {'/resolved':>9} {'relaxed':>7} {'beyond':>6} {'width':>5}"]
    for case in cases:
        for setting, rows in results.items():
            r = rows.get(case.id)
            if r is None:
                lines.append(f"{case.id:28} {setting:17} not run")
                continue
            ref = results.get(reference_of(setting), {}).get(case.id)
            both = ref is not None and ref["status"] == r["status"] == "converged"
            ratio = format(r["max_disp_mm"] / ref["max_disp_mm"], ".3f") if both else "-"
            point = format(r["point_disp_mm"] / ref["point_disp_mm"], ".3f") if both else "-"
            lines.append(
                f"{case.id:28} {setting:17} {r['status']:9} {r['steps']:5d} {r['newton']:6d} "
                f"{r['wall_s']:7.1f} {r['dofs']:8d} {r['max_disp_mm']:9.3f} {ratio:>9} "
                f"{r['point_disp_mm']:8.3f} {point:>9} "
                f"{100 * r['relaxed_area_fraction']:6.0f}% "
                f"{100 * r['beyond_critical_area_fraction']:5.1f}% {r['least_width_ratio']:5.2f}")
    return lines


def verdicts(results: dict[str, dict[str, dict]], cases: list[Case]) -> list[str]:
    """Per membrane setting: the cases within :data:`TOLERANCE` of the resolved layer."""
    lines = []
    for setting in ("membrane", "default-membrane", "plain-membrane", "membrane-fine",
                    "resolved-2"):
        if setting not in results:
            continue
        ratios = {}
        for case in cases:
            r, ref = (results[setting].get(case.id),
                      results.get(reference_of(setting), {}).get(case.id))
            if r and ref and r["status"] == ref["status"] == "converged":
                ratios[case.id] = r["max_disp_mm"] / ref["max_disp_mm"] - 1.0
        within = [c for c, e in ratios.items() if abs(e) <= TOLERANCE]
        worst = max(ratios.items(), key=lambda item: abs(item[1]), default=None)
        lines.append(f"{setting} against {reference_of(setting)}: {len(within)} of "
                     f"{len(ratios)} converged cases within {100 * TOLERANCE:g} % of max |u|"
                     + (f"; largest difference {100 * worst[1]:+.1f} % ({worst[0]})"
                        if worst else ""))
    return lines


def main(argv: list[str] | None = None) -> int:
    """Command line: see the module docstring."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--config", type=Path, default=Path("config.yaml"))
    parser.add_argument("--thickness", type=float, default=DEFAULT_SKIN_THICKNESS)
    parser.add_argument("--ratio", type=float, default=Tissues().ratio(Tissue.SKIN))
    parser.add_argument("--in-plane", type=float, default=0.006,
                        help="the layer's cells' size along the skin, m")
    parser.add_argument("--finer-in-plane", type=float,
                        help="also resolved-fine and membrane-fine at this in-plane size")
    parser.add_argument("--cases", type=parse_case, nargs="+")
    parser.add_argument("--settings", nargs="+", choices=list(SETTINGS),
                        default=list(DEFAULT_SETTINGS))
    parser.add_argument("--point", type=float, nargs=3, help="interior point, m")
    parser.add_argument("--work", type=Path, help="working folder (a temporary one by default)")
    parser.add_argument("--out", type=Path, help="the JSON (default WORK/skin_reference.json)")
    parser.add_argument("--limit-s", type=float, default=1800.0)
    parser.add_argument("--child", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    config = read_config_file(args.config)
    cases = args.cases or clinical_cases(config["clinical"])
    point = np.array(args.point) if args.point else mound_centre(config)
    work = args.work or Path(tempfile.mkdtemp(prefix="skin_reference_"))
    if args.child:
        logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(message)s")
        solve(config, work, args.child, args.thickness, args.ratio, cases, point)
        return 0
    settings = list(args.settings)
    if args.finer_in_plane is not None:
        settings += [s for s in ("resolved-fine", "membrane-fine") if s not in settings]
    settings = [s for s in SETTINGS if s in settings]  # references first
    work.mkdir(parents=True, exist_ok=True)
    needed = {SETTINGS[s][0].removesuffix("-fat") for s in settings}
    reports = make_meshes(config, work, args.thickness, args.in_plane, args.finer_in_plane,
                          needed)
    results: dict[str, dict[str, dict]] = {}
    for setting in settings:
        command = [sys.executable, "-m", "benchmarks.skin_reference", "--config",
                   str(args.config), "--thickness", str(args.thickness), "--ratio",
                   str(args.ratio), "--work", str(work), "--point", *map(str, point),
                   "--cases", *[f"{c.C1}:{c.phi}:{c.theta}" for c in cases],
                   "--child", setting]
        log = work / f"{setting}.log"
        try:
            with open(log, "w") as output:
                subprocess.run(command, check=True, timeout=args.limit_s, stdout=output,
                               stderr=subprocess.STDOUT)
        except subprocess.TimeoutExpired:
            print(f"{setting}: stopped after {args.limit_s:.0f} s (its log: {log})")
        except subprocess.CalledProcessError:
            print(f"{setting}: failed: {log.read_text(errors='replace')[-400:]}")
        path = work / f"{setting}.json"
        results[setting] = {r["case"]: r for r in json.loads(path.read_text())} \
            if path.is_file() else {}
    for ref in ("resolved-fine", "resolved"):  # a reference solved by an earlier run
        path = work / f"{ref}.json"
        if ref not in results and path.is_file():
            results = {ref: {r["case"]: r for r in json.loads(path.read_text())}, **results}
            print(f"{ref}: read from {path} (an earlier run on the same meshes)")
    print(f"skin {1e3 * args.thickness:g} mm at {args.ratio:g} × the fat (a bonded film of it "
          f"wrinkles past {100 * wrinkling_strain(args.ratio):.1f} % compression); point "
          f"{np.round(1e3 * point, 1).tolist()} mm")
    for name, report in reports.items():
        layer = report.get("skin_layer")
        extra = "" if layer is None else (
            f", {layer['skin_cells']} skin cells {layer['spec']['cells_across']} across, "
            f"in-plane edges {1e3 * layer['in_plane_edge_m']['mean']:.1f} mm mean "
            f"({1e3 * layer['in_plane_edge_m']['min']:.1f}–"
            f"{1e3 * layer['in_plane_edge_m']['max']:.1f}), {layer['skin_volume_ml']:.1f} ml")
        print(f"mesh {name}: {report['cells']} cells, {report['volume_ml']:.1f} ml{extra}")
    lines = table(results, cases) + verdicts(results, cases)
    outside = max((r["point_outside_m"] for rows in results.values() for r in rows.values()),
                  default=0.0)
    if outside > 1e-6:
        lines.append(f"the point lies {1e3 * outside:.2f} mm outside some mesh's cells")
    print("\n".join(lines))
    out = args.out or work / "skin_reference.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({
        "thickness_m": args.thickness, "ratio": args.ratio, "in_plane_m": args.in_plane,
        "finer_in_plane_m": args.finer_in_plane, "point_m": point.tolist(),
        "tolerance": TOLERANCE, "meshes": reports,
        "rows": [r for rows in results.values() for r in rows.values()]}, indent=1))
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
