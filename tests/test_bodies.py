"""A file of more than one body is refused by the import, naming them and where they cross.

Issue 70: two closed bodies in one OBJ were meshed as one two-body mesh (899 ml), and two
closed spheres that cross (mirror images, their triangles meeting along edges) as their union.
Valid inputs (one closed body, the corpus's anatomies) still pass.
"""

from __future__ import annotations

import re
from pathlib import Path

import meshio
import numpy as np
import pytest
import trimesh

from meshes.bodies import check_one_body, winding_numbers
from meshes.exceptions import MeshInputError
from meshes.importing import ImportSpec, read_volume
from meshes.sizing import MeshSize

pytestmark = pytest.mark.unit

SIZE = MeshSize(global_size=0.03, mound_size=0.02)
RIB = {"plane": {"point": [0.0, 0.0, 0.0], "normal": [1.0, 0.0, 0.0]}, "distance": 0.001}
RADIUS = 0.05


def spheres(*centres: tuple[float, float, float], radius: float = RADIUS,
            subdivisions: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """Closed icospheres about ``centres`` in one surface (points, m; triangles)."""
    x, tris = [], []
    for centre in centres:
        sphere = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
        tris.append(np.asarray(sphere.faces) + sum(len(p) for p in x))
        x.append(np.asarray(sphere.vertices) + centre)
    return np.vstack(x), np.vstack(tris)


def imported(tmp_path: Path, x: np.ndarray, tris: np.ndarray, remesh: bool = False) -> None:
    """Read ``x, tris`` written as an OBJ (mm) through the import's own path."""
    path = tmp_path / "breast.obj"
    trimesh.Trimesh(1000 * x, tris, process=False).export(str(path))
    spec = ImportSpec.from_mapping({"path": str(path), "units": "mm", "remesh": remesh,
                                    "surfaces": {"rib": RIB}})
    read_volume(spec, SIZE)


def test_two_separate_spheres_in_one_obj_are_refused_naming_two_bodies(tmp_path: Path) -> None:
    x, tris = spheres((0.0, 0.0, 0.0), (0.2, 0.0, 0.0))
    with pytest.raises(MeshInputError, match=r"holds 2 closed bodies, not one: .*? they lie apart"):
        imported(tmp_path, x, tris)


@pytest.mark.parametrize("remesh", [False, True])
def test_two_mirror_spheres_that_cross_are_refused_naming_where(tmp_path: Path,
                                                                 remesh: bool) -> None:
    """Mirror images about x = 30 mm: their triangles meet along edges, no edge pierces a face.

    Before: kept triangles stopped in gmsh ("PLC Error"), remeshed they became their union.
    """
    x, tris = spheres((0.0, 0.0, 0.0), (0.06, 0.0, 0.0))
    with pytest.raises(MeshInputError, match=r"2 closed bodies") as raised:
        imported(tmp_path, x, tris, remesh)
    where = re.search(r"cross each other near \((\S+), (\S+), (\S+)\) mm", str(raised.value))
    assert where, str(raised.value)
    point = np.array([float(v) for v in where.groups()])
    # the spheres cross on the circle x = 30 mm, radius 40 mm about the x axis; the point is
    # a vertex (the icospheres' edges are about 15 mm long) by it
    off = np.hypot(point[0] - 30.0, np.hypot(point[1], point[2]) - 40.0)
    assert off < 15.0, (point, off)


def test_spheres_whose_edges_pierce_each_other_are_refused_naming_where(tmp_path: Path) -> None:
    x, tris = spheres((0.0, 0.0, 0.0), (0.061, 0.013, 0.007))
    with pytest.raises(MeshInputError, match=r"2 closed bodies.*?cross each other near"):
        imported(tmp_path, x, tris)


def test_a_sphere_inside_another_is_refused() -> None:
    x, tris = spheres((0.0, 0.0, 0.0))
    inner, inner_tris = spheres((0.01, 0.0, 0.0), radius=0.02)
    x, tris = np.vstack([x, inner]), np.vstack([tris, inner_tris + len(x)])
    with pytest.raises(MeshInputError, match=r"2 closed bodies.*?body 2 lies inside body 1"):
        check_one_body(x, tris, "the input")


def test_a_volume_mesh_of_two_bodies_is_refused(tmp_path: Path) -> None:
    from scipy.spatial import Delaunay

    from meshes.quality import tet_volumes

    cube = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], float) * 0.06
    cells = Delaunay(cube).simplices
    cells = np.where((tet_volumes(cube, cells) < 0)[:, None], cells[:, [1, 0, 2, 3]], cells)
    x = np.vstack([cube, cube + [0.1, 0.0, 0.0]])
    tets = np.vstack([cells, cells + 8])
    path = tmp_path / "breast.vtu"
    meshio.write(str(path), meshio.Mesh(x, [("tetra", tets)]))
    spec = ImportSpec.from_mapping({"path": str(path), "surfaces": {"rib": RIB}})
    with pytest.raises(MeshInputError, match=r"holds 2 closed bodies.*?they lie apart"):
        read_volume(spec, SIZE)


def test_one_sphere_is_one_body_and_its_winding_number_is_one_inside() -> None:
    x, tris = spheres((0.0, 0.0, 0.0), subdivisions=3)
    check_one_body(x, tris, "the input")
    w = winding_numbers(np.array([[0.0, 0.0, 0.0], [0.01, -0.02, 0.03], [0.2, 0.0, 0.0]]),
                        x, tris)
    np.testing.assert_allclose(w, [1.0, 1.0, 0.0], atol=1e-9)


def test_the_corpus_anatomies_are_one_body_each() -> None:
    from meshes.corpus import dome_volume_mesh, hemisphere_surface, rim_surface, scan_surface
    from meshes.quality import exterior_faces

    for name, (x, tris) in {"hemisphere": hemisphere_surface(),
                            "scan": scan_surface(), "rim": rim_surface()}.items():
        check_one_body(x, tris, name)
    x, tets, *_ = dome_volume_mesh()
    check_one_body(x, exterior_faces(tets), "volume", cells=tets)


def test_a_single_closed_surface_still_imports(tmp_path: Path) -> None:
    x, tris = spheres((0.0, 0.0, 0.0))
    imported(tmp_path, x, tris)
