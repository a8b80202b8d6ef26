"""Probe the workflow with bad configs and bad files end to end, as a careful or hostile user.

    .venv/bin/python tests/probe_inputs.py [-j JOBS] [-k PATTERN] [--keep DIR]

Every probe runs a real entry point in a working directory of its own: the project's
Snakefile (``snakemake -n`` for a config, the mesh job for a geometry file, the aggregation
job for a case folder's files), ``python -m run.config``, ``make reproduce``, or a
command (``fem.cli``, ``fem.reference``, ``surrogate.cli predict``,
``studies.reference_state.stiffness``,
``report.viewer``) on a solved three-case sweep and a small model trained on it. A probe
passes when the run stops (or, for an input that must be answered, answers), names the problem
in the words given (on the console or in the job's log), writes
nothing it should not (no ``results/`` for a bad config, no mesh for a bad file, the previous
dataset untouched for bad case files) and writes no file outside its working directory.

It prints one line per probe and, last, ``N passed, M failed``; it exits 1 if any failed.
``tests/test_probe_inputs.py`` runs it in the suite.
"""

from __future__ import annotations

import argparse
import copy
import json
import re
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))  # run as a script: the suite's helpers are in tests/
from tests.conftest import snakemake_command  # noqa: E402

BASE_CONFIG = yaml.safe_load((REPO / "tests" / "config.yaml").read_text())
RIB = {"plane": {"point": [0.0, 0.0, 0.0], "normal": [1.0, 0.0, 0.0]}, "distance": 0.001}


def snakemake(workdir: Path, config: Path | None, *args: str) -> subprocess.CompletedProcess:
    """The project's Snakefile in ``workdir`` (on ``config``, or on its own config.yaml)."""
    return subprocess.run(snakemake_command(workdir, *args, config=config), cwd=workdir,
                          capture_output=True, text=True, timeout=300)


@dataclass(frozen=True)
class Outcome:
    """What a probe found: passed, and what it saw (for a failed probe, what was wrong)."""

    passed: bool
    detail: str


def expect(run: subprocess.CompletedProcess, text: str, where: str | None = None) -> Outcome:
    """The run failed and ``text`` (a regular expression) is in its output or in ``where``."""
    said = run.stdout + run.stderr
    if where is not None:
        said = Path(where).read_text() if Path(where).is_file() else ""
    if run.returncode == 0:
        return Outcome(False, "the run succeeded")
    if not re.search(text, said, re.S):
        tail = " ".join(said.split())[-400:]
        return Outcome(False, f"{text!r} not in {'the log' if where else 'the output'}: ...{tail}")
    return Outcome(True, " ".join(re.search(text, said, re.S)[0].split())[:120])


# -- bad configs ---------------------------------------------------------------------------


def config_with(**changes: Any) -> dict[str, Any]:
    """tests/config.yaml with ``section__key=value`` changes (``section=value`` replaces)."""
    config = copy.deepcopy(BASE_CONFIG)
    for dotted, value in changes.items():
        *parents, last = dotted.split("__")
        node = config
        for key in parents:
            node = node.setdefault(key, {})
        node[last] = value
    return config


SENTINEL = "probe-must-not-exist"


def config_probe(config: dict[str, Any] | str, text: str) -> Callable[[Path], Outcome]:
    """Plan the workflow on ``config`` (a mapping, or a file's text): it must stop first.

    The run must name ``text``, create no ``results/`` and no file that a PETSc viewer option
    would have written.
    A mapping is given as ``--configfile``; a file's text (a syntax error) is the working
    directory's ``config.yaml``, which the Snakefile reads itself (Snakemake reads a
    ``--configfile`` without naming a syntax error's line). ``python -m run.config``, which
    ``make reproduce`` runs first, must name ``text`` too.
    """

    def probe(workdir: Path) -> Outcome:
        path = workdir / ("bad.yaml" if isinstance(config, dict) else "config.yaml")
        body = yaml.safe_dump(config) if isinstance(config, dict) else config
        path.write_text(body.replace("SENTINEL", str(workdir.parent / SENTINEL)))
        run = snakemake(workdir, path if isinstance(config, dict) else None, "-n", "-j1")
        outcome = expect(run, text)
        if outcome.passed and (workdir / "results").exists():
            return Outcome(False, "results/ was created")
        checked = subprocess.run(
            [sys.executable, "-m", "run.config", str(path)], capture_output=True, text=True
        )
        if outcome.passed and (checked.returncode != 2 or not re.search(text, checked.stderr)):
            return Outcome(False, f"python -m run.config: {checked.stderr.strip()[-300:]}")
        return outcome

    return probe


def alias_bomb(mapping: bool = False) -> str:
    """A ``sweep`` of nine anchors, each ten aliases of the one before (a billion laughs)."""
    lines = []
    for i in range(9):
        items = ["lol"] * 10 if i == 0 else [f"*a{i - 1}"] * 10
        body = ("{" + ", ".join(f"k{j}: {v}" for j, v in enumerate(items)) + "}" if mapping
                else "[" + ", ".join(items) + "]")
        lines.append(f"  a{i}: &a{i} {body}\n")
    return "sweep:\n" + "".join(lines)


