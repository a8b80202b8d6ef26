"""The Snakemake workflow: planning, config validation, and the small sweep end to end."""

from __future__ import annotations

import json
import os
import re
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml

from tests.conftest import REPO, job_counts, snakemake

pytestmark = pytest.mark.workflow


def test_full_config_plans_its_start_design_and_a_round_and_the_paper_preset_688_in_16(
    tmp_path: Path,
) -> None:
    """The default is adaptive: the start design's chains, then the checkpoint of round 1.

    The rounds' cases are planned once round 1 is written, as the run goes.
    """
    from run.config import WorkflowConfig

    config = WorkflowConfig.from_mapping(yaml.safe_load((REPO / "config.yaml").read_text()))
    start = {f"results/cases/{case.id}/summary.json" for case in config.cases}
    directions = {(case.phi, case.theta) for case in config.cases}
    run = snakemake(tmp_path, "-n", "-j2", config=REPO / "config.yaml")
    assert run.returncode == 0, run.stderr
    text = run.stdout + run.stderr
    counts = job_counts(text)
    assert counts["solve_chain"] == len(directions) and "solve" not in counts
    assert counts["sweep_round"] == 1 and "wildcards: round=1" in text
    assert set(re.findall(r"results/cases/[^,\s]+/summary\.json", text)) == start
    # the paper's own sweep, on the same config: its fixed grid, no rounds
    run = snakemake(tmp_path, "-n", "-j2", "--config", "sweep={preset: paper}",
                    config=REPO / "config.yaml")
    assert run.returncode == 0, run.stderr
    text = run.stdout + run.stderr
    counts = job_counts(text)
    assert counts["solve_chain"] == 16 and "sweep_round" not in counts
    assert len(set(re.findall(r"results/cases/[^,\s]+/summary\.json", text))) == 688
    # chains off: one job per case
    raw = yaml.safe_load((REPO / "config.yaml").read_text())
    raw["sweep"]["chains"] = False
    (tmp_path / "per_case.yaml").write_text(yaml.safe_dump(raw))
    run = snakemake(tmp_path, "-n", "-j2", config=tmp_path / "per_case.yaml")
    assert run.returncode == 0, run.stderr
    counts = job_counts(run.stdout + run.stderr)
    assert counts["solve"] == len(start) and "solve_chain" not in counts
    assert counts["sweep_round"] == 1
    assert counts["mesh"] == counts["aggregate"] == counts["select_model"] == counts["report"] == 1


def test_one_case_path_runs_its_chain_or_itself(tmp_path: Path) -> None:
    """A case at a C1 value of the sweep runs its direction's chain; any other is solved alone.

    With the default adaptive sweep, at any direction: a round may add it.
    """
    for target, job in (("c1=2.00_phi=-150.0_theta=0.0", "solve_chain"),
                        ("c1=2.30_phi=-150.0_theta=0.0", "solve"),
                        ("c1=2.00_phi=-140.0_theta=-20.0", "solve_chain")):
        run = snakemake(tmp_path, "-n", "-j2", f"results/cases/{target}/summary.json",
                        config=REPO / "config.yaml")
        assert run.returncode == 0, run.stderr
        assert job_counts(run.stdout + run.stderr) == {"mesh": 1, job: 1, "total": 2}


def test_a_sphere_sweep_chains_each_direction_and_only_its_directions(tmp_path: Path) -> None:
    """The chain's wildcard matches the sweep's (Φ, θ) pairs, not their Φ × θ combinations."""
    from fem.sweep import Case, sphere_directions

    config = yaml.safe_load((REPO / "config.yaml").read_text())
    config["sweep"] = {"C1_kPa": [1.0, 2.0, 5.0], "sphere": {"n": 8, "part": "caudal"}}
    (tmp_path / "sphere.yaml").write_text(yaml.safe_dump(config))
    run = snakemake(tmp_path, "-n", "-j2", "results/dataset/dataset.h5",
                    config=tmp_path / "sphere.yaml")
    assert run.returncode == 0, run.stderr
    assert job_counts(run.stdout + run.stderr)["solve_chain"] == 8
    first, second = (Case(1.0, p, t) for p, t in sphere_directions(8, "caudal")[:2])
    mixed = Case(1.0, first.phi, second.theta)  # its angles are the sweep's, its direction not
    for case, job in ((first, "solve_chain"), (mixed, "solve")):
        run = snakemake(tmp_path, "-n", "-j2", f"results/cases/{case.id}/summary.json",
                        config=tmp_path / "sphere.yaml")
        assert run.returncode == 0, run.stderr
        assert job_counts(run.stdout + run.stderr) == {"mesh": 1, job: 1, "total": 2}


def planned(workdir: Path, config: Path, *targets: str) -> tuple[dict[str, int], set[str]]:
    """The jobs of a dry run for ``targets``, and the case summaries it names."""
    run = snakemake(workdir, "-n", "-j2", *targets, config=config)
    assert run.returncode == 0, run.stderr
    text = run.stdout + run.stderr
    return job_counts(text), set(re.findall(r"results/cases/([^/,\s]+)/summary\.json", text))


