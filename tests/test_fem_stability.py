"""Stability where the solves end: the tangent's inertia, and gravity turned to the patch's edge.

The inertia from MUMPS's LDLᵀ is checked against the eigenvalues of the dense tangent on a
very coarse mesh (about 1,600 unknowns), at a stable equilibrium and at a state whose pressure
makes the body unstable; the turn of gravity against a case solved alone.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fem.exceptions import InvalidParameterError
from fem.parameters import Gravity, Loading, SolverSettings
from fem.sweep import Case


@pytest.fixture(scope="module")
def tiny_mesh(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The default geometry with elements of 5–6 cm: a tangent small enough to diagonalise."""
    from meshes.build import MeshSize, write_parametric_mesh
    from meshes.parametric import BreastGeometry

    path = tmp_path_factory.mktemp("tiny") / "mesh.xdmf"
    write_parametric_mesh(BreastGeometry(), MeshSize(global_size=0.06, mound_size=0.05, order=1),
                          path)
    return path


def _dense_signs(problem) -> tuple[int, int]:
    """Negative and positive eigenvalues of the assembled tangent, by LAPACK."""
    import dolfinx.fem.petsc as fem_petsc

    A = fem_petsc.assemble_matrix(problem.tangent, bcs=problem.bcs)
    A.assemble()
    values = np.linalg.eigvalsh(A.convert("dense").getDenseArray())
    A.destroy()
    return int((values < 0).sum()), int((values > 0).sum())


@pytest.mark.solve
def test_the_inertia_counts_the_dense_tangents_eigenvalues(tiny_mesh: Path) -> None:
    """Stable at equilibrium; a state under a large pressure has unstable modes, counted right."""
    from fem.case import CaseRunner
    from fem.stability import tangent_inertia

    with CaseRunner(tiny_mesh) as runner:
        result, _ = runner.solve(Case(1.0, 180.0))
        assert result.converged
        problem = runner.problem
        inertia = tangent_inertia(problem)
        assert inertia.pressure_dofs == len(problem.pressure_dofs) > 0
        assert (inertia.negative, inertia.positive) == _dense_signs(problem)
        assert inertia.zero == 0 and inertia.unstable_modes == 0 and inertia.stable
        # −p δ²J: a large pressure makes the displacement block indefinite
        problem.w.x.array[problem.pressure_dofs] = 2e4
        loaded = tangent_inertia(problem)
        assert (loaded.negative, loaded.positive) == _dense_signs(problem)
        assert loaded.unstable_modes > 0 and not loaded.stable
        assert loaded.as_dict()["unstable_modes"] == loaded.unstable_modes
    # the kept factorisation goes with its problem
    import gc
    import weakref

    alive = weakref.ref(problem)
    del runner, problem
    gc.collect()
    assert alive() is None


@pytest.mark.unit
def test_directions_on_the_great_circle() -> None:
    from fem.directions import gravity_angles as direction_angles
    from studies.fe_study.failure_edge import great_circle

    for phi, theta in ((-75.0, 0.0), (75.0, 0.0), (120.0, -30.0), (90.0, 90.0), (180.0, 0.0)):
        g = Gravity(phi, theta, magnitude=1.0).vector
        assert np.allclose(Gravity(*direction_angles(g), magnitude=1.0).vector, g, atol=1e-12)
    assert direction_angles(Gravity(-75.0, 0.0, magnitude=1.0).vector) == pytest.approx((-75, 0))
    start, target = (Gravity(a, 0.0, magnitude=1.0).vector for a in (-75.0, -90.0))
    span, at = great_circle(start, target)
    assert span == pytest.approx(15.0)
    assert direction_angles(at(5.0)) == pytest.approx((-80.0, 0.0))
    assert np.allclose(at(span), target)
    for other in (start, -start):
        with pytest.raises(InvalidParameterError, match="neither the same nor opposite"):
            great_circle(start, other)