CONFIG_PROBES: dict[str, Callable[[Path], Outcome]] = {
    "C1 list item below its bound": config_probe(
        config_with(sweep__C1_kPa=[1.0, -2.0]), r"sweep\.C1_kPa\.1: -2\.0 is less than"
    ),
    "C1 list item not a number": config_probe(
        config_with(sweep__C1_kPa=[1.0, "soft"]), r"sweep\.C1_kPa\.1: 'soft'"
    ),
    "split fractions that sum to 1.9": config_probe(
        config_with(dataset__split={"train": 0.9, "validation": 0.5, "test": 0.5}),
        r"dataset\.split.*?add up to 1",
    ),
    "PETSc option of the wrong kind": config_probe(
        config_with(fe__petsc_options={"snes_max_it": "lots"}), r"fe\.petsc_options.*?snes_max_it"
    ),
    "PETSc option with a typo": config_probe(
        config_with(fe__petsc_options={"snes_maxit_typo": 1}),
        r"fe\.petsc_options.*?snes_maxit_typo",
    ),
    "PETSc viewer that writes a file": config_probe(
        config_with(fe__petsc_options={"snes_view": "ascii:SENTINEL"}),
        r"fe\.petsc_options.*?snes_view",
    ),
    "PETSc monitor that writes a file": config_probe(
        config_with(fe__petsc_options={"ksp_monitor": "ascii:SENTINEL"}),
        r"fe\.petsc_options.*?ksp_monitor",
    ),
    "PETSc log to a file": config_probe(
        config_with(fe__petsc_options={"log_view": "ascii:SENTINEL"}),
        r"fe\.petsc_options.*?log_view",
    ),
    "C1 values one folder would merge": config_probe(
        config_with(sweep__C1_kPa=[1.0, 1.001, 5.0]), r"1\.0 and 1\.001 share one case folder"
    ),
    "a sweep of millions of cases": config_probe(
        config_with(sweep__C1_kPa={"start": 0.8, "stop": 5.0, "step": 0.0001}),
        r"sweep\.C1_kPa.*?more than 10000",
    ),
    "a sphere of too many directions": config_probe(
        config_with(sweep__sphere={"n": 100000}, sweep__C1_kPa=[1.0, 2.0, 3.0]),
        r"more than 50000",
    ),
    "an ablation's bad value under its own key": config_probe(
        config_with(surrogate_study__ablations={"x": {"activation": "sigmoidish"}}),
        r"surrogate_study\.ablations\.x\.activation",
    ),
    "density zero": config_probe(config_with(material__density=0.0), r"material\.density"),
    "network width zero": config_probe(config_with(surrogate__width=0), r"surrogate\.width"),
    "contact stiffness zero": config_probe(
        config_with(fe__contact={"stiffness": 0}), r"fe\.contact\.stiffness"
    ),
    "an unknown section": config_probe(config_with(not_a_section={"a": 1}), r"not_a_section"),
    "a YAML syntax error": config_probe(
        "sweep:\n  C1_kPa: [1.0, 5.0\n  phi_deg: [0.0]\n", r"YAML syntax error at line 3, column"
    ),
    "a config that is a list": config_probe("- mesh\n- fe\n", r"a config file is a mapping"),
    "a YAML alias bomb": config_probe(alias_bomb(), r"sweep\.a4 expands to more than 100000"),
    "a YAML alias bomb given as --configfile": config_probe(
        config_with(sweep=yaml.safe_load(alias_bomb())["sweep"]),
        r"sweep\.a4 expands to more than 100000"),
    "a YAML tag that would run a command": config_probe(
        'sweep: !!python/object/apply:os.system ["touch SENTINEL"]\n',
        r"could not determine a constructor for the tag",
    ),
    "an imported file in inches": config_probe(
        config_with(mesh__source="file", mesh__file={"path": "b.stl", "units": "inch",
                                                      "surfaces": {"rib": RIB}}),
        r"mesh\.file\.units",
    ),
    "an import without a rib rule": config_probe(
        config_with(mesh__source="file", mesh__file={"path": "b.stl", "surfaces": {}}),
        r"rib",
    ),
    "a split fraction that is NaN": config_probe(
        config_with(dataset__split={"train": float("nan"), "validation": 0.1, "test": 0.1}),
        r"dataset\.split\.train: nan is not a finite number",
    ),
    "a prediction budget that is NaN": config_probe(
        config_with(surrogate_study__prediction_budget_ms=float("nan")),
        r"surrogate_study\.prediction_budget_ms: nan is not a finite number",
    ),
    "a reference tolerance that is NaN": config_probe(
        config_with(reference_state__tolerance_mm=float("nan")),
        r"reference_state\.tolerance_mm: nan is not a finite number",
    ),
    "a 2 x 2 sweep of the clinical cases and two more": config_probe(
        config_with(sweep={"C1_kPa": [1.0, 5.0], "phi_deg": [0.0, 180.0]}),
        r"sweep: 4 cases, 2 of them clinical .*? at least 5 cases",
    ),
    "a NaN in the second observation's posture": config_probe(
        config_with(reference_state__observation={"file": "skin.csv", "phi": float("nan")}),
        r"reference_state\.observation\.phi: nan is not a finite number",
    ),
    "a posterior rule without the file's orientation": config_probe(
        config_with(mesh__source="file", mesh__size={"fold_size": None, "order": 1},
                    mesh__file={"path": "b.stl", "surfaces": {
                        "rib": {"posterior": {"angle": 30, "band": 0.01}}}}),
        r"a posterior rule needs to know where the patient's posterior is",
    ),
    "the parametric chest as an import's obstacle": config_probe(
        config_with(mesh__source="file", mesh__size={"fold_size": None, "order": 1},
                    mesh__file={"path": "b.stl", "surfaces": {"rib": RIB}},
                    fe__contact={"obstacle": "chest"}),
        r"fe\.contact\.obstacle 'chest'",
    ),
}


# -- bad geometry files --------------------------------------------------------------------


def box_surface(size: tuple[float, float, float] = (0.05, 0.2, 0.15)) -> tuple[np.ndarray, ...]:
    """A closed box surface of 12 outward triangles, metres."""
    x = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], float) * size
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    tris = np.array([t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))])
    return x, tris


def write_stl(path: Path, x: np.ndarray, tris: np.ndarray) -> None:
    import meshio

    meshio.write(str(path), meshio.Mesh(x, [("triangle", tris)]), binary=False)