def test_a_chain_is_one_direction_at_every_c1_of_a_fixed_or_an_adaptive_sweep(
    tmp_path: Path,
) -> None:
    """Fixed: the design's directions only. Adaptive: any direction, so a round's are chains."""
    from fem.adaptive import RoundPlan
    from fem.sweep import Case, sweep_cases

    fixed = {"C1_kPa": [1.0, 1.2, 5.0], "phi_deg": [0.0, 90.0, 180.0],
             "sphere": {"n": 4, "part": "caudal"}}
    start = {case.id for case in sweep_cases(fixed)}
    levels = (5.0, 1.2, 1.0)
    assert len(start) == 3 * 7
    new = (45.0, -30.0)  # no direction of the start design
    config = yaml.safe_load((REPO / "config.yaml").read_text())
    for name, sweep in (("fixed", fixed),
                        ("adaptive", {**fixed, "adaptive": {"max_cases": 40, "per_round": 2}})):
        config["sweep"] = sweep
        (tmp_path / f"{name}.yaml").write_text(yaml.safe_dump(config))
    fixed_config, adaptive_config = tmp_path / "fixed.yaml", tmp_path / "adaptive.yaml"
    chain = {Case(c1, *new).id for c1 in levels}

    counts, cases = planned(tmp_path, fixed_config, "results/dataset/dataset.h5")
    assert counts["solve_chain"] == 7 and "solve" not in counts and "sweep_round" not in counts
    assert cases == start
    # a design's case runs its chain, every C1 of its direction; another direction's, alone
    counts, cases = planned(tmp_path, fixed_config, "results/cases/c1=1.20_phi=90.0_theta=0.0/"
                            "summary.json")
    assert counts == {"mesh": 1, "solve_chain": 1, "total": 2}
    assert cases == {Case(c1, 90.0).id for c1 in levels}
    counts, cases = planned(tmp_path, fixed_config, f"results/cases/{Case(1.0, *new).id}/"
                            "summary.json")
    assert counts == {"mesh": 1, "solve": 1, "total": 2} and cases == {Case(1.0, *new).id}

    # adaptive: the start design, then round 1's checkpoint
    counts, cases = planned(tmp_path, adaptive_config, "results/dataset/dataset.h5")
    assert counts["solve_chain"] == 7 and counts["sweep_round"] == 1 and "solve" not in counts
    assert cases == start
    # a direction outside the start design is a chain too; a C1 outside the sweep's is not
    counts, cases = planned(tmp_path, adaptive_config, f"results/cases/{Case(1.0, *new).id}/"
                            "summary.json")
    assert counts == {"mesh": 1, "solve_chain": 1, "total": 2} and cases == chain
    counts, cases = planned(tmp_path, adaptive_config, f"results/cases/{Case(2.0, *new).id}/"
                            "summary.json")
    assert counts == {"mesh": 1, "solve": 1, "total": 2}

    # round 1 planned after the start design was solved: its direction is one chain, then
    # round 2 (files stand in for the solved cases, older than the plan that read them)
    for name in ("mesh.xdmf", "mesh.h5", "quality.json", "mesh.png"):
        (tmp_path / "results" / "mesh").mkdir(parents=True, exist_ok=True)
        (tmp_path / "results" / "mesh" / name).touch()
    for case in start:
        folder = tmp_path / "results" / "cases" / case
        folder.mkdir(parents=True)
        for name in ("summary.json", "points.h5", "fields.xdmf", "fields.h5"):
            (folder / name).touch()
    RoundPlan(1, 21, 21, 2.0, (1.0, *new), 0.1, 1.0, directions=[new],
              cases=sorted(chain)).write(tmp_path / "results" / "sweep" / "round_1.json")
    stamp = time.time()
    for path in (tmp_path / "results").rglob("*"):
        if path.is_file():
            late = 10.0 if path.name == "round_1.json" else 0.0
            os.utime(path, (stamp - 20.0 + late, stamp - 20.0 + late))
    run = snakemake(tmp_path, "-n", "-j2", "results/dataset/dataset.h5", config=adaptive_config)
    assert run.returncode == 0, run.stderr
    text = run.stdout + run.stderr
    assert job_counts(text) == {"solve_chain": 1, "sweep_round": 1, "aggregate": 1, "total": 3}
    assert f"wildcards: direction=phi={new[0]:.1f}_theta={new[1]:.1f}" in text
    assert "wildcards: round=2" in text and "wildcards: round=1" not in text