@pytest.mark.solve
def test_turning_gravity_reaches_the_case_solved_alone(tiny_mesh: Path) -> None:
    """Where nothing fails, the turn ends on the target case's equilibrium, every state stable."""
    from fem.case import CaseRunner
    from studies.fe_study.failure_edge import turn

    edge = turn(tiny_mesh, SolverSettings(), 1.0, (180.0, 0.0), (150.0, 20.0), via=(2.0,),
                step_deg=10.0, resolution_deg=1.0)
    assert edge.reached_target and edge.first_failure_deg is None and edge.all_stable
    assert all(0 < s.min_detF < 1.5 and s.contact_vertices is None for s in edge.states)
    assert edge.edge_deg == pytest.approx(edge.span_deg) and len(edge.states) >= 3
    assert [s.angle_deg for s in edge.states] == sorted(s.angle_deg for s in edge.states)
    last = edge.states[-1]
    assert (last.phi, last.theta) == pytest.approx((150.0, 20.0))
    with CaseRunner(tiny_mesh) as runner:
        runner.solve(Case(1.0, 150.0, 20.0))
        u = runner.problem.displacement().x.array.reshape(-1, 3)
        alone = 1e3 * np.linalg.norm(u, axis=1).max()
    assert last.max_displacement_mm == pytest.approx(alone, rel=1e-6)


@pytest.mark.solve
def test_a_turn_whose_steps_fail_stops_at_the_resolution(tiny_mesh: Path) -> None:
    """Steps that cannot converge are halved down to the resolution; the edge is the start."""
    from studies.fe_study.failure_edge import turn

    edge = turn(tiny_mesh, SolverSettings(), 1.0, (180.0, 0.0), (120.0, 0.0), step_deg=8.0,
                resolution_deg=1.0, newton={"snes_max_it": 1, "snes_linesearch_type": "basic"})
    assert not edge.reached_target and edge.edge_deg == 0.0 and len(edge.states) == 1
    assert [f.angle_deg for f in edge.failures] == [8.0, 4.0, 2.0, 1.0]
    assert edge.first_failure_deg == 1.0
    with pytest.raises(InvalidParameterError, match="did not converge"):
        turn(tiny_mesh, SolverSettings(loading=Loading(rescue=False, max_steps=4),
                                       petsc_options={"snes_max_it": 1}), 1.0, (180.0, 0.0),
             (150.0, 0.0), step_deg=8.0, resolution_deg=1.0)
    with pytest.raises(InvalidParameterError, match="stiffer than 1.0 kPa"):
        turn(tiny_mesh, SolverSettings(), 1.0, (180.0, 0.0), (150.0, 0.0), via=(0.8,))


def _columns(rows: list[tuple[float, float, float, bool]]) -> dict[str, np.ndarray]:
    c1, phi, theta, converged = (np.array(col) for col in zip(*rows, strict=True))
    ids = np.array([f"c1={a:.2f}_phi={b:.1f}_theta={c:.1f}" for a, b, c, _ in rows])
    return {"C1": c1, "phi": phi, "theta": theta, "converged": converged, "id": ids,
            "load_fraction": np.where(converged, 1.0, 0.5), "max_disp_mm": np.full(len(ids), 9.0)}


@pytest.mark.unit
def test_the_sweeps_failures_are_traced_softest_first_from_the_nearest_converged_case() -> None:
    from studies.fe_study.sweep_edges import choose_traces

    columns = _columns([
        (1.2, -75.0, 0.0, True), (1.0, -75.0, 0.0, True), (0.9, -75.0, 0.0, False),
        (0.8, -75.0, 0.0, True),     # 0-3: a chain with a failure inside it
        (0.8, -90.0, 0.0, False),    # 4: 15° from -75, 30° from -60 and from (-85, 30)
        (0.8, -60.0, 0.0, True),
        (0.8, 100.0, -120.0, False),  # 6: off the plane, so after 4; nearest to (-85, 30)
        (0.7, -90.0, 0.0, False),    # 7: nothing converged at 0.7: skipped
        (1.0, -90.0, 0.0, False),    # 8: stiffer, so last; from -75 at 1.0
        (0.8, -85.0, 30.0, True),
        (2.0, 0.0, 0.0, False), (2.0, 180.0, 0.0, True),  # 10, 11: only the opposite: skipped
    ])
    traces = choose_traces(columns, 10)
    assert [(t.failed, t.start, t.via) for t in traces] == [
        (4, 3, (1.0, 1.2)),  # through the converged stiffer cases only (0.9 failed)
        (6, 9, ()),
        (8, 1, (1.2,)),
    ]
    assert [t.failed for t in choose_traces(columns, 1)] == [4]
    assert choose_traces(columns, 0) == []