def mesh_job_refuses(workdir: Path, config: dict[str, Any], name: str, text: str) -> Outcome:
    """The mesh job refuses ``config``, naming ``text``, and writes no mesh.

    The config is written as ``name``, without the chest contact.
    """
    del config["fe"]["contact"]
    path = workdir / name
    path.write_text(yaml.safe_dump(config))
    run = snakemake(workdir, path, "-j1", "results/mesh/mesh.xdmf")
    outcome = expect(run, text, workdir / "results/logs/mesh.log")
    if outcome.passed and (workdir / "results/mesh/mesh.xdmf").exists():
        return Outcome(False, "a mesh was written")
    return outcome


def file_probe(
    make: Callable[[Path], None],
    text: str,
    units: str = "m",
    rib: dict | None = None,
    suffix: str = ".stl",
) -> Callable[[Path], Outcome]:
    """Build the mesh from the file ``make`` writes: the job fails, its log names ``text``."""

    def probe(workdir: Path) -> Outcome:
        make(workdir / "breast.stl")
        config = config_with(
            mesh__source="file",
            mesh__size={"fold_size": None, "order": 1, "global_size": 0.03},
            mesh__file={"path": f"breast{suffix}", "units": units,
                        "surfaces": {"rib": rib or RIB}},
        )
        return mesh_job_refuses(workdir, config, "import.yaml", text)

    return probe


def _nan_vertex(path: Path) -> None:
    x, tris = box_surface()
    x[3, 2] = np.nan
    write_stl(path, x, tris)


def _open_surface(path: Path) -> None:
    x, tris = box_surface()
    write_stl(path, x, tris[:-1])


def _two_boxes_crossing(path: Path) -> None:
    x, tris = box_surface()
    write_stl(path, np.vstack([x, x + [0.02, 0.05, 0.05]]), np.vstack([tris, tris + 8]))


def _two_spheres(path: Path, apart: float) -> None:
    """Two closed spheres of 50 mm radius, ``apart`` metres between centres, in one OBJ.

    At 0.06 m they cross as mirror images (their triangles meet along edges), at 0.2 m not.
    """
    import trimesh

    ball = trimesh.creation.icosphere(subdivisions=2, radius=0.05)
    x, tris = np.asarray(ball.vertices), np.asarray(ball.faces)
    both = trimesh.Trimesh(np.vstack([x, x + [apart, 0.0, 0.0]]), np.vstack([tris, tris + len(x)]),
                           process=False)
    both.export(str(path.with_suffix(".obj")))


def _inverted_tetrahedra(path: Path) -> None:
    """The box as tetrahedra about its centre, three of them inside out (a .vtu volume mesh)."""
    import meshio
    from scipy.spatial import Delaunay

    x = np.vstack([box_surface()[0], [[0.025, 0.1, 0.075]]])
    tets = Delaunay(x).simplices.copy()
    tets[:3] = tets[:3, [1, 0, 2, 3]]
    meshio.write(str(path.with_suffix(".vtu")), meshio.Mesh(x, [("tetra", tets)]))


FILE_PROBES: dict[str, Callable[[Path], Outcome]] = {
    "an empty STL": file_probe(lambda p: p.write_text("solid e\nendsolid e\n"), r"is empty"),
    "a zero-byte STL": file_probe(lambda p: p.write_bytes(b""), r"is empty"),
    "an STL of random bytes": file_probe(
        lambda p: p.write_bytes(bytes(range(256)) * 3), r"cannot read|is empty"
    ),
    "a NaN vertex": file_probe(_nan_vertex, r"NaN or infinite coordinate"),
    "millimetres read as metres": file_probe(
        lambda p: write_stl(p, 1000 * box_surface()[0], box_surface()[1]),
        r"probably in other units.*?units: mm",
    ),
    "a 5 cm model declared in cm (a 32-litre breast)": file_probe(
        lambda p: write_stl(p, 1000 * box_surface((0.02, 0.05, 0.032))[0], box_surface()[1]),
        r"holds 32 l of tissue with units 'cm'.*?set mesh\.file\.units: mm",
        units="cm",
        rib={"plane": {"point": [0, 0, 0], "normal": [1, 0, 0]}, "distance": 0.1},
    ),
    "a rib rule that clamps the whole boundary": file_probe(
        lambda p: write_stl(p, *box_surface()), r"selects 100 % of the boundary",
        rib={"plane": RIB["plane"], "distance": 1.0},
    ),
    "a rib rule that selects nothing": file_probe(
        lambda p: write_stl(p, *box_surface()), r"no boundary facets found for the rib",
        rib={"plane": {"point": [-0.1, 0, 0], "normal": [1, 0, 0]}, "distance": 0.001},
    ),
    "a surface with a hole": file_probe(_open_surface, r"not a closed surface"),
    "two surfaces through each other": file_probe(
        _two_boxes_crossing, r"holds 2 closed bodies.*?cross each other near \(\S+, \S+, \S+\) mm"),
    "two separate closed bodies in one OBJ": file_probe(  # the rib: the far sphere's back
        lambda p: _two_spheres(p, 0.2), r"holds 2 closed bodies, not one.*?they lie apart",
        suffix=".obj", rib={"plane": {"point": [0.25, 0, 0], "normal": [1, 0, 0]},
                            "distance": 0.01}),
    "two spheres crossing along their edges": file_probe(
        lambda p: _two_spheres(p, 0.06),
        r"holds 2 closed bodies.*?cross each other near \(\S+, \S+, \S+\) mm", suffix=".obj",
        rib={"plane": {"point": [0.11, 0, 0], "normal": [1, 0, 0]}, "distance": 0.01}),
    "a chest wall anterior of the breast, no orientation": file_probe(
        lambda p: write_stl(p, *box_surface()), r"chest wall \(the rib facets\) lies [0-9.]+ mm "
        r"anterior of the breast's centroid",
        rib={"plane": {"point": [0.0, 0, 0], "normal": [-1, 0, 0]}, "distance": 0.001}),
    "a volume mesh with inverted tetrahedra": file_probe(
        _inverted_tetrahedra, r"\d+ inverted tetrahedra \(oriented opposite", suffix=".vtu"
    ),
}


