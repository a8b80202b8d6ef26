"""The interactive 3D view: one HTML file that predicts and draws the breast under any gravity.

:func:`build_viewer` writes ``index.html``, which opens from the file system with no server
and no network. It holds:

* the surrogate, exported by :func:`surrogate.export.export_web`, whose forward pass runs in
  the page (``app.js``, the same computation as :meth:`surrogate.predict.Surrogate.predict`);
* the mesh's surface (its exterior triangles on the material points);
* the FE displacement of some sweep cases (the clinical ones first), to compare with;
* ``app.js`` and three.js (the npm package pinned in ``package.json``, installed by
  ``make setup``) bundled into one script by esbuild; three.js's licence is kept in the
  bundle and written beside the page.
"""

from __future__ import annotations

import json
import logging
import os
import shutil
import subprocess
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import jinja2
import numpy as np

from fem.dataset import read_dataset
from fem.sweep import ClinicalCase
from meshes.quality import exterior_faces
from surrogate.exceptions import OutsideMeshError
from surrogate.export import encode_array, export_web
from surrogate.fields import read_mesh_vertices
from surrogate.predict import Surrogate

log = logging.getLogger(__name__)

HERE = Path(__file__).resolve().parent
REPO = HERE.parent.parent
NODE_MODULES = REPO / "node_modules"
ESBUILD = NODE_MODULES / ".bin" / "esbuild"
THREE_LICENSE = NODE_MODULES / "three" / "LICENSE"
LICENCE = "THREE-LICENSE.txt"
"""three.js's licence, written beside the page."""
MAX_FE_CASES = 24
"""FE cases carried for comparison: the clinical cases and others spread over the sweep (each
adds its surface field, about 1 % of the page per 1,000 surface vertices)."""


class ViewerError(RuntimeError):
    """The viewer cannot be built (e.g. its JavaScript tools are not installed)."""


def bundle_script(entry: Path = HERE / "app.js") -> str:
    """``entry`` and the three.js it imports, as one minified script (esbuild).

    Raises:
        ViewerError: if esbuild or three.js is missing (``make setup`` runs ``npm ci``).
    """
    if not ESBUILD.is_file() or not THREE_LICENSE.is_file():
        raise ViewerError(
            f"the viewer needs three.js and esbuild from npm in {NODE_MODULES}: run `make setup` "
            "(or `npm ci` in the repository)"
        )
    run = subprocess.run(
        [str(ESBUILD), str(entry), "--bundle", "--minify", "--format=iife",
         "--legal-comments=inline", "--target=es2020", "--log-level=warning"],
        capture_output=True, text=True, cwd=REPO, check=False,
    )
    if run.returncode != 0:
        raise ViewerError(f"esbuild could not bundle {entry}: {run.stderr.strip()}")
    return run.stdout


