"""Aggregation of case files into the HDF5 dataset, and its failure modes."""

from __future__ import annotations

import json
import os
import stat
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

from fem.aggregate import build_dataset
from fem.case_files import write_points
from fem.dataset import BOUNDARY, read_dataset
from fem.exceptions import DatasetError
from fem.splits import SplitFractions
from fem.sweep import Case

pytestmark = pytest.mark.unit

REPO = Path(__file__).resolve().parent.parent

N = 50


def _write_case(root: Path, C1: float, phi: float, status: str = "converged", n: int = N,
                rng: np.random.Generator | None = None, **extra: object) -> tuple[Path, Path]:
    """A case folder under ``root``, named as the workflow names it."""
    rng = rng or np.random.default_rng(0)
    folder = root / Case(C1, phi).id
    folder.mkdir(parents=True)
    X = np.linspace(0, 1, 3 * N).reshape(N, 3)[:n]
    fixed = np.arange(n) < 5
    u = np.where(fixed[:, None], 0.0, rng.normal(size=(n, 3)) * 1e-3 / C1)
    write_points(folder / "points.h5", np.arange(n), X, u, fixed, folder.name)
    summary = {
        "status": status,
        "reason": "converged" if status == "converged" else "diverged",
        "case": folder.name,
        "C1": C1,
        "phi": phi,
        "theta": 0.0,
        "gravity_vector": [9.81 * np.cos(np.radians(phi)), 9.81 * np.sin(np.radians(phi)), 0.0],
        "load_fraction": 1.0 if status == "converged" else 0.5,
        "load_steps": 1,
        "first_failure": "" if status == "converged" else "diverged_max_it",
        "min_detF": 0.9 if status == "converged" else 0.05,
        "newton_iterations": [5],
        "wall_s": {"solve": 1.0},
        "max_disp_mm": 1.0,
        "self_overlap": {"overlapping_vertices": 0},
        "contact": None,
        **extra,
    }
    (folder / "summary.json").write_text(json.dumps(summary))
    return folder / "summary.json", folder / "points.h5"


def _cases(
    tmp_path: Path, overrides: dict[int, dict] | None = None
) -> tuple[list[Path], list[Path]]:
    overrides = overrides or {}
    paths = [_write_case(tmp_path, 1.0 + i, 30.0 * i, **overrides.get(i, {})) for i in range(5)]
    return [p[0] for p in paths], [p[1] for p in paths]