# -- bad label volumes (mesh.source: image) ---------------------------------------------------


def image_probe(make: Callable[[Path], Path], text: str,
                **image: Any) -> Callable[[Path], Outcome]:
    """Mesh the label volume ``make`` writes in the folder: the job fails, its log names ``text``.

    The volume is :mod:`meshes.phantom`'s, small (160 x 165 x 150 mm in 4 mm voxels), spoiled.
    """

    def probe(workdir: Path) -> Outcome:
        path = make(workdir)
        config = config_with(
            mesh__source="image",
            mesh__size={"fold_size": None, "order": 1, "global_size": 0.03},
            mesh__image={"path": path.name, "breast_labels": [1, 2, 4], "chest_label": 3,
                         "side": "left", **image},
        )
        return mesh_job_refuses(workdir, config, "image.yaml", text)

    return probe


def _phantom(folder: Path, suffix: str = ".nii", **kwargs: Any) -> Path:
    from meshes.phantom import write_phantom

    return write_phantom(folder / f"labels{suffix}", (40, 44, 30), (4.0, 3.75, 5.0), **kwargs)


def _zero_pixdim(folder: Path) -> Path:
    """NIfTI-1's pixdim[1] (float32 at byte 80) set to 0; the sform still says 4 mm."""
    path = _phantom(folder)
    data = bytearray(path.read_bytes())
    data[80:84] = np.float32(0.0).tobytes()
    path.write_bytes(bytes(data))
    return path


def _metaimage_edit(old: str, new: str) -> Callable[[Path], Path]:
    def make(folder: Path) -> Path:
        path = _phantom(folder, ".mhd")
        path.write_text(path.read_text().replace(old, new))
        return path

    return make


def _cut_in_half(folder: Path) -> Path:
    path = _phantom(folder, ".nii.gz")
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    return path


def _two_breasts(folder: Path) -> Path:
    """The phantom twice, side by side along i: two equal breasts."""
    from tests.test_image_headers import two_breasts

    return two_breasts(folder)


def _research_phantom(folder: Path) -> Path:
    """Voxel axes really SLA (the breast along +k), written LPS with the identity direction."""
    import SimpleITK as sitk

    sla = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])  # i S, j L, k A in LPS
    image = sitk.ReadImage(str(_phantom(folder, ".nrrd", direction=sla)))
    image.SetDirection(tuple(np.eye(3).ravel()))
    sitk.WriteImage(image, str(folder / "research.nrrd"), True)
    return folder / "research.nrrd"


IMAGE_PROBES: dict[str, Callable[[Path], Outcome]] = {
    "a NIfTI whose pixdim is 0 (its sform says 4 mm)": image_probe(
        _zero_pixdim, r"pixdim\[1:4\] = \(0, 3\.75, 5\) mm is not a finite, positive voxel size"),
    "a MetaImage whose direction matrix is scaled by 2": image_probe(
        _metaimage_edit("TransformMatrix = 1 0 0 0 1 0 0 0 1",
                        "TransformMatrix = 2 0 0 0 2 0 0 0 2"),
        r"direction cosines \(TransformMatrix\) are not orthonormal"),
    "a MetaImage whose spacing is 1e-6 mm": image_probe(
        _metaimage_edit("ElementSpacing = 4 3.75 5", "ElementSpacing = 4e-06 3.75e-06 5e-06"),
        r"the image is \S+ mm across .*? probably in other units"),
    # without the tumour's label, which lies in the half that is lost
    "a .nii.gz cut to half its bytes": image_probe(
        _cut_in_half, r"labels\.nii\.gz is truncated", breast_labels=[1, 2]),
    "two equal breasts in one image": image_probe(
        _two_breasts, r"form 2 separate pieces: the largest (\S+) ml .*?the next \1 ml"),
    "a wrong header and no mesh.image.orientation": image_probe(
        _research_phantom, r"lies \S+ mm from the breast's centroid towards the patient's "
        r"inferior \(I\), 90° from posterior.*?give them as mesh\.image\.orientation"),
}
FILE_PROBES.update(IMAGE_PROBES)


# -- bad case files at aggregation ---------------------------------------------------------

# the smallest sweep whose dataset every reader takes: three cases to train, validate and
# test on (no clinical case, which the by-case split would hold out as test besides)
SWEEP = config_with(sweep={"C1_kPa": [1.0], "phi_deg": [0.0, 90.0, 180.0]}, clinical=[])
CASES = ("c1=1.00_phi=0.0_theta=0.0", "c1=1.00_phi=90.0_theta=0.0", "c1=1.00_phi=180.0_theta=0.0")


def solved_sweep(workdir: Path) -> None:
    """Solve the three-case sweep and build its dataset once; the case-file probes copy it."""
    path = workdir / "sweep.yaml"
    path.write_text(yaml.safe_dump(SWEEP))
    run = snakemake(workdir, path, "-j2", "results/dataset/dataset.h5")
    if run.returncode != 0:
        raise RuntimeError(f"the three-case sweep failed: {run.stderr[-2000:]}")


def case_probe(spoil: Callable[[Path], None], text: str) -> Callable[[Path, Path], Outcome]:
    """Spoil a copy of the solved sweep; rebuilding the dataset must fail and keep the old one.

    The aggregation log must name ``text``, and a second run must fail the same way (the kept
    dataset is out of date until the input is fixed, not "Nothing to be done").
    """

    def probe(workdir: Path, solved: Path) -> Outcome:
        shutil.copytree(solved, workdir, symlinks=True, dirs_exist_ok=True)
        dataset = workdir / "results/dataset/dataset.h5"
        before = dataset.read_bytes()
        spoil(workdir / "results" / "cases")
        time.sleep(0.01)
        for attempt in ("first", "second"):  # a refused input keeps the target failing
            run = snakemake(workdir, workdir / "sweep.yaml", "-j1", "results/dataset/dataset.h5")
            outcome = expect(run, text, workdir / "results/logs/aggregate.log")
            if outcome.passed and dataset.read_bytes() != before:
                return Outcome(False, f"the previous dataset was changed ({attempt} run)")
            if not outcome.passed:
                return Outcome(False, f"{attempt} run: {outcome.detail}")
        return outcome

    return probe