@pytest.mark.solve
def test_a_traced_sweep_is_written_read_and_shown(tiny_mesh: Path, tmp_path: Path) -> None:
    """The record of a sweep's traces round-trips, and the report's table shows it."""
    from report.sections.stability import failure_edges_section
    from studies.fe_study.sweep_edges import SweepEdges, sweep_edges

    # a "failed" case that the turn reaches: the record says so, and names its start
    columns = _columns([(1.0, 180.0, 0.0, True), (1.0, 160.0, 0.0, False)])
    edges = sweep_edges(tiny_mesh, SolverSettings(), columns, 2, step_deg=10.0,
                        resolution_deg=1.0)
    assert edges.failed == 1 and len(edges.traced) == 1
    traced = edges.traced[0]
    assert traced.start_case == "c1=1.00_phi=180.0_theta=0.0" and traced.load_fraction == 0.5
    assert traced.start_sweep_max_mm == 9.0 and traced.edge.states[0].max_displacement_mm > 0
    assert traced.edge.reached_target and traced.edge.span_deg == pytest.approx(20.0)
    edges.write(tmp_path / "failure_edges.json")
    back = SweepEdges.read(tmp_path / "failure_edges.json")
    assert back == edges
    page = failure_edges_section(back)
    assert 'id="failure-edges"' in page and "<td>reached</td>" in page
    assert "1 of the sweep&#x27;s 1 failed cases" in page
    assert "none failed" in failure_edges_section(SweepEdges(failed=0, traced=[], seconds=0.0))
    assert "was not found" in failure_edges_section(None)
    # a start that does not converge again is recorded with its reason, not turned
    crippled = SolverSettings(loading=Loading(rescue=False, max_steps=4),
                              petsc_options={"snes_max_it": 1})
    stuck = sweep_edges(tiny_mesh, crippled, columns, 2, step_deg=10.0, resolution_deg=1.0)
    assert stuck.traced[0].edge is None and "did not converge" in stuck.traced[0].error
    assert "did not converge" in failure_edges_section(stuck)
    with pytest.raises(InvalidParameterError, match="no column load_fraction"):
        sweep_edges(tiny_mesh, SolverSettings(),
                    {k: v for k, v in columns.items() if k != "load_fraction"}, 2)


@pytest.mark.solve
def test_turns_from_both_sides_meet_the_sweeps_solution_where_it_is_unique(
    tiny_mesh: Path, tmp_path: Path
) -> None:
    """Away from any fold the three ways to one direction find one equilibrium."""
    from studies.fe_study.failure_edge import Meeting, meet

    meeting = meet(tiny_mesh, SolverSettings(), 1.0, ((180.0, 0.0), (140.0, 0.0)), (160.0, 0.0),
                   via=(2.0,), step_deg=10.0, resolution_deg=1.0)
    assert all(t.reached_target for t in meeting.turns) and meeting.chain_converged
    assert set(meeting.max_difference_mm) == {"from 180/0|from 140/0", "from 180/0|chain",
                                              "from 140/0|chain"}
    assert max(meeting.max_difference_mm.values()) < 1e-3  # mm, against |u| of tens of mm
    assert all(meeting.stable.values())
    meeting.write(tmp_path / "meet.json")
    assert Meeting.read(tmp_path / "meet.json") == meeting


