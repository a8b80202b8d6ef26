"""The reference state takes the forward problem's material: the skin membrane and the tissues.

An imaged shape hangs under the whole model (issue 69): the solid's law with each cell's C1
and, with ``material.skin``, the skin as a membrane on its boundary. The reference found by
the inverse-motion solve (:mod:`fem.inverse_motion`) is that model's only where the inverse
problem carries both: on the curved coarse breast, where the inverse and forward discrete
problems are one, its reference then reproduces the loaded shape under a forward solve at
once, and without either it does not.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fem.case import CaseRunner
from fem.io import node_displacement
from fem.parameters import SolverSettings
from fem.reference import estimate_reference, write_reference_mesh
from fem.sweep import Case
from meshes.io import read_mesh
from tests.test_reference import _deformed

pytestmark = pytest.mark.solve


#: The model of the skin and tissues test: the skin as a wrinkling membrane, the gland twice
#: as stiff as the fat (the config's sections, as every entry point reads them).
SKIN_AND_TISSUES = {"material": {"skin": {"thickness": 0.0015, "wrinkles": True},
                                 "tissues": {"gland": 2.0}}}


def test_the_reference_takes_the_skin_membrane_and_the_tissues_of_the_forward_model(
    curved_coarse_mesh: Path, tmp_path: Path
) -> None:
    """With the skin membrane and a gland, the inverse solve's reference is the forward model's.

    On the curved breast with its inner half of cells gland, the reference found (by
    :func:`estimate_reference`, and by the command line from a config with the same sections)
    reproduces the loaded shape under a forward solve of the same model within the tolerance,
    at once. The reference the inverse-motion solve finds without the membrane, or with the gland
    as soft as the fat, misses the loaded shape by far more than the tolerance under that
    forward model: each of the two is what makes the first one reproduce it.
    """
    import json
    from dataclasses import replace

    import yaml
    from dolfinx.mesh import meshtags

    from fem.inverse_motion import solve_inverse_motion
    from fem.materials import Tissues
    from fem.reference import main
    from meshes.io import geometry_nodes, write_tagged_mesh
    from meshes.tags import Tissue

    mesh, _, facet_tags = read_mesh(curved_coarse_mesh)
    centroids = mesh.geometry.x[geometry_nodes(mesh)[:, :4]].mean(axis=1)
    depth = np.linalg.norm(centroids - centroids.mean(axis=0), axis=1)
    tissue = np.where(depth < np.median(depth), int(Tissue.GLAND), int(Tissue.FAT))
    glandular = tmp_path / "glandular.xdmf"
    write_tagged_mesh(mesh, meshtags(mesh, 3, np.arange(tissue.size, dtype=np.int32),
                                     tissue.astype(np.int32)), facet_tags, glandular)
    settings = SolverSettings.from_config(SKIN_AND_TISSUES)
    prone, tolerance = Case(2.0, 180.0), 1e-6
    with CaseRunner(glandular, settings) as runner:
        assert runner.problem.material.skin is not None
        assert runner.problem.material.stiffness_ratio is not None
        X_true = runner.mesh.geometry.x.copy()
        x_observed = _deformed(runner, prone, X_true)
        runner.problem.set_geometry(x_observed)
        estimate = estimate_reference(runner, prone.material(), prone.gravity(), tolerance)
        assert estimate.converged and estimate.inverse is not None
        assert estimate.inverse.converged, estimate.inverse.loading.reason
        # the forward check, with the same model, starts at the loaded shape
        assert estimate.forward_solves == 1 and estimate.newton_iterations[0] <= 1
        assert estimate.misfit_m[0] <= tolerance
        sag = np.linalg.norm(x_observed - X_true, axis=1).max()
        assert np.linalg.norm(estimate.X - X_true, axis=1).max() <= 1e-6 * sag

        for name, reduced in (("no membrane", replace(settings, skin=None)),
                              ("one tissue", replace(settings, tissues=Tissues(
                                  {Tissue.GLAND: 1.0})))):
            inverse = solve_inverse_motion(runner.mesh, runner.facet_tags, reduced,
                                           prone.material(), prone.gravity(), runner.cell_tags)
            assert inverse.converged, (name, inverse.loading.reason)
            try:
                runner.problem.set_geometry(inverse.X)  # loaded by the whole model
                ok, _, _ = runner.solve_from(prone.material(), prone.gravity(), inverse.state)
                assert ok, name
                miss = np.linalg.norm(inverse.X + node_displacement(runner.problem)
                                      - x_observed, axis=1).max()
            finally:
                runner.problem.set_geometry(x_observed)
            assert miss > 1e3 * tolerance, (name, miss)
        observed = write_reference_mesh(runner, x_observed, tmp_path / "prone.xdmf")

    # the command line takes the skin and the tissues from the config, as a forward solve does
    config = tmp_path / "config.yaml"
    config.write_text(yaml.safe_dump(SKIN_AND_TISSUES))
    assert main([str(observed), "--c1", "2", "--phi", "180", "--config", str(config),
                 "--tolerance-mm", str(1e3 * tolerance), "--out", str(tmp_path / "ref")]) == 0
    record = json.loads((tmp_path / "ref" / "reference.json").read_text())
    assert record["forward_solves"] == 1 and record["newton_iterations"][0] <= 1
    assert record["misfit_mm"][0] <= 1e3 * tolerance