def _summary(cases: Path, case: str, **changes: Any) -> None:
    path = cases / case / "summary.json"
    summary = json.loads(path.read_text())
    path.write_text(json.dumps({**summary, **changes}))


def _huge_displacement(points: Path) -> None:
    import h5py

    with h5py.File(points, "a") as h5:
        h5["u"][3] = [1e30, 0.0, 0.0]


def _copy_case(cases: Path, source: str, target: str) -> None:
    for name in ("summary.json", "points.h5"):
        shutil.copy(cases / source / name, cases / target / name)


CASE_PROBES: dict[str, Callable[[Path, Path], Outcome]] = {
    "a summary of garbage bytes": case_probe(
        lambda c: (c / CASES[1] / "summary.json").write_bytes(b"\xff\xfe\x00\x01"),
        rf"{re.escape(CASES[1])}/summary\.json: unreadable",
    ),
    "a summary that is null": case_probe(
        lambda c: (c / CASES[1] / "summary.json").write_text("null"),
        rf"{re.escape(CASES[1])}/summary\.json: a summary is a JSON object",
    ),
    "an unknown status": case_probe(
        lambda c: _summary(c, CASES[0], status="ok"), r"unknown status 'ok'"
    ),
    "a non-numeric C1": case_probe(
        lambda c: _summary(c, CASES[0], C1="one"), r"C1 are not finite numbers"
    ),
    "a summary of another C1 than its folder": case_probe(
        lambda c: _summary(c, CASES[2], C1=2.0),
        r"not of its folder.*?snakemake \S+summary\.json --forcerun \S+summary\.json"
    ),
    "a converged displacement of 1e30 m": case_probe(
        lambda c: _huge_displacement(c / CASES[1] / "points.h5"),
        r"moves a point 1e\+30 m, farther than the body's own size"
    ),
    "another case's files in a folder": case_probe(
        lambda c: _copy_case(c, CASES[0], CASES[2]),
        rf"summary is of case '{re.escape(CASES[0])}'",
    ),
    "another case's points file in a folder": case_probe(
        lambda c: shutil.copy(c / CASES[0] / "points.h5", c / CASES[1] / "points.h5"),
        rf"points\.h5: written for case '{re.escape(CASES[0])}'",
    ),
}


# -- the commands, on the solved sweep and a model trained on it ----------------------------

MESH = "results/mesh/mesh.xdmf"
MODEL = "model"
SEPARABLE = "separable"


def train_model(solved: Path) -> None:
    """Small models of the three-case sweep (the commands' probes load them): pod, separable."""
    for folder, settings in ((MODEL, ["structure=pod", "modes=2"]),
                             (SEPARABLE, ["structure=separable", "modes=2", "width=8"])):
        run = subprocess.run(
            [sys.executable, "-m", "surrogate.cli", "train", "results/dataset/dataset.h5",
             "--config", str(REPO / "tests" / "config.yaml"),
             *(a for item in [*settings, "max_epochs=2"] for a in ("--set", item)),
             "--out", folder],
            cwd=solved, capture_output=True, text=True, timeout=300)
        if run.returncode != 0:
            raise RuntimeError(f"the probes' {folder} model did not train: {run.stderr[-2000:]}")


def command_probe(args: list[str], text: str, status: int = 2,
                  prepare: Callable[[Path], None] | None = None) -> Callable[[Path, Path], Outcome]:
    """Run ``python -m ARGS`` in a copy of the solved sweep: exit ``status``, ``text`` said.

    ``{...}`` in ``args`` is filled from the working directory's paths. Nothing may be written
    in the working directory but what ``prepare`` wrote and, for a command that answers
    (status 0), the output it was asked for.
    """

    def probe(workdir: Path, solved: Path) -> Outcome:
        shutil.copytree(solved, workdir, symlinks=True, dirs_exist_ok=True)
        if prepare is not None:
            prepare(workdir)
        before = {p: p.stat().st_mtime_ns for p in workdir.rglob("*")}
        run = subprocess.run([sys.executable, "-m", *args], cwd=workdir, capture_output=True,
                             text=True, timeout=300)
        said = run.stdout + run.stderr
        if run.returncode != status:
            tail = " ".join(said.split())[-400:]
            return Outcome(False, f"exit status {run.returncode}, not {status}: ...{tail}")
        if not re.search(text, said, re.S):
            return Outcome(False, f"{text!r} not in the output: ...{' '.join(said.split())[-400:]}")
        if status != 0:
            written = sorted(str(p.relative_to(workdir)) for p in workdir.rglob("*")
                             if before.get(p) != p.stat().st_mtime_ns)
            if written:
                return Outcome(False, f"written although refused: {written[:5]}")
        return Outcome(True, " ".join(re.search(text, said, re.S)[0].split())[:120])

    return probe


def _spoil_params(workdir: Path) -> None:
    params = workdir / MODEL / "params.npz"
    params.write_bytes(params.read_bytes()[:5000])


def _spoil_card(workdir: Path, **normalisation: Any) -> None:
    card = json.loads((workdir / MODEL / "model.json").read_text())
    card["normalisation"].update(normalisation)
    if "format_version" in normalisation:
        card["format_version"] = card["normalisation"].pop("format_version")
    (workdir / MODEL / "model.json").write_text(json.dumps(card))


def _spoil_range(workdir: Path, C1_kPa: Any = None, whole: Any = None) -> None:
    """The model card's training range replaced (``whole``) or its C1 range changed."""
    card = json.loads((workdir / MODEL / "model.json").read_text())
    if whole is not None:
        card["training_range"] = whole
    else:
        card["training_range"]["C1_kPa"] = C1_kPa
    (workdir / MODEL / "model.json").write_text(json.dumps(card))