def surface(model: Surrogate, mesh_xdmf: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """The mesh's exterior triangles on the material points.

    Returns:
        ``(vertices, triangles)``: the material point of each surface vertex, and the triangles
        (m, 3) on the surface vertices.
    """
    _, cells = read_mesh_vertices(mesh_xdmf, model.node_index, model.X)
    vertices, triangles = np.unique(exterior_faces(cells), return_inverse=True)
    return vertices, triangles.reshape(-1, 3)


def fe_cases(
    dataset_path: str | Path,
    vertices: np.ndarray,
    clinical: Sequence[ClinicalCase] = (),
    limit: int = MAX_FE_CASES,
    material_points: np.ndarray | None = None,
    inner: np.ndarray | None = None,
) -> list[dict[str, Any]]:
    """FE surface displacements (mm) of the clinical cases and of others spread over the sweep.

    With ``inner`` (named material points inside the body, (M, 3), m), each case carries the FE
    displacement there too (``inner_u_mm``), by the mesh's own shape functions (quadratic where
    the dataset has the fields at every node), where the dataset has the mesh's cells.

    Raises:
        ViewerError: if ``material_points`` (the model's) are not the dataset's.
    """
    ds = read_dataset(dataset_path, nodes=inner is not None)
    if material_points is not None and (
            ds.X.shape != material_points.shape
            or not np.allclose(ds.X, material_points, rtol=0, atol=1e-6)):
        raise ViewerError(f"{dataset_path} holds {ds.n_points} material points that are not "
                          f"the model's {len(material_points)}: give the dataset the model was "
                          "trained on")
    good = np.flatnonzero(ds.converged)
    chosen: list[int] = []
    labels: dict[int, str] = {}
    for item in clinical:
        try:
            i = ds.case_index(item.case.C1, item.case.phi, item.case.theta)
        except KeyError:
            continue
        if ds.converged[i] and i not in chosen:
            chosen.append(i)
            # a case the config gave no label is named by its numbers alone
            labels[i] = item.label if item.label != item.case.id else ""
    spread = good[np.linspace(0, len(good) - 1, min(limit, len(good))).round().astype(int)]
    for i in spread:
        if len(chosen) >= limit:
            break
        if int(i) not in chosen:
            chosen.append(int(i))
    at_inner = _fe_at(ds, inner) if inner is not None else None
    out = []
    for i in chosen:
        name = f"C1 = {ds.C1[i]:g} kPa, Φ = {ds.phi[i]:g}°, θ = {ds.theta[i]:g}°"
        case = {
            "id": str(ds.ids[i]),
            "label": f"{labels[i]}: {name}" if labels.get(i) else name,
            "C1": float(ds.C1[i]),
            "phi": float(ds.phi[i]),
            "theta": float(ds.theta[i]),
            "u_mm": encode_array(ds.displacement[i][vertices], "float32"),
        }
        if at_inner is not None:
            case["inner_u_mm"] = encode_array(at_inner(i), "float32")
        out.append(case)
    return out


def _fe_at(ds: Any, points: np.ndarray) -> Any:
    """A function of a case's index: its FE displacement (mm) at ``points``; None without cells.

    Raises:
        ViewerError: if a point lies outside the mesh.
    """
    from surrogate.interpolation import interpolate, locate_in

    if ds.nodes is not None and ds.nodes.displacement is not None:  # every node: quadratic
        X, cells, field = ds.nodes.X, ds.nodes.cells, ds.nodes.displacement
    elif ds.cells is not None:
        X, cells, field = ds.X, ds.cells, ds.displacement
    else:
        return None
    try:
        rows, weights = locate_in(X, cells, points)
    except ValueError as err:
        raise ViewerError(f"the named points: {err}") from None
    return lambda i: interpolate(field[i].astype(np.float64), rows, weights)


def inner_points(model: Surrogate, names: list[str], X: np.ndarray) -> dict[str, Any] | None:
    """Named material points ``X`` (M, 3), m, for the page: their names and the model there.

    Raises:
        ViewerError: if a point lies outside the body (or the model cannot answer between its
            own points), naming the points.
    """
    if not names:
        return None
    try:
        at = model.at(X)
    except OutsideMeshError as err:
        raise ViewerError(f"the named points: {err.naming(names)}") from None
    except ValueError as err:
        raise ViewerError(f"the named points ({', '.join(names)}): {err}") from None
    return {"names": names, "model": export_web(at)}


def build_viewer(
    model_dir: str | Path,
    mesh_xdmf: str | Path,
    dataset_path: str | Path | None,
    output: str | Path,
    clinical: Sequence[ClinicalCase] = (),
    postures: Sequence[dict[str, Any]] = (),
    points: Sequence[tuple[str, Sequence[float]]] = (),
    start: Mapping[str, Any] | None = None,
    initial: Mapping[str, float] | None = None,
) -> dict[str, Any]:
    """Write the viewer page ``output`` (and three.js's licence beside it).

    Args:
        model_dir: the surrogate's model folder.
        mesh_xdmf: the mesh the surrogate was trained on.
        dataset_path: the sweep's dataset (the FE cases to compare with); None: no FE cases.
        output: the page to write.
        clinical: the config's clinical cases (:func:`fem.sweep.clinical_list`), carried
            first, with their labels.
        postures: the postures offered as buttons, ``{name, phi, theta, note}`` each
            (``surrogate_study.postures.directions``): g = [cos Φ, sin Φ cos θ,
            sin Φ sin θ] in the body's frame.
        points: named material points inside the body, ``(name, (x, y, z))`` in the model's
            reference frame, m (a tumour's centre and margin): the page predicts and draws
            them too (:meth:`surrogate.predict.Surrogate.at`).
        start: the posture the page first measures movement from, ``{name, phi, theta}``
            (e.g. the posture an imaged breast was imaged in); None: from rest. The user can
            choose rest, any posture of ``postures`` or the sliders' posture in the page.
        initial: the query the page opens at, ``{C1, phi, theta}``; None: the first FE case
            (the first clinical case), or without FE cases prone at the middle C1.

    Returns:
        What the page holds: points, surface vertices and triangles, FE cases, named points,
        bytes.

    Raises:
        ViewerError: if a named point lies outside the body, or the dataset is not the
            model's.
    """
    model = Surrogate.load(model_dir)
    vertices, triangles = surface(model, mesh_xdmf)
    names = [str(name) for name, _ in points]
    X = np.array([list(xyz) for _, xyz in points], dtype=float) if names else None
    inner = inner_points(model, names, X)  # first: a point outside the body is named here
    cases = ([] if dataset_path is None
             else fe_cases(dataset_path, vertices, clinical, material_points=model.X, inner=X))
    data = {
        "model": export_web(model),
        "surface": {"points": encode_array(vertices, "int32"),
                    "triangles": encode_array(triangles, "int32")},
        "fe_cases": cases,
        "inner": inner,
        # the postures a movement can be measured from, as the page's select lists them
        "starts": [{"name": str(p["name"]), "phi": float(p["phi"]),
                    "theta": float(p.get("theta", 0.0)), "selected": False}
                   for p in [*postures, *([start] if start else [])]],
    }
    if start:
        data["starts"][-1]["selected"] = True
    C1s = [c for c in model.trained.range_checks()["c1_kPa"] if c is not None]
    first = initial or (cases[0] if cases else {
        "C1": float(np.median(C1s)) if C1s else 1.0, "phi": 180.0, "theta": 0.0})
    env = jinja2.Environment(
        loader=jinja2.FileSystemLoader(HERE), autoescape=True, keep_trailing_newline=True
    )
    page = env.get_template("page.html.j2").render(
        title="Breast under gravity: the surrogate, live",
        subtitle=f"{model.config.architecture} {model.config.activation} network, "
        f"{len(model.X)} material points, predicted in this page",
        initial={"C1": first["C1"], "phi": first["phi"], "theta": first["theta"]},
        fe_cases=bool(cases),  # without a dataset, no FE controls
        inner=bool(names),
        presets=[{"theta": 0.0, "note": "", **posture} for posture in postures],
        starts=data["starts"],
        axes="x anterior→posterior · y medial→lateral · z caudal→cranial",
        provenance=f"model {Path(model_dir).name}, mesh {Path(mesh_xdmf).name}; three.js "
        "(MIT licence, THREE-LICENSE.txt beside this page)",
        data=json.dumps(data, separators=(",", ":")).replace("</", "<\\/"),
        bundle=bundle_script().replace("</script", "<\\/script"),
    )
    output = Path(output)
    output.parent.mkdir(parents=True, exist_ok=True)
    tmp = output.with_name(f".{output.name}.{os.getpid()}.tmp")  # no name a user may have
    try:
        tmp.write_text(page, encoding="utf-8")
        tmp.replace(output)
    finally:
        tmp.unlink(missing_ok=True)
    shutil.copyfile(THREE_LICENSE, output.parent / LICENCE)
    info = {"points": len(model.X), "surface_vertices": int(len(vertices)),
            "triangles": len(triangles),
            "fe_cases": len(cases), "named_points": len(points),
            "bytes": output.stat().st_size}
    log.info("viewer: %s", info)
    return info