@pytest.mark.unit
def test_held_out_cases_are_banded_by_their_angle_to_the_nearest_failure() -> None:
    """The angle to the nearest failed direction of the same C1, and the report's bands."""
    from types import SimpleNamespace

    from report.context import Context
    from report.sections.generalisation import held_out_part
    from studies.surrogate_study.errors_against_fe import CaseErrors, ErrorSpread
    from studies.surrogate_study.held_out import (
        HeldOutBlock,
        HeldOutEvaluation,
        by_failure_distance,
        failure_distances,
    )

    ds = SimpleNamespace(C1=np.array([0.8, 0.8, 0.8, 1.0, 0.8]),
                         phi=np.array([-75.0, -90.0, -60.0, -75.0, 100.0]),
                         theta=np.array([0.0, 0.0, 0.0, 0.0, -120.0]),
                         converged=np.array([True, False, True, True, False]))
    near = failure_distances(ds, [0, 2, 3])
    assert near[0] == pytest.approx(15.0) and near[1] == pytest.approx(30.0)
    assert np.isnan(near[2])  # nothing failed at 1.0 kPa
    fe = np.ones((4, 3))
    rows = [CaseErrors.between(fe + e, fe, f"case{k}", 0.8, 0.0, 0.0)
            for k, e in enumerate((3.0, 0.1, 0.2, 0.05))]
    bands = by_failure_distance(rows, [1.4, 17.0, 30.0, float("nan")])
    assert [(label, s.cases) for label, s in bands] == [
        ("within 10° of a failure at its C1", 1), ("10–25°", 1), ("25° or more from one", 1),
        ("no failure at its C1", 1)]
    assert bands[0][1].max_mm == pytest.approx(3.0 * np.sqrt(3))
    with pytest.raises(ValueError, match="3 distances for 4 cases"):
        by_failure_distance(rows, [1.0, 2.0, 3.0])
    block = HeldOutBlock(split="by_direction", held_out="whole directions", groups=["a"],
                         held_out_model=ErrorSpread.over(rows), inside_model=None, rows=rows,
                         inside_rows=[], failure_distance_deg=[1.4, 17.0, 30.0, float("nan")])
    result = HeldOutEvaluation(blocks=[block], inside_all=ErrorSpread.over(rows))
    page = held_out_part(Context(out_dir=Path("."), clinical=[], paths={}, clinical_fields=[],
                                 results={"held_out": result}))
    assert 'id="held-out-near-failures"' in page and "within 10° of a failure" in page
    old = HeldOutBlock(**{**{f: getattr(block, f) for f in block.__dataclass_fields__},
                          "failure_distance_deg": []})
    assert "near-failures" not in held_out_part(Context(
        out_dir=Path("."), clinical=[], paths={}, clinical_fields=[],
        results={"held_out": HeldOutEvaluation(blocks=[old], inside_all=result.inside_all)}))
    assert "unstable equilibrium" not in page  # no audit: nothing said
    from studies.fe_study.stability_audit import AuditedCase, StabilityAudit

    audit = StabilityAudit(C1=[0.8], cases=[AuditedCase("case0", 0.8, 0.0, 0.0, False),
                                             AuditedCase("case1", 0.8, 0.0, 0.0, True)])
    page = held_out_part(Context(out_dir=Path("."), clinical=[], paths={}, clinical_fields=[],
                                 results={"held_out": result, "fe_stability_audit": audit}))
    assert "1 converged case of the sweep (case0) ends on an unstable equilibrium" in page


def _vertex_field(runner) -> tuple[np.ndarray, np.ndarray]:
    """A solved case's displacement at the mesh's vertices (mm), as a dataset holds it."""
    from scipy.spatial import cKDTree

    from studies.fe_study.stability_audit import displacement_rows

    V, rows = displacement_rows(runner.problem)
    x = V.tabulate_dof_coordinates()[: len(rows)]
    vertices = runner.mesh.geometry.x
    distance, dof = cKDTree(x).query(vertices)
    assert distance.max() < 1e-12
    return vertices.copy(), 1e3 * runner.problem.w.x.array[rows[dof]]


@pytest.mark.solve
def test_a_sweeps_own_state_is_polished_and_judged(tiny_mesh: Path) -> None:
    """The audit judges the dataset's state itself: Newton from it stays put.

    A state Newton would leave, or points of another mesh, are not judged.
    """
    from fem.case import CaseRunner
    from studies.fe_study.stability_audit import audit_case, state_from_points

    case = Case(1.0, 160.0, 0.0)
    with CaseRunner(tiny_mesh) as runner:
        assert runner.solve(case)[0].converged
        points, u_mm = _vertex_field(runner)
        order = np.random.default_rng(0).permutation(len(points))  # any order of the points
        state, at, where = state_from_points(runner.problem, points[order], u_mm[order])
        assert len(at) == len(points) and not np.any(state[runner.problem.pressure_dofs])
        judged = audit_case(runner, case, points[order], u_mm[order])
        assert judged.stable is True and judged.unstable_modes == 0 and judged.error == ""
        assert judged.moved_mm < 1e-4 and judged.newton_iterations <= 4
        assert judged.max_mm == pytest.approx(1e3 * np.linalg.norm(
            runner.problem.displacement().x.array.reshape(-1, 3), axis=1).max())
        other = audit_case(runner, case, points, 1.5 * u_mm)  # Newton returns to the answer
        assert other.stable is None and "left the dataset's state" in other.error
        assert other.moved_mm > 1.0
        with pytest.raises(InvalidParameterError, match="not this mesh's"):
            state_from_points(runner.problem, points + 0.01, u_mm)