def _nan_node(workdir: Path) -> None:
    import h5py

    with h5py.File(workdir / "results/mesh/mesh.h5", "a") as h5:
        h5["Mesh/mesh/geometry"][7, 0] = np.nan


def _corner_points(workdir: Path, bom: bool = False) -> None:
    """Points near the corners of the mesh's largest cell: inside it, far from its centroid."""
    import h5py

    with h5py.File(workdir / "results/mesh/mesh.h5") as h5:
        x = h5["Mesh/mesh/geometry"][...]
        cells = h5["Mesh/mesh/topology"][...][:, :4]
    corners = x[cells]
    volume = np.abs(np.linalg.det(corners[:, 1:] - corners[:, :1]))
    big = corners[np.argmax(volume)]
    weights = np.full((4, 4), 0.01) + 0.96 * np.eye(4)
    rows = "".join(f"c{i},{a!r},{b!r},{c!r}\n" for i, (a, b, c) in enumerate(weights @ big))
    text = "name,x,y,z\n" + rows
    (workdir / "points.csv").write_bytes(("\ufeff" if bom else "").encode() + text.encode())


def _rib_point(workdir: Path) -> None:
    """A node of the clamped chest wall (the rib facets, tag 1), as a named point."""
    import h5py

    with h5py.File(workdir / "results/mesh/mesh.h5") as h5:
        x = h5["Mesh/mesh/geometry"][...]
        facets = h5["MeshTags/facet_tags/topology"][...]
        tags = h5["MeshTags/facet_tags/Values"][...].ravel()
    node = x[facets[tags == 1][0, 0]]
    (workdir / "rib.csv").write_text("name,x,y,z\n" + "rib0," + ",".join(map(repr, node)) + "\n")


def _import_config(workdir: Path, orientation: dict, rib: dict | None = None) -> None:
    """A config importing a box written in LPS mm of a left breast, with these rules."""
    x, tris = box_surface()
    # a left breast: L (lateral) = +y of the project, P = +x, S = +z; a mirror image, so the
    # triangles turn to keep facing outwards
    lps = 1000 * x[:, [1, 0, 2]]
    write_stl(workdir / "box_lps.stl", lps, tris[:, [0, 2, 1]])
    rib = rib or {"plane": {"point": [0.0, 50.0, 0.0], "normal": [0.0, 1.0, 0.0]},
                  "distance": 1.0}
    mesh = {"source": "file", "size": {"fold_size": None, "order": 1, "global_size": 0.03},
            "file": {"path": "box_lps.stl", "units": "mm", "orientation": orientation,
                     "surfaces": {"rib": rib}}}
    (workdir / "import.yaml").write_text(yaml.safe_dump({"mesh": mesh}))


def truncated_arrays_rerun_probe(workdir: Path, solved: Path) -> Outcome:
    """The workflow's 3D view of a model whose ``params.npz`` is then cut short.

    The view is built (the workflow's ``viewer`` rule alone, on the probes' model as the
    selected one); the arrays are then truncated: the next run must make the view again and
    fail naming them in its log, twice (not "Nothing to be done", the rule reading only the card).
    """
    shutil.copytree(solved, workdir, symlinks=True, dirs_exist_ok=True)
    shutil.copytree(workdir / MODEL, workdir / "results/surrogate/model")
    view = ("--allowed-rules", "viewer", "--", "results/viewer/index.html")
    built = snakemake(workdir, workdir / "sweep.yaml", "-j1", *view)
    if built.returncode != 0:
        return Outcome(False, f"the view of the whole model failed: {built.stderr[-400:]}")
    _spoil_params(workdir / "results/surrogate")
    for attempt in ("first", "second"):
        run = snakemake(workdir, workdir / "sweep.yaml", "-j1", *view)
        outcome = expect(run, r"params\.npz is not a whole NumPy archive",
                         workdir / "results/logs/viewer.log")
        if not outcome.passed:
            return Outcome(False, f"{attempt} run: {outcome.detail}")
    return outcome


MODEL_QUERY = ["surrogate.cli", "predict", MODEL, "--c1", "2", "--phi", "90"]