def test_dataset_schema_and_contents(tmp_path: Path) -> None:
    contact = {
        "force_N": 0.25,
        "vertices": 392,
        "vertices_in_contact": 2,
        "max_penetration_mm": 0.1,
    }
    summaries, points = _cases(
        tmp_path,
        {
            3: {"status": "failed"},
            1: {"contact": contact, "self_contact": {"force_N": 0.31, "area_cm2": 6.7}},
            2: {"self_overlap": {"overlapping_vertices": 13}},
            4: {"self_overlap": None, "cpu_s": {"solve": 0.5},
                "clock": {"process_start": 1.7e9, "finished": 1.7e9 + 12.5},
                "start": {"from": "neighbours", "neighbours": ["c1=6.00_phi=120.0_theta=0.0"],
                          "fraction": 5 / 6}},
        },
    )  # None: solved under MPI
    info = build_dataset(
        summaries,
        points,
        tmp_path / "ds.h5",
        SplitFractions(),
        seed=1,
        config={"sweep": {"phi_deg": [0]}},
    )
    assert info["failed"] == ["c1=4.00_phi=90.0_theta=0.0"]
    with h5py.File(tmp_path / "ds.h5") as h5:
        assert h5["displacement"].shape == (5, N, 3)
        assert h5["displacement"].attrs["units"] == "m"
        assert h5["displacement"].compression == "gzip"
        assert np.all(np.isnan(h5["displacement"][3]))
        assert list(h5["cases/status"].asstr()[...]) == ["converged"] * 3 + ["failed", "converged"]
        assert list(h5["cases/first_failure"].asstr()[...]) == [""] * 3 + ["diverged_max_it", ""]
        assert list(h5["cases/min_detF"][...]) == [0.9] * 3 + [0.05, 0.9]
        assert list(h5["cases/self_overlap"][...]) == [0, 0, 13, 0, -1]
        # the solve's CPU time and where its load path started (a summary may lack both)
        assert np.isnan(h5["cases/cpu_s"][:4]).all() and h5["cases/cpu_s"][4] == 0.5
        assert list(h5["cases/start_fraction"][...]) == [0.0] * 4 + [5 / 6]
        # when the case's process started and the case ended (NaN: a summary without a clock)
        assert h5["cases/process_start_s"][4] == 1.7e9 and h5["cases/finished_s"][4] == 1.7e9 + 12.5
        assert np.isnan(h5["cases/process_start_s"][:4]).all()
        assert np.isnan(h5["cases/finished_s"][:4]).all()
        assert h5["cases/finished_s"].attrs["units"] == "s (Unix time)"
        force = h5["cases/contact_force_N"]
        assert force.attrs["units"] == "N"
        assert force[1] == 0.25 and np.isnan(np.delete(force[...], 1)).all()
        itself = h5["cases/self_contact_force_N"]
        assert itself.attrs["units"] == "N"
        assert itself[1] == 0.31 and np.isnan(np.delete(itself[...], 1)).all()
        assert np.sum(h5["points/kind"][...] == BOUNDARY) == 5
        prov = json.loads(h5.attrs["provenance"])
        assert prov["config"] == {"sweep": {"phi_deg": [0]}} and "packages" in prov
        by_sample = [h5[f"splits/by_sample/{k}"][...] for k in ("train", "validation", "test")]
        allidx = np.concatenate(by_sample)
        # the failed case and the converged one that passes through itself are in no split
        assert len(allidx) == len(np.unique(allidx)) == 3 * N
        assert not np.any(np.isin(allidx // N, [2, 3]))
        assert len(by_sample[0]) == pytest.approx(0.8 * 3 * N, abs=1)
        by_case = np.concatenate(
            [h5[f"splits/by_case/{k}"][...] for k in ("train", "validation", "test")]
        )
        assert sorted(by_case) == [0, 1, 4]
        assert not np.isnan(h5["displacement"][2]).any()  # kept, and flagged by self_overlap


def test_report_says_whether_the_sweep_had_contact() -> None:
    """The report's sweep sentence reads the dataset's contact column: NaN is no contact."""
    from report.sections.stability import sweep_contact_and_overlap as _sweep_contact_and_overlap

    columns = {
        "C1": np.array([0.8, 0.9, 5.0]),
        "phi": np.array([-90.0, -120.0, 180.0]),
        "self_overlap": np.array([2, 0, 0]),
    }
    failed = np.array([True, False, False])
    without = _sweep_contact_and_overlap({**columns, "contact_force_N": np.full(3, np.nan)}, failed)
    assert "solved without contact" in without
    assert "1 case ends passing through itself" in without
    assert "C1 = 0.8 kPa at Φ = -90° (2, failed)" in without
    assert "in no split" not in without  # the one that passes through itself failed
    converged = _sweep_contact_and_overlap(columns, np.zeros(3, dtype=bool))
    assert "holds none of them: the one that converged is in no split" in converged
    force = np.array([np.nan, 0.48, 0.0])  # the failed case has no force
    with_contact = _sweep_contact_and_overlap({**columns, "contact_force_N": force}, failed)
    assert "Solved with contact of the skin with the chest: 1 case ends in contact" in with_contact
    assert "the largest force 0.48 N (C1 = 0.9 kPa at Φ = -120°)" in with_contact
    assert "self-contact" not in with_contact  # an older dataset has no such column
    itself = _sweep_contact_and_overlap(
        {**columns, "self_contact_force_N": np.array([np.nan, 0.31, 0.0])}, failed)
    assert ("Solved with self-contact of the skin: 1 case ends with the skin resting on itself, "
            "the largest force 0.31 N (C1 = 0.9 kPa at Φ = -120°)") in itself
    off = _sweep_contact_and_overlap({**columns, "self_contact_force_N": np.full(3, np.nan)},
                                     failed)
    assert "solved without self-contact" in off


def test_mismatched_point_count_names_the_case(tmp_path: Path) -> None:
    summaries, points = _cases(tmp_path, {2: {"n": N - 1}})
    match = "case c1=3.00_phi=60.0_theta=0.0: .* 49 material points, expected 50"
    with pytest.raises(DatasetError, match=match):
        build_dataset(summaries, points, tmp_path / "ds.h5")
    assert not (tmp_path / "ds.h5").exists()


def test_a_converged_field_larger_than_the_body_is_refused(tmp_path: Path) -> None:
    summaries, points = _cases(tmp_path)
    with h5py.File(points[3], "a") as h5:
        h5["u"][7] = [1e30, 0.0, 0.0]
    match = ("case c1=4.00_phi=90.0_theta=0.0: .*points.h5 moves a point 1e\\+30 m, farther "
             "than the body's own size")
    with pytest.raises(DatasetError, match=match):
        build_dataset(summaries, points, tmp_path / "ds.h5")
    assert not (tmp_path / "ds.h5").exists()


def test_truncated_case_file_names_the_case(tmp_path: Path) -> None:
    summaries, points = _cases(tmp_path)
    data = points[1].read_bytes()
    points[1].write_bytes(data[: len(data) // 3])
    match = "c1=2.00_phi=30.0_theta=0.0/points.h5: unreadable or truncated"
    with pytest.raises(DatasetError, match=match):
        build_dataset(summaries, points, tmp_path / "ds.h5")


def test_missing_field_names_the_case(tmp_path: Path) -> None:
    summaries, points = _cases(tmp_path)
    with h5py.File(points[4], "a") as h5:
        del h5["u"]
    with pytest.raises(DatasetError, match="c1=5.00_phi=120.0_theta=0.0/points.h5: missing field"):
        build_dataset(summaries, points, tmp_path / "ds.h5")
    summary = json.loads(summaries[0].read_text())
    del summary["phi"]
    summaries[0].write_text(json.dumps(summary))
    match = "c1=1.00_phi=0.0_theta=0.0/summary.json: summary lacks phi"
    with pytest.raises(DatasetError, match=match):
        build_dataset(summaries, points, tmp_path / "ds.h5")


def test_existing_dataset_survives_a_failed_rebuild(tmp_path: Path) -> None:
    summaries, points = _cases(tmp_path)
    build_dataset(summaries, points, tmp_path / "ds.h5")
    before = (tmp_path / "ds.h5").read_bytes()
    points[0].write_bytes(b"garbage")
    with pytest.raises(DatasetError):
        build_dataset(summaries, points, tmp_path / "ds.h5")
    assert (tmp_path / "ds.h5").read_bytes() == before
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


def test_a_killed_build_leaves_nothing_behind_and_the_dataset_is_readable_by_all(
    tmp_path: Path,
) -> None:
    """The next build removes a killed build's temporary file; the dataset is mode 0644.

    mkstemp makes its file private (0600); the dataset gets the mode of every other output.
    """
    summaries, points = _cases(tmp_path)
    stale = tmp_path / ".ds.h5.abc123.tmp"
    stale.write_bytes(b"half a dataset")
    old = os.umask(0o022)
    try:
        build_dataset(summaries, points, tmp_path / "ds.h5")
    finally:
        os.umask(old)
    assert not stale.exists()
    assert stat.S_IMODE((tmp_path / "ds.h5").stat().st_mode) == 0o644


@pytest.mark.parametrize(
    "content, message",
    [
        (b"\xff\xfe\x00garbage", "unreadable or truncated summary"),
        (b"null", "a summary is a JSON object, this file holds NoneType"),
        (b"[1, 2]", "a summary is a JSON object, this file holds list"),
    ],
)
def test_a_summary_that_is_not_a_json_object_names_its_file(
    tmp_path: Path, content: bytes, message: str
) -> None:
    summaries, points = _cases(tmp_path)
    summaries[2].write_bytes(content)
    with pytest.raises(DatasetError, match=f"c1=3.00_phi=60.0_theta=0.0/summary.json: {message}"):
        build_dataset(summaries, points, tmp_path / "ds.h5")
    assert not (tmp_path / "ds.h5").exists()


@pytest.mark.parametrize(
    "field, value, message",
    [
        ("status", "ok", "unknown status 'ok'; a case is one of converged, failed"),
        ("C1", "1.0", r"summary field\(s\) C1 are not finite numbers \(C1='1.0'\)"),
        ("phi", None, r"summary field\(s\) phi are not finite numbers"),
        ("load_fraction", True, r"summary field\(s\) load_fraction are not finite numbers"),
        ("gravity_vector", [0.0, "x"], r"summary field\(s\) gravity_vector are not finite"),
    ],
)
def test_a_summary_with_a_bad_field_names_the_file_and_the_field(
    tmp_path: Path, field: str, value: object, message: str
) -> None:
    summaries, points = _cases(tmp_path)
    summary = json.loads(summaries[1].read_text())
    summary[field] = value
    summaries[1].write_text(json.dumps(summary))
    with pytest.raises(DatasetError, match=f"c1=2.00_phi=30.0_theta=0.0/summary.json: {message}"):
        build_dataset(summaries, points, tmp_path / "ds.h5")


def test_a_summary_of_another_case_than_its_folder_is_refused(tmp_path: Path) -> None:
    """A summary whose C1 or Φ is not its folder's would put one case in the dataset twice."""
    summaries, points = _cases(tmp_path)
    summary = json.loads(summaries[1].read_text())
    summaries[1].write_text(json.dumps({**summary, "C1": 7.0}))
    with pytest.raises(DatasetError, match="the summary is of case .* not of its folder "
                       "'c1=2.00_phi=30.0_theta=0.0'"):
        build_dataset(summaries, points, tmp_path / "ds.h5")
    summaries[1].write_text(json.dumps({**summary, "phi": 45.0}))
    with pytest.raises(DatasetError, match="not of its folder 'c1=2.00_phi=30.0_theta=0.0'") \
            as refused:
        build_dataset(summaries, points, tmp_path / "ds.h5")
    # a remedy that reruns whichever job made the file, a chain's as well as a case's
    assert f"snakemake {summaries[1]} --forcerun {summaries[1]}" in str(refused.value)


def test_a_folder_holding_another_cases_files_is_refused(tmp_path: Path) -> None:
    """Copying case 0's files over case 3's is found, by the summary and by the points file."""
    summaries, points = _cases(tmp_path)
    summaries[3].write_bytes(summaries[0].read_bytes())
    points[3].write_bytes(points[0].read_bytes())
    with pytest.raises(DatasetError, match="c1=4.00_phi=90.0_theta=0.0/summary.json: the summary "
                       "is of case 'c1=1.00_phi=0.0_theta=0.0'"):
        build_dataset(summaries, points, tmp_path / "ds.h5")
    summaries, points = _cases(tmp_path / "again")
    points[3].write_bytes(points[0].read_bytes())  # the summary is right, the field is not
    with pytest.raises(DatasetError, match="c1=4.00_phi=90.0_theta=0.0/points.h5: written for "
                       "case 'c1=1.00_phi=0.0_theta=0.0'"):
        build_dataset(summaries, points, tmp_path / "ds.h5")


def test_case_files_outside_a_case_folder_are_refused(tmp_path: Path) -> None:
    summaries, points = _cases(tmp_path)
    with pytest.raises(DatasetError, match="in different folders"):
        build_dataset(summaries, [points[1], *points[1:]], tmp_path / "ds.h5")
    odd = tmp_path / "not_a_case"
    odd.mkdir()
    for path in (summaries[0], points[0]):
        (odd / path.name).write_bytes(path.read_bytes())
    with pytest.raises(DatasetError, match="not_a_case: not a case folder"):
        build_dataset([odd / "summary.json"], [odd / "points.h5"], tmp_path / "ds.h5")


def test_group_splits_hold_out_whole_directions_and_whole_c1_values(tmp_path: Path) -> None:
    """by_direction and by_c1 partition whole groups; the softest and stiffest C1 train.

    Adding them left the by-sample split as it was (it draws from the seed's first stream).
    """
    c1s, phis = (1.0, 1.5, 2.0, 2.5, 3.0, 3.5), (0.0, 45.0, 90.0, 135.0, 180.0)
    paths = [_write_case(tmp_path, c1, phi) for c1 in c1s for phi in phis]
    paths.append(_write_case(tmp_path, 4.0, 45.0, status="failed"))
    summaries, points = [p[0] for p in paths], [p[1] for p in paths]
    build_dataset(summaries, points, tmp_path / "ds.h5", seed=3)
    from fem.dataset import read_dataset

    ds = read_dataset(tmp_path / "ds.h5")
    converged = np.flatnonzero(ds.converged)
    for split, key in (("by_direction", ds.phi), ("by_c1", ds.C1)):
        parts = ds.splits[split]
        assert sorted(np.concatenate(list(parts.values()))) == list(converged)
        groups = [set(key[parts[p]]) for p in ("train", "validation", "test")]
        assert all(groups[1:]) and not (groups[0] & groups[1] or groups[0] & groups[2]
                                        or groups[1] & groups[2])
        held = np.concatenate([parts["validation"], parts["test"]])
        assert len(ds.sample_indices(split, "test")) == len(parts["test"]) * N
    assert {1.0, 3.5} <= set(ds.C1[ds.splits["by_c1"]["train"]])
    # the softest value that may be held out is held out, whatever the draw
    assert set(ds.C1[ds.splits["by_c1"]["test"]]) >= {1.5}
    # the older splits draw from the seed's first stream, as before the group splits existed
    rng = np.random.default_rng(3)
    samples = (converged[:, None] * N + np.arange(N)[None, :]).ravel()
    expected = SplitFractions().partition(len(samples), rng)
    assert np.array_equal(ds.splits["by_sample"]["train"], samples[expected["train"]])
    assert len(held) > 0


def test_the_by_c1_split_always_tests_its_softest_free_value() -> None:
    """Whatever the seed, the second softest C1 is tested, and the draw still holds out others."""
    from fem.splits import group_partition, softest_held_out_c1

    c1 = np.repeat([0.8, 1.0, 1.2, 1.4, 1.6, 1.8, 2.0], 3)
    cases = np.arange(c1.size)
    assert softest_held_out_c1(c1) == (1.0,)
    assert softest_held_out_c1(c1[c1 < 1.5]) == ()  # 0.8-1.4: only two between the ends
    for seed in range(6):
        parts = group_partition(cases, c1, (0.8, 2.0), SplitFractions(0.6, 0.2, 0.2),
                                np.random.default_rng(seed), always_test=(1.0,))
        tested = set(c1[parts["test"]])
        assert 1.0 in tested and len(tested) >= 2
        assert {0.8, 2.0} <= set(c1[parts["train"]]) and 1.0 not in set(c1[parts["train"]])
        assert sorted(np.concatenate(list(parts.values()))) == list(cases)
    with pytest.raises(ValueError, match="cannot all be tested"):
        group_partition(cases, c1, (0.8, 2.0), SplitFractions(), np.random.default_rng(0),
                        always_test=(0.8,))


def test_a_sweep_with_too_few_groups_holds_none_out(tmp_path: Path) -> None:
    # one direction; three C1 values, of which the softest and stiffest always train
    paths = [_write_case(tmp_path, c1, 0.0) for c1 in (1.0, 2.0, 3.0)]
    build_dataset([p[0] for p in paths], [p[1] for p in paths], tmp_path / "three.h5")
    from fem.dataset import read_dataset

    ds = read_dataset(tmp_path / "three.h5")
    for split in ("by_direction", "by_c1"):
        assert list(ds.splits[split]["train"]) == [0, 1, 2]
        assert ds.splits[split]["validation"].size == ds.splits[split]["test"].size == 0


def test_a_dataset_without_the_group_splits_asks_for_a_rebuild(tmp_path: Path) -> None:
    summaries, points = _cases(tmp_path)
    build_dataset(summaries, points, tmp_path / "ds.h5")
    with h5py.File(tmp_path / "ds.h5", "a") as h5:
        del h5["splits/by_direction"]
    from fem.dataset import read_dataset

    with pytest.raises(DatasetError, match="lacks the split /splits/by_direction.*rebuild"):
        read_dataset(tmp_path / "ds.h5")


def test_the_clock_is_the_processes_start_not_the_imports() -> None:
    """A summary's ``process_start`` includes what a job pays before the library is imported."""
    before = time.time()
    script = ("import time; time.sleep(1.0); from fem.provenance import clock; "
              "import json; print(json.dumps(clock()))")
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                         check=True, cwd=REPO).stdout
    record = json.loads(out)
    after = time.time()
    # the kernel's start time has clock-tick resolution (10 ms); the import came a second later
    assert before - 0.05 <= record["process_start"] < before + 0.5
    assert record["process_start"] + 1.0 <= record["finished"] <= after


def test_cases_set_aside_leave_every_split_and_keep_the_others(tmp_path: Path) -> None:
    """A case whose FE state is no answer is set aside as a failed one; nothing else moves."""
    from fem.dataset import read_dataset
    from studies.fe_study.stability_audit import AuditedCase, StabilityAudit, without_unstable

    c1s, phis = (1.0, 1.5, 2.0, 2.5, 3.0), (0.0, 45.0, 90.0, 135.0, 180.0)
    paths = [_write_case(tmp_path, c1, phi) for c1 in c1s for phi in phis]
    build_dataset([p[0] for p in paths], [p[1] for p in paths], tmp_path / "ds.h5", seed=3)
    ds = read_dataset(tmp_path / "ds.h5")
    gone = ds.case_index(1.5, 45.0)
    aside = ds.without([str(ds.ids[gone])])
    assert not aside.converged[gone] and aside.converged.sum() == ds.converged.sum() - 1
    assert np.isnan(aside.displacement[gone]).all() and not np.isnan(ds.displacement[gone]).any()
    for kind, parts in ds.splits.items():
        for part, indices in parts.items():
            cases = indices // ds.n_points if kind == "by_sample" else indices
            assert np.array_equal(aside.splits[kind][part], indices[cases != gone]), (kind, part)
    assert ds.without([]) is ds
    with pytest.raises(DatasetError, match="no case c1=9"):
        ds.without(["c1=9.00_phi=0.0_theta=0.0"])
    audit = StabilityAudit(C1=[1.5], cases=[
        AuditedCase(str(ds.ids[gone]), 1.5, 45.0, 0.0, False),
        AuditedCase(str(ds.ids[ds.case_index(1.5, 90.0)]), 1.5, 90.0, 0.0, True)])
    audit.write(tmp_path / "audit.json")
    kept = without_unstable(ds, tmp_path / "audit.json")
    assert np.flatnonzero(~kept.converged).tolist() == [gone]


def test_the_dataset_records_the_tissue_map_and_refuses_two(tmp_path: Path) -> None:
    """The cases' tissue map is a root attribute; cases solved with two maps are refused."""
    tissues = {"fat": 1.0, "gland": 2.0, "skin": 18.5, "tumour": 5.0}
    same = {i: {"settings": {"tissues": tissues}} for i in range(5)}
    summaries, points = _cases(tmp_path / "same", same)
    build_dataset(summaries, points, tmp_path / "same.h5")
    assert read_dataset(tmp_path / "same.h5").tissues == tissues
    # cases without the setting (solved before tissues existed) are all fat
    summaries, points = _cases(tmp_path / "old")
    build_dataset(summaries, points, tmp_path / "old.h5")
    assert read_dataset(tmp_path / "old.h5").tissues == {"fat": 1.0}
    mixed = {**same, 3: {"settings": {"tissues": {**tissues, "gland": 3.0}}}}
    summaries, points = _cases(tmp_path / "mixed", mixed)
    with pytest.raises(DatasetError, match=r"solved with 2 different tissue maps"):
        build_dataset(summaries, points, tmp_path / "mixed.h5")
    assert not (tmp_path / "mixed.h5").exists()


def test_the_clinical_cases_are_held_out_as_test_by_their_case(tmp_path: Path) -> None:
    """The by-case split tests the clinical cases, cases the random split alone would not.

    They are matched as cases: each summary's numbers against the config's cases.
    """
    summaries, points = _cases(tmp_path)

    def tested(name: str, clinical: list[Case]) -> set[str]:
        build_dataset(summaries, points, tmp_path / name, test_cases=clinical)
        ds = read_dataset(tmp_path / name)
        return {str(ds.ids[i]) for i in ds.splits["by_case"]["test"]}

    alone = tested("none.h5", [])
    untested = [Case.from_id(c) for c in (Case(1.0 + i, 30.0 * i).id for i in range(5))
                if c not in alone]
    assert len(untested) >= 2
    assert {c.id for c in untested[:2]} <= tested("two.h5", untested[:2])
