"""docs/patient.md run as its reader would: a label volume with a wrong header to a tumour supine.

The page's commands (its ``bash`` blocks) run in order in a folder of the test's own, as the page
asks of a user, with ``PROJECT`` set to the checkout. The folder holds what the page names: the
label volume ``labels.nrrd`` (a research phantom's, written LPS with an identity direction
whose voxel axes really point SLA, :func:`tests.test_image_headers.research_phantom`), the
tumour's voxels of the page's ``csv`` block, and ``patient.yaml``: ``tests/config.yaml`` (the
page's quick run) with the page's ``mesh`` section and its ``reference_state`` keys put in.
Nothing of the page is substituted.

Before the commands, the page's refusal: without ``mesh.image.orientation`` the preview stops
with exit status 2 and the very line the page shows. After them, the outputs the page tells the
reader to look at hold what it says: the axes taken from ``mesh.image.orientation``, the
tumour picked at the phantom's tumour and carried by both paths from prone to supine, back
towards the chest, and a point outside the breast refused by the tracking job by name.
"""

from __future__ import annotations

import csv
import json
import os
import re
import subprocess
from pathlib import Path

import numpy as np
import pytest
import yaml

from tests.conftest import REPO

pytestmark = pytest.mark.workflow

PAGE = REPO / "docs" / "patient.md"


def blocks(kind: str) -> list[str]:
    """The page's fenced code blocks of one kind (``bash``, ``yaml``, ``text``, ``csv``)."""
    return [body for tag, body in re.findall(r"^```(\w*)\n(.*?)^```", PAGE.read_text(),
                                             re.S | re.M) if tag == kind]


def run_block(block: str, folder: Path) -> subprocess.CompletedProcess:
    """One ``bash`` block, as a reader runs it: in their folder, with PROJECT set."""
    return subprocess.run(["bash", "-euo", "pipefail", "-c", block], cwd=folder,
                          env={**os.environ, "PROJECT": str(REPO)}, capture_output=True,
                          text=True, timeout=1800)


def write_config(folder: Path, sections: dict, orientation: bool = True) -> None:
    """``patient.yaml``: the quick run's config with the page's sections put in."""
    config = yaml.safe_load((REPO / "tests" / "config.yaml").read_text())
    config["mesh"] = json.loads(json.dumps(sections["mesh"]))
    if not orientation:
        del config["mesh"]["image"]["orientation"]
    config.setdefault("reference_state", {}).update(sections["reference_state"])
    (folder / "patient.yaml").write_text(yaml.safe_dump(config, sort_keys=False))