COMMAND_PROBES: dict[str, Callable[[Path, Path], Outcome]] = {
    "fem.cli at an angle of 1e300 degrees": command_probe(
        ["fem.cli", MESH, "--c1", "1", "--phi", "1e300", "--out", "case"],
        r"argument --phi: 1e300 is not an angle from -180 to 360 degrees"),
    "fem.cli writing into a file": command_probe(
        ["fem.cli", MESH, "--c1", "1", "--phi", "0", "--out", "sweep.yaml"],
        r"argument --out: sweep\.yaml is a file, not a folder to write into"),
    "fem.cli on a mesh with a NaN node": command_probe(
        ["fem.cli", MESH, "--c1", "1", "--phi", "0", "--out", "case"],
        r"mesh\.xdmf: node \d+ .*? not finite numbers", prepare=_nan_node),
    "fem.reference with a tolerance of zero": command_probe(
        ["fem.reference", MESH, "--c1", "1", "--phi", "180", "--out", "ref",
         "--tolerance-mm", "0"], r"argument --tolerance-mm: 0 is not above zero"),
    "fem.reference given a case's fields": command_probe(
        ["fem.reference", f"results/cases/{CASES[0]}/fields.xdmf", "--c1", "1", "--phi", "180",
         "--out", "ref"], r"is not a mesh|holds no mesh named 'mesh'"),
    "fem.reference given an STL": command_probe(
        ["fem.reference", "breast.stl", "--c1", "1", "--phi", "180", "--out", "ref"],
        r"breast\.stl is not a mesh of this project",
        prepare=lambda w: write_stl(w / "breast.stl", *box_surface())),
    "predict at an angle of 1e300 degrees": command_probe(
        ["surrogate.cli", "predict", MODEL, "--c1", "2", "--phi", "1e300"],
        r"argument --phi: 1e300 is not an angle"),
    "studies.reference_state.stiffness at Φ = 1000 degrees": command_probe(
        ["studies.reference_state.stiffness", MESH, "--model", MODEL, "--phi", "1000"],
        r"argument --phi: 1000 is not an angle"),
    "predict with a truncated params.npz": command_probe(
        MODEL_QUERY, r"params\.npz is not a whole NumPy archive", prepare=_spoil_params),
    "predict with a NaN scale in model.json": command_probe(
        MODEL_QUERY, r"normalisation\.x_std is nan, not a finite number",
        prepare=lambda w: _spoil_card(w, x_std=float("nan"))),
    "predict with a model of format 999": command_probe(
        MODEL_QUERY, r"format_version 999 is not one this code reads",
        prepare=lambda w: _spoil_card(w, format_version=999)),
    "predict with a training range of NaN": command_probe(
        MODEL_QUERY, r"training_range is nan, not a mapping",
        prepare=lambda w: _spoil_range(w, whole=float("nan"))),
    "predict with a C1 training range of [NaN, NaN]": command_probe(
        MODEL_QUERY, r"training_range\.C1_kPa is \[nan, nan\], not \[low, high\]",
        prepare=lambda w: _spoil_range(w, [float("nan")] * 2)),
    "the viewer of a model with its C1 training range reversed": command_probe(
        ["report.viewer", MODEL, "-o", "page.html", "--mesh", MESH],
        r"training_range\.C1_kPa is \[5\.0, 1\.0\], not \[low, high\]",
        prepare=lambda w: _spoil_range(w, [5.0, 1.0])),
    "the viewer written over a folder": command_probe(
        ["report.viewer", MODEL, "-o", "page.html", "--mesh", MESH],
        r"page\.html is a folder, not a file to write",
        prepare=lambda w: (w / "page.html").mkdir()),
    "points inside a cell far from its centroid": command_probe(
        [*MODEL_QUERY, "--points", "points.csv"], r"c3 +\d", status=0,
        prepare=_corner_points),
    "points saved as 'CSV UTF-8' (a byte-order mark)": command_probe(
        [*MODEL_QUERY, "--points", "points.csv"], r"c0 +\d", status=0,
        prepare=lambda w: _corner_points(w, bom=True)),
    "fem.reference writing into a file": command_probe(
        ["fem.reference", MESH, "--c1", "1", "--phi", "180", "--out", "sweep.yaml"],
        r"argument --out: sweep\.yaml is a file, not a folder to write into"),
    "studies.reference_state.tracking on a mesh with a NaN node": command_probe(
        ["studies.reference_state.tracking", "points.csv", "--imaged", MESH, "--reference", MESH,
            "--model",
         MODEL, "--c1", "1", "--phi", "0", "--out", "tracked.csv"],
        r"mesh\.xdmf: node \d+ .*? not finite numbers",
        prepare=lambda w: (_corner_points(w), _nan_node(w))),
    "the viewer of a truncated model": command_probe(
        ["report.viewer", MODEL, "-o", "page.html", "--mesh", MESH],
        r"params\.npz is not a whole NumPy archive", prepare=_spoil_params),
    "the workflow's view of a model whose params.npz is then truncated":
        truncated_arrays_rerun_probe,
    "the viewer of a model with a NaN scale": command_probe(
        ["report.viewer", MODEL, "-o", "page.html", "--mesh", MESH],
        r"normalisation\.x_std is nan", prepare=lambda w: _spoil_card(w, x_std=float("nan"))),
    "a separable model asked at a clamped node": command_probe(
        ["surrogate.cli", "predict", SEPARABLE, "--c1", "1", "--phi", "90", "--points",
         "rib.csv"], r"rib0 +0\.000 +0\.000 +0\.000 +0\.000", status=0,
        prepare=_rib_point),
    "the preview of an LPS file declared RAS": command_probe(
        ["meshes.preview", "import.yaml"], r"the import would stop: .*? anterior of the breast",
        status=1, prepare=lambda w: _import_config(w, {"axes": "RAS", "side": "left"})),
    "the preview of the code LAS": command_probe(
        ["meshes.preview", "import.yaml"], r"the import would stop: .*? anterior of the breast",
        status=1, prepare=lambda w: _import_config(w, {"axes": "LAS", "side": "left"})),
    "the preview of orientation {}": command_probe(
        ["meshes.preview", "import.yaml"], r"invalid mesh section: mesh\.file\.orientation",
        prepare=lambda w: _import_config(w, {})),
    "the preview of an alias bomb": command_probe(
        ["meshes.preview", "bomb.yaml"], r"bomb\.yaml: sweep\.a4 expands to more than 100000",
        prepare=lambda w: (w / "bomb.yaml").write_text(alias_bomb(mapping=True))),
    "the preview of a distance beside a posterior rule": command_probe(
        ["meshes.preview", "import.yaml"], r"invalid mesh section: mesh\.file\.surfaces\.rib",
        prepare=lambda w: _import_config(w, {"axes": "LPS", "side": "left"}, {
            "posterior": {"angle": 30, "band": 10}, "distance": 1})),
    "the preview says a posterior rule's band in mm": command_probe(
        ["meshes.preview", "import.yaml"], r"rib .*? facing posterior within 30° and within "
        r"10 mm of the most posterior point.*?the rules would do", status=0,
        prepare=lambda w: _import_config(w, {"axes": "LPS", "side": "left"}, {
            "posterior": {"angle": 30, "band": 10}})),
    "the preview of an angle given as text": command_probe(
        ["meshes.preview", "import.yaml"], r"invalid mesh section: mesh\.file\.surfaces\.rib",
        prepare=lambda w: _import_config(w, {"axes": "LPS", "side": "left"}, {
            "posterior": {"angle": "30", "band": 10}})),
    "points from a binary file": command_probe(
        [*MODEL_QUERY, "--points", "points.csv"], r"points\.csv: not a text CSV",
        prepare=lambda w: (w / "points.csv").write_bytes(bytes(range(256)))),
    "the viewer written over the model's model.json": command_probe(
        ["report.viewer", MODEL, "-o", f"{MODEL}/model.json", "--mesh", MESH],
        r"argument -o/--output: model/model\.json lies in an input folder \(MODEL: model\)"),
    "the viewer written over the mesh's HDF5 data": command_probe(
        ["report.viewer", MODEL, "-o", "results/mesh/mesh.h5", "--mesh", MESH],
        r"mesh\.h5 is the HDF5 data of an input \(--mesh"),
    "predicted positions written over the points": command_probe(
        [*MODEL_QUERY, "--points", "points.csv", "-o", "points.csv"],
        r"--output points\.csv is an input \(--points: points\.csv\)", prepare=_corner_points),
    "meshes.frame written over its picks": command_probe(
        ["meshes.frame", "import.yaml", "picks.csv", "picks.csv", "--to", "project"],
        r"argument out: picks\.csv is an input \(points: picks\.csv\)",
        prepare=lambda w: (_import_config(w, {"axes": "LPS", "side": "left"}),
                           (w / "picks.csv").write_text("name,x,y,z\ntumour,30,-40,10\n"))),
}