@pytest.mark.parametrize(
    "section, key, value, message",
    [
        ("sweep", "C1_kPa", [1.0, -2.0], "sweep.C1_kPa"),
        ("material", "density", 0.0, "material.density"),
        ("surrogate", "width", 0, "surrogate.width"),
        ("fe", "contact", {"stiffness": 0}, "fe.contact.stiffness"),
        ("fe", "contact", {"obstacle": "floor"}, "fe.contact.obstacle"),
    ],
)
def test_out_of_bounds_config_stops_before_any_job(
    tmp_path: Path, section: str, key: str, value: object, message: str
) -> None:
    config = yaml.safe_load((REPO / "tests" / "config.yaml").read_text())
    config.setdefault(section, {})[key] = value
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(config))
    run = snakemake(tmp_path, "-j1", config=path)
    assert run.returncode != 0
    assert "invalid configuration" in run.stderr and message in run.stderr
    assert not (tmp_path / "results").exists()


def test_a_typed_value_given_inside_a_mapping_with_config_is_explained(tmp_path: Path) -> None:
    """Snakemake's ``--config`` passes ``sweep={chains: false}``'s false on as text."""
    run = snakemake(tmp_path, "-j1", "-n", "--config", "sweep={chains: false}")
    said = run.stdout + run.stderr  # a dry run reports the error on stdout
    assert run.returncode != 0
    assert "sweep.chains: 'false' is not of type 'boolean'" in said
    assert "set it in a file given with --configfile instead" in said
    assert not (tmp_path / "results").exists()


def test_inconsistent_geometry_stops_before_any_job(tmp_path: Path) -> None:
    config = yaml.safe_load((REPO / "tests" / "config.yaml").read_text())
    config["mesh"]["geometry"] = {"mound_radius_cranial": 0.11}
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(config))
    run = snakemake(tmp_path, "-j1", config=path)
    assert run.returncode != 0 and "cranial or caudal" in run.stderr
    assert not (tmp_path / "results").exists()


def test_small_sweep_dataset_content(small_run: Path) -> None:
    config = yaml.safe_load((REPO / "tests" / "config.yaml").read_text())
    n_cases = len(config["sweep"]["C1_kPa"]) * len(config["sweep"]["phi_deg"])
    with h5py.File(small_run / "results/dataset/dataset.h5") as h5:
        u = h5["displacement"][...]
        kind = h5["points/kind"][...]
        assert u.shape == (n_cases, h5["points/X"].shape[0], 3)
        assert np.all(h5["cases/converged"][...])
        boundary = kind == 1
        assert 0 < boundary.sum() < len(kind)
        assert np.all(u[:, boundary] == 0.0)  # clamped on the chest wall
        norms = np.linalg.norm(u[:, ~boundary], axis=2)
        assert np.all(norms.max(axis=1) > 1e-3)  # every case sags by more than a millimetre
        C1 = h5["cases/C1"][...]
        phi = h5["cases/phi"][...]
        prone_soft = np.flatnonzero((C1 == 1.0) & (phi == 180.0))[0]
        prone_stiff = np.flatnonzero((C1 == 5.0) & (phi == 180.0))[0]
        # five times stiffer sags about five times less (near-linear regime)
        ratio = np.abs(u[prone_soft]).max() / np.abs(u[prone_stiff]).max()
        assert 3.5 < ratio < 7.0
    for case in (small_run / "results/cases").iterdir():
        assert (case / "fields.xdmf").is_file() and (case / "fields.h5").is_file()


def test_small_sweep_surrogate_predicts_the_fe(small_run: Path) -> None:
    from fem.dataset import read_dataset
    from surrogate.predict import Surrogate

    ds = read_dataset(small_run / "results/dataset/dataset.h5")
    model = Surrogate.load(small_run / "results/surrogate/model")
    total_err = total_norm = 0.0
    for case in range(len(ds.C1)):
        fe = ds.displacement[case]
        pred = model.predict(float(ds.C1[case]), float(ds.phi[case]))
        err = np.linalg.norm(pred - fe, axis=1).mean()
        norm = np.linalg.norm(fe, axis=1).mean()
        # at least twice as good as predicting no displacement, in every case ...
        assert err < 0.5 * norm, ds.ids[case]
        total_err, total_norm = total_err + err, total_norm + norm
    # ... and within 15 % of the typical displacement over the sweep
    assert total_err < 0.15 * total_norm


