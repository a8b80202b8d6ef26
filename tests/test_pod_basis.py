"""The POD-basis benchmark's model: a basis of the training fields and a branch weighing it."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.pod_basis import fit
from fem.dataset import Dataset
from fem.directions import gravity_direction
from surrogate.config import SurrogateConfig


def _dataset(C1: np.ndarray, phi: np.ndarray) -> Dataset:
    """Fields u = A(X) ĝ / C1 + B(X) ĝ / C1², a rank-6 family that is not linear in 1/C1."""
    rng = np.random.default_rng(0)
    X = rng.uniform(-0.05, 0.05, (40, 3))
    A, B = rng.normal(size=(40, 3, 3)), 0.3 * rng.normal(size=(40, 3, 3))
    g = gravity_direction(phi, np.zeros_like(phi))
    u = (np.einsum("nij,mj->mni", A, g) / C1[:, None, None]
         + np.einsum("nij,mj->mni", B, g) / C1[:, None, None] ** 2)
    m = len(C1)
    return Dataset(X=X, boundary=np.zeros(40, bool), C1=C1, phi=phi, theta=np.zeros(m),
                   direction=g, displacement=u, converged=np.ones(m, bool), splits={},
                   ids=np.array([f"c{i}" for i in range(m)]), node_index=np.arange(40))


@pytest.mark.unit
def test_the_benchmarks_pod_model_recovers_a_field_between_its_cases() -> None:
    """Fitted on a grid of C1 and Φ, it predicts a case between them to 2 % of its size."""
    c1, phi = np.meshgrid([1.0, 1.5, 2.0, 3.0, 5.0], np.arange(-150.0, 181.0, 30.0))
    ds = _dataset(c1.ravel(), phi.ravel())
    config = SurrogateConfig(modes=6, width=32, hidden_layers=2, activation="silu",
                             c1_encoding="inverse", output_scaling="compliance",
                             output_form="gravity_linear", learning_rate=0.003, beta1=0.9,
                             beta2=0.999, lr_schedule="cosine", max_epochs=30, patience=30)
    model, _ = fit(ds, np.arange(c1.size), np.arange(c1.size), config)
    assert model.config.structure == "pod"
    truth = _dataset(np.array([1.25]), np.array([75.0])).displacement[0]
    error = np.linalg.norm(model.predict(1.25, 75.0) - truth, axis=1).max()
    assert error < 0.02 * np.linalg.norm(truth, axis=1).max()
    with pytest.raises(ValueError, match="at least as many training cases"):
        fit(ds, [0, 1, 2], [3], config)
    ds.converged[1] = False
    with pytest.raises(ValueError, match="converged cases only"):
        fit(ds, np.arange(c1.size), [3], config)


@pytest.mark.workflow
def test_the_benchmark_refuses_a_linear_mesh_for_the_centroids(
    small_run, capsys: pytest.CaptureFixture[str]
) -> None:
    """The tests' small run has a linear mesh: ``--centroids`` names the problem, fits nothing."""
    from benchmarks.pod_basis import main

    results = small_run / "results"
    code = main([str(results / "dataset/dataset.h5"), "--model", str(results / "surrogate/model"),
                 "--centroids", "--config", "tests/config.yaml",
                 "--set", "max_epochs=1", "--set", "modes=2"])
    assert code == 2
    assert "10-node tetrahedra" in capsys.readouterr().err
