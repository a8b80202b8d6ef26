"""The direction-density benchmark's designs, test directions and job batches."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.directions_needed import _batches, designs, random_caudal_directions
from fem.directions import gravity_direction
from fem.sweep import PAPER_PHI_DEG, Case

pytestmark = pytest.mark.unit


def test_random_directions_are_seeded_and_spread_over_the_caudal_half() -> None:
    dirs = np.array(random_caudal_directions(2000, seed=1))
    g = gravity_direction(dirs[:, 0], dirs[:, 1])
    np.testing.assert_allclose(np.linalg.norm(g, axis=1), 1.0)
    assert g[:, 2].max() <= 0.0
    assert np.mean(g[:, 2] > -0.5) == pytest.approx(0.5, abs=0.03)  # uniform over the half
    first = random_caudal_directions(5, seed=1)
    assert first == random_caudal_directions(5, seed=1) != random_caudal_directions(5, seed=2)


def test_designs_are_the_paper_plane_and_caudal_lattices() -> None:
    plans = designs((8, 32))
    assert [p for p, _ in plans["plane"]] == list(PAPER_PHI_DEG)
    assert len(plans["caudal 8"]) == 8 and len(plans["caudal 32"]) == 32


def test_each_direction_goes_whole_to_one_batch() -> None:
    cases = [Case(c1, phi) for c1 in (1.0, 2.0, 5.0) for phi in (0.0, 30.0, 60.0, 90.0, 120.0)]
    batches = _batches(cases, 2)
    assert sorted(len(b) for b in batches) == [6, 9]
    owner = {(c.phi, c.theta): i for i, batch in enumerate(batches) for c in batch}
    assert all(owner[(c.phi, c.theta)] == i for i, batch in enumerate(batches) for c in batch)
    assert sum(len(b) for b in _batches(cases, 8)) == 15 and len(_batches(cases, 8)) == 5