def test_the_movement_between_two_postures_is_written_for_paraview(
    small_run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``predict --from-phi`` on the whole field: each point's way from prone to supine.

    The ``.xdmf`` holds the displacement and, beside it, the movement from the other posture,
    the difference of the two predictions; the command prints its largest and mean.
    """
    import meshio

    from surrogate.cli import main
    from surrogate.predict import Surrogate

    model_dir = small_run / "results/surrogate/model"
    out = tmp_path / "moved.xdmf"
    assert main(["predict", str(model_dir), "--c1", "1.0", "--phi", "0", "--from-phi", "180",
                 "--mesh", str(small_run / "results/mesh/mesh.xdmf"), "-o", str(out)]) == 0
    model = Surrogate.load(model_dir)
    way = np.linalg.norm(model.predict(1.0, 0.0) - model.predict(1.0, 180.0), axis=1)
    said = capsys.readouterr().out
    assert (f"moved from Φ = 180°, θ = 0° (at the same C1): max |Δx| = {way.max():.3f} mm, "
            f"mean |Δx| = {way.mean():.3f} mm") in said
    fields = meshio.read(out).point_data
    np.testing.assert_allclose(np.sort(fields["movement_magnitude_mm"]), np.sort(way),
                               atol=1e-4)
    before = fields["displacement_mm"] - fields["movement_mm"]  # prone's, in the file's order
    np.testing.assert_allclose(np.sort(np.linalg.norm(before, axis=1)), np.sort(
        np.linalg.norm(model.predict(1.0, 180.0), axis=1)), atol=1e-4)
    assert main(["predict", str(model_dir), "--c1", "1.0", "--phi", "0", "--from-phi", "180",
                 "-o", str(tmp_path / "u.npy")]) == 2
    assert "an .npy holds the displacement alone" in capsys.readouterr().err


def test_a_cases_fe_field_answers_at_named_points(
    small_run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A case's FE displacement at material points, by its shape functions.

    The command is ``studies.reference_state.fe_at_points``.

    At the mesh's vertices it is the case's own ``points.h5``; between them, at a cell's
    centroid, the field's value there (the quadratic field's on a quadratic mesh, the corners'
    mean on the test config's linear one). A case that did not converge is refused.
    """
    import json
    import shutil

    from fem.case_files import read_node_displacement
    from fem.dataset import read_dataset
    from meshes.points import read_points
    from studies.reference_state.fe_at_points import CasePointsError, fe_at_points, main
    from surrogate.interpolation import at_centroids

    ds = read_dataset(small_run / "results/dataset/dataset.h5")
    case = small_run / "results/cases" / str(ds.ids[0])
    assert np.allclose(fe_at_points(case, ds.X[:50]), ds.displacement[0][:50], atol=1e-9)
    u, cells, nodes = read_node_displacement(case / "fields.h5")
    if cells.shape[1] == 10:  # a quadratic mesh: the quadratic field at the centroid
        centroids, at_them = at_centroids(nodes, cells[:3]), at_centroids(u, cells[:3])
    else:  # a linear one (the test config's): the mean of the corners
        centroids, at_them = nodes[cells[:3]].mean(axis=1), u[cells[:3]].mean(axis=1)
    np.testing.assert_allclose(fe_at_points(case, centroids), 1e3 * at_them, atol=1e-9)
    points = tmp_path / "tumour.csv"
    points.write_text("name,x,y,z\n" + "".join(
        f"t{i},{x!r},{y!r},{z!r}\n" for i, (x, y, z) in enumerate(centroids)))
    out = tmp_path / "moved.csv"
    assert main([str(case), str(points), "-o", str(out)]) == 0
    assert "t2 " in capsys.readouterr().out
    names, moved = read_points(out)
    assert names == ["t0", "t1", "t2"]
    np.testing.assert_allclose(moved, centroids + at_them, atol=1e-12)
    # --from another case: the points' movement between the two cases' postures
    other = small_run / "results/cases" / str(ds.ids[1])
    assert main([str(case), str(points), "--from", str(other)]) == 0
    table = capsys.readouterr().out.split(f"moved from {other.name} to {case.name}:\n")[1]
    way = 1e3 * at_them - fe_at_points(other, centroids)
    for line, d in zip(table.splitlines()[1:], way, strict=True):
        np.testing.assert_allclose([float(x) for x in line.split()[1:]],
                                   [np.linalg.norm(d), *d], atol=6e-4)
    failed = tmp_path / "failed"
    shutil.copytree(case, failed)
    summary = json.loads((failed / "summary.json").read_text())
    summary.update(status="failed", reason="diverged_max_it", load_fraction=0.5)
    (failed / "summary.json").write_text(json.dumps(summary))
    with pytest.raises(CasePointsError, match="did not converge .*at 50 % of the load"):
        fe_at_points(failed, centroids)
    assert main([str(failed), str(points)]) == 2
    assert main([str(case), str(points), "--from", str(failed)]) == 2
    assert "did not converge" in capsys.readouterr().err


REPORT_SECTIONS = (
    "Mesh",
    "FE speed against accuracy",
    "Surrogate speed against accuracy",
    "Model no more than a scene needs",
    "Stability",
    "The paper side by side",
    "Sweep cost",
    "The time of this run",
    "Surrogate training",
    "From the imaged shape to the reference state",
    "The surrogate between its cases and in every posture",
    "The surrogate outside its training data",
    "What the skin changes",
)


def html_table(page: str, table_id: str) -> str:
    """The HTML of the report's table with this id."""
    match = re.search(rf'<table id="{table_id}">(.*?)</table>', page, re.S)
    assert match, f"the report has no table {table_id!r}"
    return match[1]


def png_size(path: Path) -> tuple[int, int]:
    """Width and height of a PNG, from its header."""
    data = path.read_bytes()[:24]
    assert data[:8] == b"\x89PNG\r\n\x1a\n", f"{path.name} is not a PNG"
    return int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")


def test_small_sweep_report(small_run: Path) -> None:
    results = small_run / "results"
    report = results / "report"
    page = (report / "index.html").read_text()
    for heading in REPORT_SECTIONS:
        assert f"<h2>{heading}</h2>" in page, heading
    assert "could not be built" not in page
    # the run that built it, from its own Snakemake log: every stage before the report ended
    run_time = html_table(page, "run-time")
    assert "<td>dataset</td><td>1 of 1</td>" in run_time and "the dataset " in page
    # every figure is a PNG beside the page, referenced relatively, and has content
    images = re.findall(r'<img[^>]*src="([^"]+)"', page)
    config = yaml.safe_load((REPO / "tests" / "config.yaml").read_text())
    fig5 = [img for img in images if img.startswith("fig5_")]
    assert len(fig5) == len(config["clinical"])
    assert {"fe_speed_accuracy.png", "surrogate_speed_accuracy.png", "c1_effect.png",
            "convergence_maps.png", "extrapolation.png", "sweep_cost.png",
            "training_history.png"} <= set(images)
    for img in images:
        assert img.endswith(".png") and "/" not in img, img
        assert (report / img).stat().st_size > 5000, img
        width, height = png_size(report / img)
        assert width >= 400 and height >= 300, img
    # numbers from the result files appear in their tables
    table2 = json.loads((results / "surrogate/study/table2.json").read_text())
    selected = table2["selected_architecture"]
    ours = html_table(page, "table2")
    assert f'<tr class="highlight"><td>{selected}</td>' in ours
    assert f"{table2['rows'][selected]['validation_error_mm']['mean']:.3g}" in ours
    speed_accuracy = json.loads((results / "fe_study/speed_accuracy.json").read_text())
    variants = html_table(page, "fe-variants")
    for variant in speed_accuracy["variants"]:
        assert f"<td>{variant['dofs']}</td>" in variants
    clinical = json.loads((results / "surrogate/clinical.json").read_text())
    table3 = html_table(page, "table3-by_sample")
    for row in clinical["by_sample"]["rows"]:
        assert f"{row['rmse_mm']:.3g} ± {row['sd_mm']:.3g}" in table3
    # the reference state: the estimate's error beside the naive one, from the result file
    trips = json.loads((results / "reference/roundtrip.json").read_text())["rows"]
    roundtrip = html_table(page, "reference-roundtrip")
    for trip in trips:
        assert trip["converged"] and trip["target_error_mm"] < 0.01 * trip["target_sag_mm"]
        assert trip["naive_error_mm"] > 10 * trip["target_error_mm"]
        assert f"{trip['naive_error_mm']:.2f}" in roundtrip
        # found by the inverse-motion solve, checked by forward solves from its answer
        assert trip["method"] == "inverse" and trip["inverse_newton_iterations"] > 0
        assert (f"1 inverse ({trip['inverse_newton_iterations']} Newton its) + "
                f"{trip['forward_solves']} forward") in roundtrip
    convergence = json.loads((results / "fe_study/convergence_map.json").read_text())
    sweep_lowest = html_table(page, "sweep-lowest-converging")
    assert "sweep: lowest converging C1" in sweep_lowest
    with h5py.File(results / "dataset/dataset.h5") as h5:
        converged = h5["cases/converged"][...]
        overlap = h5["cases/self_overlap"][...]
        force = h5["cases/contact_force_N"][...]
        started, finished = h5["cases/process_start_s"][...], h5["cases/finished_s"][...]
    assert f"{int((~converged).sum())} of {converged.size} cases did not reach" in page
    # the sweep's wall time, from its cases' clocks: every case ends after its process started
    assert (started < finished).all()
    from report.html import seconds

    span = seconds(float(finished.max() - started.min()))
    assert f"between runs included)</td><td>{span}</td>" in html_table(page, "sweep-cost")
    # tests/config.yaml solves with contact: every converged case records its force, 0 N or more
    assert (force[converged] >= 0).all()
    touching = int((force > 0).sum())
    assert (f"Solved with contact of the skin with the chest: {touching} "
            f"{'case ends' if touching == 1 else 'cases end'} in contact") in page
    assert ("No case ends passing through itself" in page) == (not overlap.any())
    lowest = html_table(page, "lowest-converging")
    for scheme, per_phi in convergence["lowest_converging"].items():
        assert f"{scheme}: lowest converging C1" in lowest
        if per_phi["all_phi"] is not None:
            assert f"<td>{per_phi['all_phi']:g}</td>" in lowest


def section_html(page: str, section_id: str) -> str:
    """The HTML of the report's section with this id."""
    match = re.search(rf'<section id="{section_id}">(.*?)</section>', page, re.S)
    assert match, f"the report has no section {section_id!r}"
    return match[1]


def test_the_first_report_shows_the_first_results_as_the_full_one_does(small_run: Path) -> None:
    """The first report: its sections only, the full report named, the 3D view linked.

    Sections that read only the first report's inputs are the full report's, word for word.
    """
    from report.build import FIRST_SECTIONS

    report = small_run / "results/report"
    first, full = (report / "first/index.html").read_text(), (report / "index.html").read_text()
    assert re.findall(r'<section id="([^"]+)">', first) == [
        s for s in re.findall(r'<section id="([^"]+)">', full) if s in FIRST_SECTIONS]
    assert "first report" in first and "results/report/index.html" in first
    assert "could not be built" not in first
    link = re.search(r'<p class="viewer"><a href="([^"]+)">', first)
    assert link and (report / "first" / link[1]).resolve() == (
        small_run / "results/viewer/index.html").resolve()
    for section in ("mesh", "sweep-cost", "training"):
        assert section_html(first, section) == section_html(full, section), section
    for img in re.findall(r'<img[^>]*src="([^"]+)"', first):
        assert (report / "first" / img).stat().st_size > 5000, img


def test_the_study_repeats_only_the_architectures_close_to_the_best(small_run: Path) -> None:
    """Only the best first run's architecture trains its repeat; Table 2 counts what ran.

    tests/config.yaml sets surrogate_study.repeat_within to 0.
    """
    from studies.surrogate_study.architecture import ArchitectureTable, RepeatPlan, read_run

    study = small_run / "results/surrogate/study"
    plan = RepeatPlan.read(study / "repeats.json")
    first = {a: read_run(study / a / "r0")["validation_error_mm"] for a in ("1x16", "2x32")}
    assert plan.first_error_mm == first
    best = min(first, key=first.get)
    assert plan.runs == {a: 2 if a == best else 1 for a in first}
    trained = sorted(str(p.parent.relative_to(study)) for p in study.glob("*/r*/model.json"))
    assert trained == sorted(f"{a}/r{r}" for a, n in plan.runs.items() for r in range(n))
    table = ArchitectureTable.read(study / "table2.json")
    assert {a: row.runs for a, row in table.rows.items()} == plan.runs
    assert (table.repeats, table.repeat_within) == (2, 0.0)
    page = (small_run / "results/report/index.html").read_text()
    assert "(surrogate_study.repeat_within)" in page  # Table 2's caption says why
    once = next(a for a, n in plan.runs.items() if n == 1)
    row = re.search(rf"<tr[^>]*><td>{once}</td>(.*?)</tr>", html_table(page, "table2"), re.S)
    assert row and "±" not in row[1].split("</td>")[2]  # one run: its error without an SD


def test_the_model_used_downstream_is_the_selected_run_trained_again(small_run: Path) -> None:
    """surrogate_study.refit (default): the selected run's config trained on its validation too.

    For its best epoch's worth of epochs; the report says that its validation error is then on
    data it trained on.
    """
    results = small_run / "results"
    table = json.loads((results / "surrogate/study/table2.json").read_text())
    run = json.loads((small_run / table["selected_run"] / "model.json").read_text())
    model = json.loads((results / "surrogate/model/model.json").read_text())
    assert model["config"] == run["config"]
    assert model["metrics"]["refit"] and not run["metrics"]["refit"]
    assert model["metrics"]["epochs"] == model["metrics"]["best_epoch"] == run["metrics"][
        "best_epoch"]
    assert model["metrics"]["n_train_cases"] >= run["metrics"]["n_train_cases"]
    assert "c1_by_direction" in model["training_range"]
    page = (results / "report/index.html").read_text()
    assert "validation error, on data it trained on (mm)" in html_table(page, "training")
    assert (results / "benchmarks/surrogate/select_model.tsv").is_file()


def test_held_out_models_and_postures_are_judged_against_fe(small_run: Path) -> None:
    """Held-out models are judged on exactly their held-out groups; postures against FE.

    A posture's FE case comes from the sweep or from one solve outside it, as configured; the
    random case off the grid from a solve outside it.
    """
    from fem.dataset import read_dataset
    from studies.surrogate_study.held_out import HeldOutEvaluation
    from studies.surrogate_study.postures import PostureEvaluation

    results = small_run / "results"
    ds = read_dataset(results / "dataset/dataset.h5")
    held = HeldOutEvaluation.read(results / "surrogate/held_out.json")
    # tests/config.yaml: three directions (one can be held out), two C1 values (none can)
    assert [b.split for b in held.blocks] == ["by_case", "by_direction"]
    for block in held.blocks:
        model = json.loads((results / f"surrogate/model_{block.split}/model.json").read_text())
        assert model["config"]["split"] == block.split
        test = [str(ds.ids[i]) for i in ds.splits[block.split]["test"]]
        assert [r.case for r in block.rows] == [r.case for r in block.inside_rows] == test
        assert len(block.failure_distance_deg) == len(block.rows)  # NaN where none failed
        assert len(block.warned) == len(block.rows)
        for row in block.rows:
            assert 0 <= row.mean_mm <= row.p95_mm <= row.max_mm
            assert row.relative_max == pytest.approx(row.max_mm / row.fe_max_mm)
    direction = held.blocks[1]
    assert len(direction.groups) == 1
    assert set(ds.phi[ds.splits["by_direction"]["test"]]) == {float(direction.groups[0]
                                                              .split("/")[0][4:])}
    assert held.inside_all.cases == int(ds.converged.sum())

    postures = PostureEvaluation.read(results / "surrogate/postures.json")
    assert [(r.posture, r.in_sweep) for r in postures.rows] == [("prone", True),
                                                               ("standing", False)]
    standing = postures.rows[1]
    assert (results / "outside" / standing.case / "summary.json").is_file()
    assert standing.kind == "unseen theta" and standing.extrapolation_warnings
    assert all(r.errors is not None and r.errors.max_mm > 0 for r in postures.rows)
    page = (results / "report/index.html").read_text()
    table = html_table(page, "postures")
    assert f"{standing.errors.max_mm:.3g}" in table and "standing" in table
    held_table = html_table(page, "held-out")
    assert "by-direction" in held_table and f"{direction.held_out_model.max_mm:.3g}" in held_table

    # the random case off the grid (surrogate_study.off_grid): solved outside the sweep
    from studies.surrogate_study.off_grid import OffGridEvaluation

    off_grid = OffGridEvaluation.read(results / "surrogate/off_grid.json")
    (row,) = off_grid.rows
    assert row.case not in set(ds.ids) and not row.in_sweep
    assert (results / "outside" / row.case / "summary.json").is_file()
    assert row.errors is not None and off_grid.spread.max_mm == row.errors.max_mm > 0
    assert f"{row.errors.max_mm:.3g}" in html_table(page, "off-grid")

    # where the selected model warns over its trained range (rule warning_coverage)
    from studies.surrogate_study.warning_coverage import WarningCoverage

    coverage = WarningCoverage.read(results / "surrogate/warning_coverage.json")
    assert coverage.queries > 0 and sum(b.queries for b in coverage.bands) == coverage.queries
    assert f"<td>all</td><td>{coverage.queries}</td><td>{coverage.warned}</td>" in html_table(
        page, "warning-coverage")


def test_held_out_command_prints_the_workflows_figures(small_run: Path, capsys) -> None:
    """``python -m studies.surrogate_study.held_out``: a model's held-out errors as JSON."""
    from studies.surrogate_study.held_out import HeldOutEvaluation, main

    results = small_run / "results"
    dataset = results / "dataset/dataset.h5"
    direction = HeldOutEvaluation.read(results / "surrogate/held_out.json").blocks[1]
    assert main([str(dataset), str(results / "surrogate/model_by_direction"),
                 "--bands", "1.5"]) == 0
    out = capsys.readouterr().out
    spread = direction.held_out_model
    assert (f"held out{spread.cases:>19} cases  {spread.mean_mm:.4f} / {spread.p95_mm:.3f} / "
            f"{spread.max_mm:.3f} mm") in out
    assert "trained on" in out and "C1 < 1.5" in out and "C1 >= 1.5" in out
    assert main([str(dataset), str(results / "no_such_model")]) == 2
    assert "error:" in capsys.readouterr().err


def test_fe_study_rules_run_end_to_end(small_run: Path) -> None:
    """The FE study's rules ran as part of the small workflow (the report needs them)."""
    config = yaml.safe_load((REPO / "tests" / "config.yaml").read_text())
    study = small_run / "results" / "fe_study"

    clinical = json.loads((study / "fe_clinical.json").read_text())
    assert len(clinical["cases"]) == len(config["clinical"])
    for row in clinical["cases"]:
        # measured and positive; its size is a timing ratio, the benchmark's to judge (it fell
        # to 0.23 with a niced test run starved beside a sweep on both cores)
        assert row["converged"] and row["wall_s"] > 0 and row["factorization_equivalents"] > 0
        steps = config["fe_study"]["clinical"]["baseline_fixed_steps"]
        assert row["baseline"]["load_steps"] == steps
        # the baseline reaches the same state, and the reference is a different discretisation
        assert row["baseline"]["max_difference_from_adaptive_mm"] < 1e-3
        assert 0 < row["accuracy"]["relative_max_error"] < 0.2
    assert set(clinical["summary"]["targets"]) == {
        "median_wall_s",
        "factorization_equivalents",
        "relative_max_error",
    }

    sa = json.loads((study / "speed_accuracy.json").read_text())
    assert len(sa["variants"]) == 3 and sa["pareto_front"]
    by_solver = {v["solver"]: v for v in sa["variants"] if v["element"] == "p2p1"}
    assert by_solver["direct"]["max_relative_error"] == pytest.approx(
        by_solver["iterative"]["max_relative_error"], rel=1e-5
    )

    convergence = json.loads((study / "convergence_map.json").read_text())
    schemes = {r["scheme"] for r in convergence["records"]}
    assert schemes == {"adaptive", "fixed-4"}
    assert convergence["schemes"]["adaptive"]["rescue"] and not convergence["schemes"]["fixed-4"][
        "rescue"]
    assert convergence["schemes"]["adaptive"]["rescue_min_step"] == 1 / 16
    page = (small_run / "results" / "report" / "index.html").read_text()
    assert "down to 0.0156, then a last resort from rest down to 0.0625" in page
    assert len(convergence["records"]) == 2 * 2 * 2
    assert convergence["lowest_converging"]["adaptive"]["all_phi"] is not None
    # the sweep's failures traced (the small sweep's stiff cases converge: none to trace)
    from fem.dataset import read_case_columns

    failed = int((~read_case_columns(small_run / "results/dataset/dataset.h5")["converged"]).sum())
    edges = json.loads((study / "failure_edges.json").read_text())
    assert edges["failed"] == failed and len(edges["traced"]) <= min(failed, 2)
    assert "Where the sweep&#x27;s failures begin" in page
    # the softest C1 values' converged cases judged for stability (both of the small sweep's)
    from studies.fe_study.stability_audit import StabilityAudit

    audit = StabilityAudit.read(study / "stability_audit.json")
    columns = read_case_columns(small_run / "results/dataset/dataset.h5")
    assert audit.C1 == [1.0, 5.0] and len(audit.cases) == int(columns["converged"].sum())
    # in the audit's order, though shared by fe_study.stability_audit.jobs jobs side by side
    order = [(c.C1, c.theta != 0.0, c.phi, c.theta) for c in audit.cases]
    assert order == sorted(order)
    assert all((small_run / f"results/logs/fe_study/stability_audit_part{k}.log").is_file()
               for k in range(2))
    assert all(c.stable is not None and c.moved_mm < 1e-3 for c in audit.cases), audit.cases
    assert "Are the sweep&#x27;s converged states stable?" in page
    assert 'id="stability-audit"' in page
    # the named prone case cut at the fold both ways: nothing touches, the same state
    from studies.fe_study.fold_section import FoldSections

    (fold,) = FoldSections.read(study / "fold_section.json").cases
    assert fold.case == "c1=2.00_phi=180.0_theta=0.0"
    on, off = sorted(fold.states, key=lambda s: s.setting != "self-contact")
    assert on.status == off.status == "converged" and on.self_contact_force_N == 0
    assert on.max_disp_mm == pytest.approx(off.max_disp_mm, rel=1e-6)
    assert np.allclose(on.segments_mm, off.segments_mm, atol=1e-3)
    assert 'id="fold-section"' in page and (small_run / "results/report/fold_section.png").is_file()


def test_the_clinical_cases_are_solved_without_and_with_the_skin(small_run: Path) -> None:
    """fe_skin: homogeneous, the default skin, tests/config.yaml's extra ratio and thickness."""
    from fem.sweep import Case
    from studies.fe_study.skin import SkinStudy

    results = small_run / "results"
    study = SkinStudy.read(results / "fe_study/skin.json")
    assert [s.name for s in study.settings] == ["homogeneous", "skin", "ratio 7",
                                                "thickness 2.5 mm"]
    assert (results / "benchmarks/fe_study/skin.tsv").is_file()
    page = (results / "report/index.html").read_text()
    section = section_html(page, "skin")
    clinical = yaml.safe_load((REPO / "tests/config.yaml").read_text())["clinical"]
    for item in clinical:
        cid = Case(item["C1"], item["phi"]).id
        rows = html_table(section, f"skin-{cid}")
        assert "<td>homogeneous</td><td>none</td><td>none</td><td>converged</td>" in rows
        assert "<td>skin</td><td>18.5</td><td>1.5</td><td>converged</td>" in rows
        # the membrane, 18.5 times stiffer than the fat, holds the breast: it sags less
        assert study.case("skin", cid).max_disp_mm < study.case("homogeneous", cid).max_disp_mm
    # the small config's clinical cases pair no prone with a supine case of one C1
    assert not study.paths and "there is no way to follow" in section
    assert (results / "report/skin.png").is_file()


@pytest.mark.parametrize(
    "change", [{"solver": "direct-refactor"}, {"discretisation": {"quadrature_degree": 3}}]
)
def test_the_default_discretisation_does_not_rerun_the_study_variants(
    small_run: Path, tmp_path: Path, change: dict
) -> None:
    """Changing the default's discretisation re-solves the sweep and the clinical benchmark only.

    The reference and the speed-accuracy variants set their own element, quadrature and solver.
    """
    config = yaml.safe_load((REPO / "tests" / "config.yaml").read_text())
    fe = config.setdefault("fe", {})
    for key, value in change.items():
        fe[key] = {**fe.get(key, {}), **value} if isinstance(value, dict) else value
    path = tmp_path / "config.yaml"
    path.write_text(yaml.safe_dump(config))
    run = snakemake(small_run, "-n", "-j2", config=path)
    assert run.returncode == 0, run.stderr[-3000:]
    counts = job_counts(run.stdout + run.stderr)
    assert counts["solve_chain"] == len(config["sweep"]["phi_deg"])
    assert counts["fe_clinical"] == counts["fe_convergence_map"] == 1
    assert "fe_variant" not in counts and "fe_reference" not in counts
