"""The sweep's spacing error between its directions, from the dataset alone."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.direction_spacing_error import direction_spacing_error, leave_one_out, main
from fem.adaptive import direction_angles
from fem.dataset import Dataset
from fem.directions import gravity_direction
from fem.sweep import sphere_directions

pytestmark = pytest.mark.unit


def _dataset(bump: float) -> Dataset:
    """Two C1 values x a caudal lattice of 24 directions.

    The fields are linear in ĝ over C1, plus at the softer C1 a bump in direction, narrower
    than the lattice's spacing, about its direction nearest gravity towards the feet.
    """
    rng = np.random.default_rng(0)
    X = rng.uniform(-0.05, 0.05, (30, 3))
    A = rng.normal(size=(30, 3, 3))
    dirs = np.array(sphere_directions(24, "caudal"))
    phi, theta = np.tile(dirs[:, 0], 2), np.tile(dirs[:, 1], 2)
    C1 = np.repeat([1.0, 3.0], len(dirs))
    g = gravity_direction(phi, theta)
    u = np.einsum("nij,mj->mni", A, g) / C1[:, None, None]
    toward_feet = g[np.argmin(g[:, 2])]  # the lattice's caudal-most direction
    feet = np.exp(-(1.0 - g @ toward_feet) / 0.01) * (C1 == 1.0)  # none of its neighbours
    u[:, :, 2] += bump * feet[:, None]
    return Dataset(X=X, boundary=np.zeros(30, bool), C1=C1, phi=phi, theta=theta, direction=g,
                   displacement=u, converged=np.ones(len(C1), bool), splits={},
                   ids=np.array([f"case{i}" for i in range(len(C1))]))


def test_a_field_linear_in_the_direction_has_no_gap() -> None:
    gaps = direction_spacing_error(_dataset(bump=0.0))
    assert [s.C1 for s in gaps.stiffness] == [1.0, 3.0]
    for s in gaps.stiffness:
        assert s.directions == 24 and s.over_limit == 0
        assert s.max_mm < 1e-8


def test_a_field_that_changes_fast_with_direction_is_found_where_it_does() -> None:
    soft = leave_one_out(_dataset(bump=5.0), 1.0, limit_mm=0.5)
    worst = soft.rows[0]
    assert worst.max_mm > 1.0 and soft.over_limit >= 1
    assert gravity_direction(np.array(worst.phi), np.array(worst.theta))[2] < -0.97  # the feet
    stiff = leave_one_out(_dataset(bump=5.0), 3.0)
    assert stiff.max_mm < 1e-8  # the bump is at the soft C1 only
    with pytest.raises(ValueError, match="needs five"):
        leave_one_out(_dataset(bump=0.0), 2.0)


def test_a_direction_under_two_names_is_one_node_of_the_interpolant() -> None:
    ds = _dataset(bump=0.0)
    twin = 0  # the first direction again, named (-phi, theta - 180): the same vector
    phi, theta = ds.phi[twin], ds.theta[twin]
    named = (-phi, theta - 180.0 if theta > 0 else theta + 180.0)
    same = gravity_direction(np.array(named[0]), np.array(named[1]))
    assert np.allclose(same, ds.direction[twin])
    more = Dataset(X=ds.X, boundary=ds.boundary, C1=np.append(ds.C1, ds.C1[twin]),
                   phi=np.append(ds.phi, named[0]), theta=np.append(ds.theta, named[1]),
                   direction=np.vstack([ds.direction, ds.direction[twin]]),
                   displacement=np.concatenate([ds.displacement, ds.displacement[twin:twin + 1]]),
                   converged=np.ones(len(ds.C1) + 1, bool), splits={},
                   ids=np.append(ds.ids, "twin"))
    soft = leave_one_out(more, 1.0)
    assert soft.directions == 24 and soft.max_mm < 1e-8


@pytest.mark.parametrize("phi, theta, named", [
    (75.0, -180.0, (-75.0, 0.0)),  # in the plane: named as the plane names it
    (165.0, 180.0, (-165.0, 0.0)),
    (-35.0, 0.0, (-35.0, 0.0)),
    (180.0, 0.0, (180.0, 0.0)),
    (0.0, -60.0, (0.0, 0.0)),  # the pole
    (60.0, -90.0, (60.0, -90.0)),
    (30.5, -45.2, (30.5, -45.2)),
])
def test_proposed_directions_in_the_plane_are_named_as_the_plane_names_them(
        phi: float, theta: float, named: tuple[float, float]) -> None:
    assert direction_angles(gravity_direction(np.array(phi), np.array(theta))) == named


def test_the_command_names_a_missing_dataset(tmp_path, capsys) -> None:
    assert main([str(tmp_path / "none.h5")]) == 2
    assert "does not exist" in capsys.readouterr().err