@pytest.mark.workflow
def test_the_audit_of_a_sweep_reads_its_dataset(
    small_run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Every converged case of the asked C1 judged from the workflow's dataset; errors named."""
    from studies.fe_study.stability_audit import StabilityAudit, main

    results = small_run / "results"
    args = [str(results / "mesh/mesh.xdmf"), str(results / "dataset/dataset.h5"),
            "--config", "tests/config.yaml"]
    assert main([*args, "--c1", "1.0", "--json", str(tmp_path / "audit.json")]) == 0
    audit = StabilityAudit.read(tmp_path / "audit.json")
    assert [c.phi for c in audit.cases] == [0.0, 90.0, 180.0] and audit.C1 == [1.0]
    assert all(c.stable and c.moved_mm < 1e-3 for c in audit.cases), audit.cases
    assert "C1 = 1 kPa: 3 converged cases, 3 judged, 0 unstable" in capsys.readouterr().out
    assert main([*args, "--c1", "2.0"]) == 2
    assert "no case at C1 = 2 kPa (it has 1, 5)" in capsys.readouterr().err


@pytest.mark.unit
def test_the_audit_is_written_read_and_shown(tmp_path: Path) -> None:
    """The record round-trips; the report counts each C1's verdicts and lists the flagged."""
    from report.sections.stability import stability_audit_section
    from studies.fe_study.stability_audit import AuditedCase, StabilityAudit, softest_c1

    assert softest_c1(np.array([1.2, 0.8, 1.0, 0.8]), 2) == [0.8, 1.0]
    assert softest_c1(np.array([1.2]), 3) == [1.2] and softest_c1(np.array([1.2]), 0) == []
    cases = [AuditedCase("c1=0.80_phi=-60.0_theta=0.0", 0.8, -60.0, 0.0, True, moved_mm=2e-6),
             AuditedCase("c1=0.80_phi=67.7_theta=-49.8", 0.8, 67.7, -49.8, False,
                         unstable_modes=1, moved_mm=3e-6, min_detF=0.05, max_mm=60.0),
             AuditedCase("c1=1.00_phi=90.0_theta=0.0", 1.0, 90.0, 0.0, None,
                         error="Newton from the dataset's state: diverged_max_it")]
    audit = StabilityAudit(C1=[0.8, 1.0], cases=cases, seconds=12.0)
    assert [c.case for c in audit.unstable] == [cases[1].case]
    assert [c.case for c in audit.not_judged] == [cases[2].case]
    audit.write(tmp_path / "audit.json")
    assert repr(StabilityAudit.read(tmp_path / "audit.json")) == repr(audit)  # NaN ≠ NaN
    page = stability_audit_section(audit)
    assert 'id="stability-audit"' in page and 'id="unstable-cases"' in page
    assert "<td>0.8</td><td>2</td><td>2</td><td>1</td>" in page
    assert "<td>1</td><td>1</td><td>0</td><td>0</td>" in page
    assert "not judged: Newton from the dataset&#x27;s state" in page
    assert "softest is 0" in stability_audit_section(StabilityAudit(C1=[], cases=[]))
    assert "was not found" in stability_audit_section(None)


@pytest.mark.unit
def test_the_audits_parts_join_in_the_audits_order() -> None:
    """Parts run side by side (every n-th case) join into the record one job would write."""
    from fem.exceptions import InvalidParameterError
    from fem.parameters import SolverSettings
    from studies.fe_study.stability_audit import AuditedCase, StabilityAudit, audit_sweep

    with pytest.raises(InvalidParameterError, match="part 2 of 2: parts are numbered 0 to 1"):
        audit_sweep("mesh.xdmf", "dataset.h5", SolverSettings(), [1.0], part=2, parts=2)
    cases = [AuditedCase(f"case{i}", c1, phi, theta, True) for i, (c1, phi, theta) in enumerate(
        [(0.8, -90.0, 0.0), (0.8, 0.0, 0.0), (0.8, 30.0, -40.0), (1.0, -90.0, 0.0),
         (1.0, 45.0, 20.0)])]
    whole = StabilityAudit(C1=[0.8, 1.0], cases=cases, seconds=10.0, settings={"a": 1})
    parts = [StabilityAudit(C1=[0.8, 1.0], cases=cases[k::2], seconds=5.0 + k,
                            settings={"a": 1}) for k in (1, 0)]
    joined = StabilityAudit.merge(parts)
    assert [c.case for c in joined.cases] == [c.case for c in whole.cases]
    assert (joined.C1, joined.seconds, joined.settings) == ([0.8, 1.0], 11.0, {"a": 1})
    with pytest.raises(InvalidParameterError, match="other C1 values"):
        StabilityAudit.merge([parts[0], StabilityAudit(C1=[0.8], cases=[])])
    with pytest.raises(InvalidParameterError, match="no audit parts"):
        StabilityAudit.merge([])