def workdir_probe(workdir: Path) -> Outcome:
    """``make reproduce WORKDIR=<a file>``: one line, nothing run."""
    target = workdir / "a_file"
    target.write_text("")
    run = subprocess.run(["make", "-s", "-C", str(REPO), "reproduce", f"WORKDIR={target}"],
                         capture_output=True, text=True, timeout=300)
    return expect(run, r"WORKDIR=\S+ is a file, not a folder to work in")


def alias_bomb_make_probe(workdir: Path) -> Outcome:
    """``make reproduce CONFIG=<a bomb of mappings>``: refused by the config check it runs first.

    Snakemake merges the mappings of a ``--configfile`` itself, every copy, before the Snakefile
    is read: only the check before it can stop such a file.
    """
    bomb = workdir / "bomb.yaml"
    bomb.write_text(alias_bomb(mapping=True))
    run = subprocess.run(["make", "-s", "-C", str(REPO), "reproduce", f"CONFIG={bomb}",
                          f"WORKDIR={workdir / 'run'}"], capture_output=True, text=True,
                         timeout=120)
    outcome = expect(run, r"bomb\.yaml: sweep\.a4 expands to more than 100000")
    if outcome.passed and (workdir / "run").exists():
        return Outcome(False, "the run's working directory was made")
    return outcome


# -- running -------------------------------------------------------------------------------


def main(argv: list[str] | None = None) -> int:
    """Run the probes, print a line each and the count; 1 if any failed."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("-j", "--jobs", type=int, default=3, help="probes run at once")
    parser.add_argument("-k", default="", help="run only probes whose name contains this")
    parser.add_argument("--keep", type=Path, help="keep the working directories here")
    args = parser.parse_args(argv)
    start = time.perf_counter()
    root = Path(tempfile.mkdtemp(prefix="probe-")) if args.keep is None else args.keep
    root.mkdir(parents=True, exist_ok=True)

    def run(kind: str, name: str, probe: Callable[..., Outcome], *extra: Path) -> tuple:
        workdir = root / re.sub(r"\W+", "-", f"{kind}-{name}").strip("-")
        workdir.mkdir()
        began = time.perf_counter()
        try:
            outcome = probe(workdir, *extra)
        except Exception as err:  # a probe that crashes has failed, with its error
            outcome = Outcome(False, f"{type(err).__name__}: {err}")
        return kind, name, outcome, time.perf_counter() - began

    selected = [
        (kind, name, probe)
        for kind, probes in (("config", CONFIG_PROBES), ("file", FILE_PROBES),
                             ("make", {"WORKDIR naming a file": workdir_probe,
                                       "an alias bomb as CONFIG": alias_bomb_make_probe}))
        for name, probe in probes.items()
        if args.k in name
    ]
    cases = [(n, p) for n, p in CASE_PROBES.items() if args.k in n]
    commands = [(n, p) for n, p in COMMAND_PROBES.items() if args.k in n]
    results = []
    with ThreadPoolExecutor(max_workers=max(args.jobs, 1)) as pool:
        solved = root / "solved"
        pending = [pool.submit(run, *item) for item in selected]
        if cases or commands:
            solved.mkdir()
            began = time.perf_counter()
            solved_sweep(solved)
            print(f"the three-case sweep solved in {time.perf_counter() - began:.1f} s", flush=True)
            pending += [pool.submit(run, "case", name, probe, solved) for name, probe in cases]
        if commands:
            began = time.perf_counter()
            train_model(solved)
            print(f"its models trained in {time.perf_counter() - began:.1f} s", flush=True)
            pending += [pool.submit(run, "command", name, probe, solved)
                        for name, probe in commands]
        for future in pending:
            kind, name, outcome, seconds = future.result()
            results.append(outcome.passed)
            print(f"{'PASS' if outcome.passed else 'FAIL'} {kind}: {name} ({seconds:.1f} s): "
                  f"{outcome.detail}", flush=True)
    leaked = list(root.rglob(f"{SENTINEL}*"))  # where the viewer options pointed PETSc
    if leaked:
        print(f"FAIL a file was written outside a working directory: {leaked}")
        results.append(False)
    if args.keep is None:
        shutil.rmtree(root, ignore_errors=True)
    passed = sum(results)
    print(f"probes took {time.perf_counter() - start:.0f} s")
    print(f"{passed} passed, {len(results) - passed} failed")
    return 0 if passed == len(results) else 1


if __name__ == "__main__":
    sys.exit(main())