def read_rows(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as f:
        return list(csv.DictReader(f))


def test_the_patient_page_runs_from_a_wrong_header_to_the_tumour_supine(tmp_path: Path) -> None:
    import SimpleITK as sitk

    from meshes.phantom import TUMOUR, TUMOUR_CENTRE_M
    from meshes.points import read_points
    from studies.reference_state.tracking import TrackingResult
    from surrogate.predict import Surrogate
    from tests.test_image_headers import research_phantom

    sections: dict = {}
    for block in blocks("yaml"):
        sections.update(yaml.safe_load(block))
    assert set(sections) == {"mesh", "reference_state"}
    image = sections["mesh"]["image"]
    assert image["orientation"] == "SLA"
    research_phantom(tmp_path).rename(tmp_path / image["path"])
    points_file = sections["reference_state"]["points"]["tumour"]["file"]

    # the tumour as the page picks it: voxel indices, each inside the phantom's tumour label
    (picks,) = blocks("csv")
    (tmp_path / "tumour_voxels.csv").write_text(picks)
    labels = sitk.GetArrayFromImage(sitk.ReadImage(str(tmp_path / image["path"])))  # [k, j, i]
    names, voxels = read_points(tmp_path / "tumour_voxels.csv")
    assert [labels[k, j, i] for i, j, k in voxels.astype(int)] == [TUMOUR] * len(names)

    commands = blocks("bash")
    (preview,) = [c for c in commands if "meshes.preview" in c]
    (refusal,) = [t for t in blocks("text") if t.startswith("error:")]
    (printed,) = [t for t in blocks("text") if t.startswith("label volume")]

    # the header's axes are wrong: the preview stops before meshing, as the page shows
    write_config(tmp_path, sections, orientation=False)
    done = run_block(preview, tmp_path)
    assert done.returncode == 2, done.stdout + done.stderr
    assert done.stderr.strip() == refusal.strip()
    assert not (tmp_path / "preview.png").exists()

    write_config(tmp_path, sections)
    outputs = []
    for command in commands:
        done = run_block(command, tmp_path)
        assert done.returncode == 0, command + done.stdout[-3000:] + done.stderr[-3000:]
        outputs.append(done.stdout)

    # the preview prints what the page shows, line for line (CGAL's mesh is the same every run)
    said = outputs[commands.index(preview)].splitlines()
    for line in printed.strip().splitlines():
        assert line in said, line
    assert (tmp_path / "preview.png").stat().st_size > 0

    # the picks land on the phantom's tumour, by the corrected axes (1.4 mm: a voxel's corner)
    names_project, project = read_points(tmp_path / "tumour_project.csv")
    assert names_project == names
    assert np.linalg.norm(project[0] - TUMOUR_CENTRE_M) < 2e-3

    quality = json.loads((tmp_path / "results/mesh/quality.json").read_text())
    assert quality["input"]["axes"]["code"] == "SLA"
    assert quality["input"]["axes"]["from"] == "mesh.image.orientation"
    assert (tmp_path / "results/mesh/mesh.png").stat().st_size > 0
    assert json.loads((tmp_path / "results/mesh/reference.json").read_text())["converged"]

    # the answer: observed is the page's tumour.csv; prone -> unloaded -> supine, each step back
    # towards the chest (LPS +y is posterior), by a millimetre or so in this small, stiff phantom
    rows = read_rows(tmp_path / "results/tracking/tumour.csv")
    assert [r["name"] for r in rows] == names
    _, given = read_points(tmp_path / points_file)
    for row, point in zip(rows, given, strict=True):
        at = {c: np.array([float(row[f"{c}_{a}_mm"]) for a in "xyz"])
              for c in ("observed", "reference", "fe", "surrogate")}
        np.testing.assert_allclose(at["observed"], point, atol=1e-3)
        assert at["observed"][1] < at["reference"][1] < at["fe"][1], row
        assert 0.5 < np.linalg.norm(at["fe"] - at["observed"]) < 100.0, row
    tracked = TrackingResult.read(tmp_path / "results/tracking/tumour.json")
    np.testing.assert_allclose(tracked.observed, project, atol=1e-9)
    assert tracked.fe_converged and (tracked.target_phi, tracked.C1_kPa) == (0.0, 1.0)
    # the surrogate's answer is the same point's: a frame or unit slip is tens of millimetres
    model = Surrogate.load(tmp_path / "results/surrogate/model")
    assert tracked.max_difference_mm <= 5 * model.metrics["validation_error_domain_mm"]

    page = (tmp_path / "results/viewer/index.html").read_text()
    data = json.loads(re.search(r'id="viewer-data"[^>]*>(.*?)</script>', page, re.S).group(1))
    assert data["inner"]["names"] == [f"tumour: {n}" for n in names]

    # a refusal in the run: a point outside the breast stops the tracking job by name, and what
    # was computed before it is kept
    (run,) = [c for c in commands if "reproduce" in c]
    kept = (tmp_path / "results/surrogate/model/params.npz").stat().st_mtime_ns
    centre = ",".join(f"{v!r}" for v in given[0])
    (tmp_path / points_file).write_text(f"name,x,y,z\ncentre,{centre}\nstray,"
                                        f"{given[0][0]!r},{given[0][1] - 60.0!r},"
                                        f"{given[0][2]!r}\n")
    done = run_block(run, tmp_path)
    assert done.returncode != 0
    assert "Error in rule tracking" in done.stdout + done.stderr
    log = (tmp_path / "results/logs/reference/tracking_tumour.log").read_text()
    assert re.search(r"1 point\(s\) lie outside the imaged body: stray \([\d.]+ mm outside\); "
                     r"check their units and axes", log), log[-2000:]
    assert (tmp_path / "results/surrogate/model/params.npz").stat().st_mtime_ns == kept
