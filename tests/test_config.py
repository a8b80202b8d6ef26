"""The configuration parsed once (run.config); the schema's bounds and the dataclasses' agree.

No FE solve and no workflow run: these are unit checks.
"""

from __future__ import annotations

import copy
import math
import re
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
import yaml

from fem.adaptive import AdaptiveSettings
from fem.contact import Contact, Plane
from fem.exceptions import InvalidParameterError
from fem.parameters import Discretisation, Gravity, Loading, Material, SolverSettings
from fem.sweep import Case, sample_phi, sweep_cases
from meshes.config import SOURCES, MeshConfig
from meshes.exceptions import GeometryError
from meshes.parametric import BreastGeometry
from meshes.schema import SCHEMA_PATH, load_schema
from meshes.sizing import MeshSize
from run.config import ConfigError, WorkflowConfig, canonical, read_config_file, validated
from studies.fe_study.fe_variants import ELEMENTS as STUDY_ELEMENTS
from studies.fe_study.fe_variants import FEVariant, MeshSpec
from studies.surrogate_study.config import SurrogateStudyConfig
from surrogate.config import SurrogateConfig, SurrogateConfigError
from tests.conftest import REPO

pytestmark = pytest.mark.unit

SCHEMA = load_schema()


def read(name: str) -> dict[str, Any]:
    return yaml.safe_load((REPO / name).read_text())


# -- the typed object -----------------------------------------------------------------------


def test_the_default_config_parses_into_every_layer() -> None:
    raw = read("config.yaml")
    config = WorkflowConfig.from_mapping(raw)
    # the adaptive sweep: the cases known before any solve are its start design
    assert config.adaptive is not None and config.adaptive.start == config.cases
    assert config.adaptive.settings == AdaptiveSettings.from_mapping(raw["sweep"]["adaptive"])
    assert len(config.cases) == len(raw["sweep"]["C1_kPa"]) * (
        len(sample_phi(raw["sweep"]["phi_deg"])) + raw["sweep"]["sphere"]["n"])
    assert config.cases == tuple(sorted(config.cases))
    assert [case.id for case in config.clinical] == [
        "c1=1.00_phi=180.0_theta=0.0", "c1=5.00_phi=180.0_theta=0.0",
        "c1=1.00_phi=0.0_theta=0.0", "c1=5.00_phi=0.0_theta=0.0"]
    assert isinstance(config.mesh, MeshConfig) and config.mesh.size.order == 2
    assert config.solver.discretisation.element == "taylor-hood" and config.solver.contact
    assert config.surrogate.activation == "silu"  # the file's, not the dataclass default
    study = config.surrogate_study
    assert study.architectures[0] == "2x32" and len(study.architectures) == 9
    assert {v.name for v in study.ablations} == {"paper_protocol", "vector_output", "separable",
                                                "pointwise"}
    # three extrapolation blocks: 6 x 2 + 2 x 6 + 2 x 1 cases, none of them in the start design
    assert len(study.extrapolation) == 26 and not set(study.extrapolation) & set(config.cases)
    assert config.fe_study.reference.element == "p2p1"
    assert config.fe_study.reference.mesh == MeshSpec(0.008, 0.0053, 2, 0.0025)
    assert len(config.fe_study.variants) == len({v.id for v in config.fe_study.variants})


def test_the_default_variant_is_the_workflows_own_discretisation() -> None:
    config = WorkflowConfig.from_mapping(read("tests/config.yaml"))
    default = config.fe_study.default_variant
    assert default == FEVariant(MeshSpec(0.03, 0.02, 1, None), "p2p1", "direct", 0)
    raw = read("tests/config.yaml")
    raw["fe"]["discretisation"] = {"element": "p1-penalty", "quadrature_degree": 3}
    raw["fe"]["solver"] = "iterative"
    other = WorkflowConfig.from_mapping(raw).fe_study.default_variant
    assert (other.element, other.solver, other.quadrature_degree) == ("p1-penalty", "iterative", 3)


def test_extrapolation_skips_the_cases_of_the_sweep() -> None:
    raw = read("tests/config.yaml")
    # C1 = 1 and 5 at Phi = 180 are sweep cases; 0.8 and 6 are not
    raw["surrogate_study"]["extrapolation"] = [{"C1_kPa": [0.8, 1.0, 5.0, 6.0], "phi_deg": [180.0]}]
    extra = WorkflowConfig.from_mapping(raw).surrogate_study.extrapolation
    assert extra == (Case(0.8, 180.0), Case(6.0, 180.0))


def test_the_off_grid_set_is_drawn_within_the_sweep_and_off_its_grid() -> None:
    raw = read("config.yaml")
    config = WorkflowConfig.from_mapping(raw)
    cases = config.surrogate_study.off_grid
    assert len(cases) == raw["surrogate_study"]["off_grid"]["n"]
    assert not set(cases) & set(config.cases)
    c1s = [c.C1 for c in config.cases]
    assert all(min(c1s) <= c.C1 <= max(c1s) for c in cases)
    assert any(c.C1 < 1.2 for c in cases)  # the soft end is drawn
    raw["surrogate_study"]["off_grid"] = {"n": 5, "seed": 2, "C1_kPa": [1.0, 1.5]}
    again = WorkflowConfig.from_mapping(raw).surrogate_study.off_grid
    assert len(again) == 5 and all(1.0 <= c.C1 <= 1.5 for c in again)
    raw["surrogate_study"]["off_grid"] = {"n": 0}
    assert WorkflowConfig.from_mapping(raw).surrogate_study.off_grid == ()
    raw["surrogate_study"]["off_grid"] = {"n": 3, "C1_kPa": [2.0, 1.0]}
    with pytest.raises(ConfigError, match="surrogate_study.off_grid.*0 < low <= high"):
        WorkflowConfig.from_mapping(raw)


def test_the_failure_edges_are_typed_and_their_resolution_checked() -> None:
    raw = read("config.yaml")
    edges = WorkflowConfig.from_mapping(raw).fe_study.failure_edges
    assert (edges.n, edges.step_deg, edges.resolution_deg) == (2, 1.0, 0.05)
    raw["fe_study"]["failure_edges"] = {"n": 1, "step_deg": 0.5, "resolution_deg": 1.0}
    with pytest.raises(ConfigError, match=r"fe_study\.failure_edges.*at most step_deg \(0\.5\)"):
        WorkflowConfig.from_mapping(raw)


def test_the_stability_audit_names_how_many_c1_values() -> None:
    raw = read("config.yaml")
    assert WorkflowConfig.from_mapping(raw).fe_study.stability_audit.softest == 2
    del raw["fe_study"]["stability_audit"]
    assert WorkflowConfig.from_mapping(raw).fe_study.stability_audit.softest == 2
    raw["fe_study"]["stability_audit"] = {"softest": -1}
    with pytest.raises(ConfigError, match="softest"):
        WorkflowConfig.from_mapping(raw)


@pytest.mark.parametrize(("text", "message"), [
    (None, "cannot read the config file"),
    ("fe: {solver: [direct\n", "YAML syntax error at line 2, column 1"),
    ("", "the config file is empty"),
    ("[1, 2]", "a config file is a mapping of sections .* holds list"),
])
def test_the_commands_name_a_config_file_they_cannot_use(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], text: str | None, message: str
) -> None:
    """Each command stops on it by name, writing nothing.

    ``fem.cli``, ``fem.chain``, ``fem.reference``, ``meshes.preview`` and ``meshes.frame``: the
    same reader as the workflow's (``run.config.read_config_file`` wraps it).
    """
    from fem.chain import main as chain
    from fem.cli import main as one_case
    from fem.reference import main as reference
    from meshes.frame import main as frame
    from meshes.preview import main as preview

    config = tmp_path / "my.yaml"
    if text is not None:
        config.write_text(text)
    out = tmp_path / "out"
    case = ["no_mesh.xdmf", "--c1", "1", "--phi", "180", "--config", str(config)]
    for main, args in ((one_case, [*case, "--out", str(out)]),
                       (chain, [*case, "--cases", str(out)]),
                       (reference, [*case, "--out", str(out)]),
                       (preview, [str(config), "--png", str(out)]),
                       (frame, [str(config), "points.csv", str(out), "--to", "project"])):
        assert main(args) == 2
        err = capsys.readouterr().err
        assert re.search(f"^error: {re.escape(str(config))}: {message}", err), err
    assert not out.exists()
    with pytest.raises(ConfigError, match=message):
        read_config_file(config)


def test_the_mesh_commands_name_a_config_file_without_a_mesh_section(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``meshes.preview`` and ``meshes.frame`` need the ``mesh`` section; they say so."""
    from meshes.frame import main as frame
    from meshes.preview import main as preview

    config = tmp_path / "my.yaml"
    config.write_text("sweep: {C1_kPa: [1.0]}\n")
    assert preview([str(config)]) == 2
    assert frame([str(config), "points.csv", str(tmp_path / "out.csv"), "--to", "file"]) == 2
    err = capsys.readouterr().err.splitlines()
    assert err == [f"error: {config}: the config file has no mesh section"] * 2, err


def test_ablations_override_the_surrogate_settings() -> None:
    raw = read("config.yaml")
    config = WorkflowConfig.from_mapping(raw)
    protocol = config.surrogate_study.ablation("paper_protocol")
    assert protocol.overrides["activation"] == "tanh" and protocol.settings.activation == "tanh"
    assert protocol.settings.max_epochs == 200 and protocol.settings.width == config.surrogate.width
    paper_optimiser = dict(learning_rate=0.01, beta1=0.5, beta2=0.9)
    assert protocol.settings.replace(activation="silu", c1_encoding="inverse",
                                     output_scaling="compliance", output_form="gravity_linear",
                                     structure="pod", lr_schedule="cosine", learning_rate=0.003,
                                     beta1=0.9, beta2=0.999,
                                     max_epochs=config.surrogate.max_epochs,
                                     patience=config.surrogate.patience) == config.surrogate
    assert protocol.settings.patience == 20  # the paper's early stopping, at its constant rate
    vector = config.surrogate_study.ablation("vector_output").settings
    assert vector == config.surrogate.replace(output_form="vector")
    for structure in ("separable", "pointwise"):
        settings = config.surrogate_study.ablation(structure).settings
        assert settings == config.surrogate.replace(structure=structure, max_epochs=100,
                                                    **paper_optimiser)
    assert config.held_out_splits == ("by_case", "by_direction", "by_c1")
    for split in config.held_out_splits:
        held_out = config.surrogate_held_out(split)
        assert held_out.split == split and held_out.replace(split="by_sample") == config.surrogate
    # tests/config.yaml: two C1 values cannot hold one out between the softest and stiffest
    small = WorkflowConfig.from_mapping(read("tests/config.yaml"))
    assert small.held_out_splits == ("by_case", "by_direction")
    with pytest.raises(KeyError, match="forms no 'by_c1' split"):
        small.surrogate_held_out("by_c1")
    with pytest.raises(KeyError, match="no 'nope'"):
        config.surrogate_study.ablation("nope")


def test_postures_come_from_the_sweep_where_it_has_them() -> None:
    config = WorkflowConfig.from_mapping(read("config.yaml"))
    postures = config.surrogate_study.postures
    directions = config.section("surrogate_study", "postures", "directions")
    assert len(postures) == 2 * len(directions)  # every posture at C1 = 1 and 5 kPa
    by_name = {(p.name, p.case.C1): p for p in postures}
    assert by_name[("prone", 1.0)].in_sweep and by_name[("prone", 1.0)].folder.startswith("cases/")
    standing = by_name[("standing", 5.0)]
    assert standing.case == Case(5.0, 90.0, -90.0) and not standing.in_sweep
    assert standing.folder == f"outside/{standing.case.id}" and "mammogram" in standing.note
    raw = read("config.yaml")
    raw["surrogate_study"]["postures"]["directions"].append({"name": "prone", "phi": 170.0})
    with pytest.raises(ConfigError, match="postures names 'prone' twice"):
        WorkflowConfig.from_mapping(raw)


def test_the_solve_jobs_get_the_chest_obstacle_written_out() -> None:
    raw = read("tests/config.yaml")
    config = WorkflowConfig.from_mapping(raw)
    obstacle = config.solve_fe["contact"]["obstacle"]
    assert set(obstacle) == {"elliptic_cylinder"}
    assert config.solver.contact is not None
    assert config.solver.contact.obstacle.as_mapping() == obstacle
    # without contact the solve jobs get `fe` itself
    del raw["fe"]["contact"]
    config = WorkflowConfig.from_mapping(raw)
    assert config.solve_fe == config.section("fe") and config.solver.contact is None


def test_a_job_builds_the_solver_settings_of_the_config_from_its_params() -> None:
    """A solve job's one call makes the config's solver settings of its rule's params.

    With and without contact, for each config file.
    """
    from types import SimpleNamespace

    from run.config import solver_settings

    for raw in (read("config.yaml"), read("tests/config.yaml")):
        for contact in (True, False):
            if not contact:
                raw["fe"].pop("contact", None)
            config = WorkflowConfig.from_mapping(raw)
            params = config.solver_params
            assert set(params) == {"fe", "material", "fixed"}
            assert params["fe"] == config.solve_fe
            assert solver_settings(SimpleNamespace(**params)) == config.solver


def test_the_dataset_section_parses_into_its_split_and_seed() -> None:
    from fem.splits import DatasetSplit, SplitFractions

    raw = read("tests/config.yaml")
    raw["dataset"] = {"seed": 3, "split": {"train": 0.6, "validation": 0.2, "test": 0.2}}
    split = DatasetSplit(SplitFractions(0.6, 0.2, 0.2), 3)
    assert WorkflowConfig.from_mapping(raw).dataset == split
    del raw["dataset"]
    assert WorkflowConfig.from_mapping(raw).dataset == DatasetSplit(SplitFractions(), 0)


def test_defaults_are_filled_as_snakemake_fills_them() -> None:
    """The rules' params come from this mapping.

    It must equal what Snakemake's own `validate` made of the config before, or every job of an
    existing run would rerun.
    """
    from snakemake.utils import validate as snakemake_validate

    for name in ("config.yaml", "tests/config.yaml"):
        raw = read(name)
        theirs = copy.deepcopy(raw)
        snakemake_validate(theirs, schema=str(SCHEMA_PATH))
        ours = validated(raw)
        assert repr(ours) == repr(canonical(theirs))
        assert ours["surrogate"]["boundary"] == "network"  # a default, absent from both files


def test_key_order_does_not_change_the_params() -> None:
    raw = read("config.yaml")
    reordered = {key: raw[key] for key in reversed(list(raw))}
    reordered["mesh"] = {key: raw["mesh"][key] for key in reversed(list(raw["mesh"]))}
    a, b = WorkflowConfig.from_mapping(raw), WorkflowConfig.from_mapping(reordered)
    assert repr(a.sections) == repr(b.sections)
    assert repr(a.solve_fe) == repr(b.solve_fe)
    assert list(a.sections) == sorted(a.sections)


def test_the_input_is_not_modified_and_sections_are_copies() -> None:
    raw = read("tests/config.yaml")
    before = copy.deepcopy(raw)
    config = WorkflowConfig.from_mapping(raw)
    assert raw == before and "material" not in raw and config.sections["material"]["density"] == 900
    fixed = config.section("mesh", "fixed")
    fixed["rib"] = "none"
    assert config.section("mesh", "fixed") == {"rib": "all"}
    assert list(config.sections_of("mesh", "fe")) == ["mesh", "fe"]


# -- errors name their key --------------------------------------------------------------------


def test_every_schema_violation_is_listed_by_key() -> None:
    raw = read("tests/config.yaml")
    raw["material"] = {"density": -1.0}
    raw["surrogate"]["width"] = 0
    raw["sweep"]["C1_kPa"] = [1.0, -2.0]
    with pytest.raises(ConfigError) as caught:
        WorkflowConfig.from_mapping(raw)
    # the bad item of a list is named by its index, not the whole list
    assert [p.split(":")[0] for p in caught.value.problems] == [
        "material.density", "surrogate.width", "sweep.C1_kPa.1"]
    assert caught.value.problems[2] == (
        "sweep.C1_kPa.1: -2.0 is less than or equal to the minimum of 0")
    assert str(caught.value).startswith("3 problems:\n  material.density: -1.0 is less")
    # a whole section missing: the file was written as if it were merged with config.yaml
    with pytest.raises(ConfigError) as caught:
        WorkflowConfig.from_mapping({"mesh": raw["mesh"]})
    assert "<top level>: 'sweep' is a required property (a config file stands alone" in str(
        caught.value)


@pytest.mark.parametrize(
    "change, message",
    [
        ({"mesh": {"geometry": {"mound_radius_cranial": 0.11}}},
         "mesh.geometry: the mound reaches the cranial or caudal cut"),
        ({"mesh": {"geometry": {"axilla_angle": 40.0}}},
         "mesh.geometry.mound_angle must lie strictly between 0"),
        ({"mesh": {"size": {"mound_size": 0.05}}}, "mesh.size.mound_size (0.05) must not exceed"),
        ({"fe": {"loading": {"initial_step": 0.1, "min_step": 0.5}}},
         "fe.loading.min_step must lie in (0, initial_step]"),
        ({"fe_study": {"reference": {"mesh": {"global_size": 0.01, "mound_size": 0.02}}}},
         "fe_study.reference: need 0 < mound_size <= global_size"),
        ({"fe_study": {"convergence_map": {"mesh": {"global_size": 0.01, "mound_size": 0.02}}}},
         "fe_study.convergence_map.mesh: need 0 < mound_size <= global_size"),
        # found at start, not in aggregation after every solve
        ({"dataset": {"split": {"train": 0.9, "validation": 0.9, "test": 0.1}}},
         "dataset.split: split fractions must add up to 1, got 1.9"),
        # values that one case folder's name would merge are refused, not silently merged
        ({"sweep": {"C1_kPa": [1.0, 1.001, 5.0]}},
         "sweep.C1_kPa: 1.0 and 1.001 share one case folder"),
        ({"sweep": {"phi_deg": [0.0, 0.04, 180.0]}},
         "sweep gravity directions (phi, theta): (0.0, 0.0) and (0.04, 0.0) share one"),
        # an adaptive sweep's budget must hold its start design (2 C1 values x 3 directions)
        ({"sweep": {"adaptive": {"max_cases": 5}}},
         "sweep.adaptive.max_cases = 5 is fewer than the start design's 6 cases"),
        # the hand-listed directions the adaptive rounds replaced are refused, not ignored
        ({"sweep": {"refine": {"C1_max": 1.2, "directions": [[81.0, -82.5]]}}},
         "sweep.refine: removed: the adaptive sweep (sweep.adaptive)"),
        # a sweep too large to plan is refused before it is expanded
        ({"sweep": {"C1_kPa": {"start": 0.8, "stop": 5.0, "step": 1e-5}}},
         "sweep.C1_kPa: 0.8 to 5 in steps of 1e-05 is 420001 values, more than 10000"),
        ({"sweep": {"C1_kPa": {"start": 0.01, "stop": 99.99, "step": 0.01},
                    "phi_deg": [0.0, 30.0, 60.0, 90.0, 120.0, 150.0]}},
         "sweep: 9999 C1 values x 6 gravity directions is 59994 cases, more than 50000"),
        # PETSc options: only those the solver reads, of the right kind, and none that write
        ({"fe": {"petsc_options": {"snes_max_it": "lots"}}},
         "fe.petsc_options.snes_max_it must be an integer, got 'lots'"),
        ({"fe": {"petsc_options": {"snes_maxit_typo": 1}}},
         "fe.petsc_options.snes_maxit_typo is not an option the solver reads"),
        ({"fe": {"petsc_options": {"snes_view": "ascii:/tmp/anywhere"}}},
         "fe.petsc_options.snes_view: options that make PETSc write"),
        ({"fe": {"petsc_options": {"ksp_monitor": True}}},
         "fe.petsc_options.ksp_monitor: options that make PETSc write"),
        ({"fe": {"petsc_options": {"pc_type": "ascii:/tmp/anywhere"}}},
         "fe.petsc_options.pc_type must be a PETSc type name"),
    ],
)
def test_an_inconsistent_section_is_named(change: dict, message: str) -> None:
    raw = read("tests/config.yaml")
    for section, values in change.items():
        for key, value in values.items():
            raw.setdefault(section, {})[key] = value
    with pytest.raises(ConfigError) as caught:
        WorkflowConfig.from_mapping(raw)
    assert str(caught.value).startswith(message), str(caught.value)


@pytest.mark.parametrize(
    ("section", "key", "value", "words"),
    [
        ("fe_study", "stability", {}, "fe_study.stability: renamed fe_study.convergence_map"),
        ("surrogate_study", "variants", {}, "surrogate_study.variants: renamed "
                                            "surrogate_study.ablations"),
        ("sweep", "refine", [], "sweep.refine: removed: the adaptive sweep"),
    ],
)
def test_a_key_of_an_earlier_version_is_told_its_new_name(
    section: str, key: str, value: object, words: str
) -> None:
    raw = read("tests/config.yaml")
    raw[section][key] = value
    with pytest.raises(ConfigError) as caught:
        WorkflowConfig.from_mapping(raw)
    assert words in str(caught.value), str(caught.value)


def test_an_imported_mesh_needs_an_explicit_obstacle() -> None:
    raw = read("tests/config.yaml")
    raw["mesh"]["source"] = "file"
    raw["mesh"]["file"] = {"path": "box.stl", "surfaces": {"rib": {"group": "rib"}}}
    raw["fe"]["contact"] = {"obstacle": "chest"}
    with pytest.raises(ConfigError, match=r"^fe\.contact\.obstacle 'chest' is the parametric"):
        WorkflowConfig.from_mapping(raw)


def test_an_architecture_listed_twice_is_refused() -> None:
    settings = SurrogateConfig()
    study = {"architectures": ["2x32", "2X32"], "repeats": 1, "ablations": {}, "extrapolation": [],
             "timing_repeats": 10, "prediction_budget_ms": None}
    with pytest.raises(ConfigError, match="surrogate_study.architectures lists one twice"):
        SurrogateStudyConfig.from_sections(study, settings, ())
    study["architectures"] = ["2x32", "3x16"]
    assert SurrogateStudyConfig.from_sections(study, settings, ()).architectures == ("2x32", "3x16")


def test_an_ablation_with_a_bad_override_is_named() -> None:
    study = {"architectures": ["2x32"], "repeats": 1, "ablations": {"wide": {"alpha": -1.0}},
             "extrapolation": [], "timing_repeats": 10, "prediction_budget_ms": None}
    # named by the ablation's own key, not the surrogate section's
    with pytest.raises(ConfigError, match=r"^surrogate_study\.ablations\.wide\.alpha must be >= 0"):
        SurrogateStudyConfig.from_sections(study, SurrogateConfig(), ())


# -- the schema and the dataclasses agree on the bounds they both state -------------------------


def schema_node(pointer: str) -> dict[str, Any]:
    """The schema at ``pointer`` (e.g. ``properties/surrogate/properties/width``).

    A ``$ref`` is resolved; the node's own keys win over the target's.
    """
    node: Any = SCHEMA
    for part in pointer.split("/"):
        node = node[int(part)] if isinstance(node, list) else node[part]
    if "$ref" in node:
        target = schema_node(node["$ref"].removeprefix("#/"))
        node = {**target, **{k: v for k, v in node.items() if k != "$ref"}}
    return node


def outside_and_inside(node: dict[str, Any], keyword: str) -> tuple[Any, Any]:
    """A value just outside the schema's ``keyword`` bound and one just inside it."""
    bound = node[keyword]
    integer = node.get("type") == "integer"
    step = 1 if integer else 1e-9 * max(1.0, abs(bound))
    return {
        "minimum": (bound - step, bound),
        "exclusiveMinimum": (bound, bound + step),
        "maximum": (bound + step, bound),
        "exclusiveMaximum": (bound, bound - step),
    }[keyword]


def surrogate(name: str) -> Callable[[Any], Any]:
    return lambda value: SurrogateConfig(**{name: value})


def loading(name: str) -> Callable[[Any], Any]:
    if name == "initial_step":  # min_step must not exceed it
        return lambda value: Loading(initial_step=value, min_step=min(value, Loading().min_step))
    return lambda value: Loading(**{name: value})


# A tiny mound fits on the narrowest and widest chest patch the schema allows.
SMALL_MOUND = {"mound_radius_lateral": 0.004, "mound_radius_cranial": 0.004, "mound_length": 0.01,
               "mound_offset": 0.0, "fold_radius": 0.0}


def geometry(name: str) -> Callable[[Any], Any]:
    if name == "axilla_angle":
        return lambda value: BreastGeometry(
            axilla_angle=value, mound_angle=value / 2, **SMALL_MOUND)
    return lambda value: BreastGeometry(**{name: value})


SURROGATE = "properties/surrogate/properties"
LOADING = "properties/fe/properties/loading/properties"
DISC = "properties/fe/properties/discretisation/properties"
GEOMETRY = "properties/mesh/properties/geometry/properties"
CONTACT = "properties/fe/properties/contact/properties"
PLANE = Plane((0.0, 0.0, 0.0), (1.0, 0.0, 0.0))

# (schema node, bound keywords the dataclass repeats, build from a value, its error).
# Bounds the schema states and the dataclass does not (e.g. surrogate.width <= 4096, the mesh
# sizes' minima) are the schema's alone: only it refuses them, before any object is built.
REPEATED: list[tuple[str, tuple[str, ...], Callable[[Any], Any], type[Exception]]] = [
    *[(f"{SURROGATE}/{name}", ("minimum",), surrogate(name), SurrogateConfigError)
      for name in ("hidden_layers", "width", "batch_size", "max_epochs", "patience", "seed",
                   "alpha")],
    (f"{SURROGATE}/learning_rate", ("exclusiveMinimum",), surrogate("learning_rate"),
     SurrogateConfigError),
    *[(f"{SURROGATE}/{name}", ("exclusiveMinimum", "maximum"), surrogate(name),
       SurrogateConfigError) for name in ("bc_length", "lr_final")],
    *[(f"{SURROGATE}/{name}", ("minimum", "exclusiveMaximum"), surrogate(name),
       SurrogateConfigError) for name in ("beta1", "beta2")],
    ("properties/material/properties/density", ("exclusiveMinimum",),
     lambda value: Material(C1=1000.0, density=value), InvalidParameterError),
    ("properties/material/properties/gravity", ("minimum",),
     lambda value: Gravity(0.0, magnitude=value), InvalidParameterError),
    ("properties/sweep/properties/C1_kPa/oneOf/0/items", ("exclusiveMinimum",),
     lambda value: Case(value, 0.0), InvalidParameterError),
    ("properties/clinical/items/properties/C1", ("exclusiveMinimum",),
     lambda value: Case(value, 0.0), InvalidParameterError),
    (f"{LOADING}/initial_step", ("exclusiveMinimum", "maximum"), loading("initial_step"),
     InvalidParameterError),
    (f"{LOADING}/min_step", ("exclusiveMinimum", "maximum"), loading("min_step"),
     InvalidParameterError),
    (f"{LOADING}/rescue_min_step", ("exclusiveMinimum", "maximum"), loading("rescue_min_step"),
     InvalidParameterError),
    (f"{LOADING}/max_steps", ("minimum",), loading("max_steps"), InvalidParameterError),
    (f"{LOADING}/growth", ("minimum",), loading("growth"), InvalidParameterError),
    (f"{LOADING}/cutback", ("exclusiveMinimum", "exclusiveMaximum"), loading("cutback"),
     InvalidParameterError),
    (f"{LOADING}/fixed_steps", ("minimum",), loading("fixed_steps"), InvalidParameterError),
    (f"{DISC}/quadrature_degree", ("minimum",),
     lambda value: Discretisation(quadrature_degree=value), InvalidParameterError),
    (f"{DISC}/bulk_ratio", ("exclusiveMinimum",), lambda value: Discretisation(bulk_ratio=value),
     InvalidParameterError),
    (f"{CONTACT}/stiffness", ("exclusiveMinimum",),
     lambda value: Contact(PLANE, stiffness=value), InvalidParameterError),
    (f"{CONTACT}/clearance", ("minimum",), lambda value: Contact(PLANE, clearance=value),
     InvalidParameterError),
    ("properties/mesh/properties/size/properties/grading", ("exclusiveMinimum",),
     lambda value: MeshSize(grading=value), GeometryError),
    (f"{GEOMETRY}/axilla_angle", ("minimum", "maximum"), geometry("axilla_angle"), GeometryError),
    *[(f"{GEOMETRY}/{name}", ("minimum",), geometry(name), GeometryError)
      for name in ("mound_offset", "fold_radius")],
    (f"{GEOMETRY}/layer_thickness", ("exclusiveMinimum",), geometry("layer_thickness"),
     GeometryError),
]

# Positive lengths whose smallest positive values the geometry refuses for other reasons (the
# mound or the layer no longer fits): here only the refusal at the bound is the dataclass's own.
REFUSED_AT_BOUND = [
    (f"{GEOMETRY}/{name}", "exclusiveMinimum", geometry(name), GeometryError)
    for name in ("rib_depth", "rib_half_width", "mound_length", "mound_radius_lateral",
                 "mound_radius_cranial", "mound_angle")
]


@pytest.mark.parametrize(
    "pointer, keyword, build, error",
    [(p, k, b, e) for p, keywords, b, e in REPEATED for k in keywords],
    ids=[f"{p.split('/')[-1]}-{k}" for p, keywords, _, _ in REPEATED for k in keywords],
)
def test_a_dataclass_refuses_just_outside_and_accepts_just_inside_the_schemas_bound(
    pointer: str, keyword: str, build: Callable[[Any], Any], error: type[Exception]
) -> None:
    node = schema_node(pointer)
    assert keyword in node, f"the schema no longer bounds {pointer} by {keyword}"
    outside, inside = outside_and_inside(node, keyword)
    name = {"items": "C1"}.get(pointer.split("/")[-1], pointer.split("/")[-1])
    with pytest.raises(error, match=name):
        build(outside)
    build(inside)


@pytest.mark.parametrize("pointer, keyword, build, error", REFUSED_AT_BOUND,
                         ids=[p.split("/")[-1] for p, *_ in REFUSED_AT_BOUND])
def test_a_geometry_length_is_refused_at_the_schemas_bound(
    pointer: str, keyword: str, build: Callable[[Any], Any], error: type[Exception]
) -> None:
    node = schema_node(pointer)
    outside, _ = outside_and_inside(node, keyword)
    name = pointer.split("/")[-1]
    with pytest.raises(error, match=name):
        build(outside)


ENUMS: list[tuple[str, Callable[[Any], Any], type[Exception]]] = [
    *[(f"{SURROGATE}/{name}", surrogate(name), SurrogateConfigError)
      for name in ("activation", "boundary", "c1_encoding", "output_scaling", "output_form",
                   "structure", "lr_schedule", "split")],
    ("properties/fe/properties/solver", lambda value: SolverSettings(solver=value),
     InvalidParameterError),
    ("properties/fe/properties/petsc_options/properties/snes_linesearch_type",
     lambda value: SolverSettings(petsc_options={"snes_linesearch_type": value}),
     InvalidParameterError),
    (f"{DISC}/element", lambda value: Discretisation(element=value), InvalidParameterError),
    (f"{DISC}/degree", lambda value: Discretisation(degree=value), InvalidParameterError),
    ("properties/mesh/properties/size/properties/order", lambda value: MeshSize(order=value),
     GeometryError),
    ("definitions/study_mesh/properties/order", lambda value: MeshSpec(0.02, 0.01, value),
     InvalidParameterError),
    ("definitions/study_element",
     lambda value: FEVariant(MeshSpec(0.02, 0.01), element=value), InvalidParameterError),
    ("definitions/study_solver",
     lambda value: FEVariant(MeshSpec(0.02, 0.01), solver=value).settings(SolverSettings()),
     InvalidParameterError),
    ("properties/sweep/properties/phi_deg/oneOf/1/properties/sampling",
     lambda value: sample_phi({"sampling": value}), InvalidParameterError),
]


@pytest.mark.parametrize("pointer, build, error", ENUMS,
                         ids=[p.split("/")[-1] for p, *_ in ENUMS])
def test_a_dataclass_accepts_exactly_the_schemas_choices(
    pointer: str, build: Callable[[Any], Any], error: type[Exception]
) -> None:
    choices = schema_node(pointer)["enum"]
    for choice in choices:
        build(choice)
    outside = max(choices) + 1 if all(isinstance(c, int) for c in choices) else "not-a-choice"
    with pytest.raises(error):
        build(outside)


def test_the_choices_named_in_code_are_the_schemas() -> None:
    assert tuple(schema_node("properties/mesh/properties/source")["enum"]) == SOURCES
    assert set(schema_node("definitions/study_element")["enum"]) == set(STUDY_ELEMENTS)


def test_the_schema_bounds_are_finite_numbers() -> None:
    """A bound of the table above must be a number the probes can step past."""
    for pointer, keywords, _, _ in REPEATED:
        node = schema_node(pointer)
        for keyword in keywords:
            assert isinstance(node[keyword], (int, float)) and math.isfinite(node[keyword])


def test_sweep_cases_of_the_typed_config_are_the_sweeps() -> None:
    raw = read("tests/config.yaml")
    config = WorkflowConfig.from_mapping(raw)
    assert config.cases == tuple(sweep_cases(raw["sweep"])) and config.adaptive is None
    raw["sweep"]["adaptive"] = {"max_cases": 12}  # the schema fills the other settings
    config = WorkflowConfig.from_mapping(raw)
    assert config.adaptive is not None and config.adaptive.start == config.cases
    assert config.adaptive.settings == AdaptiveSettings(max_cases=12)
    assert config.section("sweep", "adaptive")["per_round"] == AdaptiveSettings().per_round


def test_the_conda_route_pins_the_versions_of_make_setup() -> None:
    """The --use-conda environment names the versions that `make setup` installs.

    workflow/envs/fenicsx-jax.yaml against requirements.lock, constraints.txt and the Debian
    FEniCSx stack this suite runs on.
    """
    import dolfinx
    import mpi4py
    import petsc4py

    env = yaml.safe_load((REPO / "workflow/envs/fenicsx-jax.yaml").read_text())
    conda = dict(d.split("=")[:2] for d in env["dependencies"] if isinstance(d, str) and "=" in d)
    pip = dict(p.split("==") for p in next(d["pip"] for d in env["dependencies"]
                                           if isinstance(d, dict)))
    pins = {}
    for name in ("requirements.lock", "constraints.txt"):
        for line in (REPO / name).read_text().splitlines():
            if "==" in line and not line.startswith("#"):
                package, version = line.split("==")
                pins[package.lower()] = version.strip()
    for package, version in pip.items():
        assert pins[package.lower()] == version, package
    for package in ("numpy", "scipy", "h5py"):
        assert conda[package] == pins[package], package
    assert conda["fenics-dolfinx"] == dolfinx.__version__
    assert conda["mpi4py"] == mpi4py.__version__
    assert petsc4py.__version__.startswith(conda["petsc4py"] + ".")
    assert conda["python"] == "{}.{}".format(*sys.version_info[:2])


def test_the_imaged_chain_parses_and_needs_its_imaged_posture() -> None:
    raw = read("tests/config.yaml")
    assert WorkflowConfig.from_mapping(raw).imaged is None  # the mesh is stress-free
    raw["reference_state"] = {
        "imaged": {"C1_kPa": 1.5, "phi": 180.0},
        "points": {"tumour": {"file": "tumour.csv", "phi": 0.0, "theta": 30.0}},
        "observation": {"file": "scan.csv", "phi": 0.0},
    }
    imaged = WorkflowConfig.from_mapping(raw).imaged
    assert imaged.case == Case(1.5, 180.0) and imaged.points["tumour"] == Case(1.5, 0.0, 30.0)
    assert imaged.input_files() == ["tumour.csv", "scan.csv"]
    del raw["reference_state"]["imaged"]
    with pytest.raises(ConfigError, match=r"reference_state.points needs reference_state.imaged"):
        WorkflowConfig.from_mapping(raw)


def test_the_model_used_downstream_is_refitted_unless_told_not_to() -> None:
    raw = read("config.yaml")
    assert raw["surrogate_study"]["refit"] is True
    assert WorkflowConfig.from_mapping(raw).surrogate_study.refit
    del raw["surrogate_study"]["refit"]  # the schema's default
    assert WorkflowConfig.from_mapping(raw).surrogate_study.refit
    raw["surrogate_study"]["refit"] = False
    assert not WorkflowConfig.from_mapping(raw).surrogate_study.refit
    raw["surrogate_study"]["refit"] = "yes"
    with pytest.raises(ConfigError, match="refit"):
        WorkflowConfig.from_mapping(raw)


@pytest.mark.parametrize("where", [("dataset", "split", "train"),
                                   ("surrogate_study", "prediction_budget_ms"),
                                   ("fe_study", "failure_edges", "step_deg")])
@pytest.mark.parametrize("value", [math.nan, math.inf])
def test_a_number_that_is_not_finite_is_refused_by_its_key(where: tuple[str, ...],
                                                           value: float) -> None:
    """NaN passes every bound of the schema (a comparison with it is never false)."""
    raw = read("tests/config.yaml")
    section = raw
    for key in where[:-1]:
        section = section.setdefault(key, {})
    section[where[-1]] = value
    with pytest.raises(ConfigError, match=re.escape(f"{'.'.join(where)}: {value} is not a "
                                                    "finite number")):
        WorkflowConfig.from_mapping(raw)


def test_the_fold_section_names_its_cases() -> None:
    raw = read("config.yaml")
    fold = WorkflowConfig.from_mapping(raw).fe_study.fold_section
    assert fold.cases == ((0.8, -90.0, 0.0),) and fold.largest == 1
    raw["fe_study"]["fold_section"] = {"cases": [[0.0, 10.0]]}
    with pytest.raises(ConfigError, match=r"fe_study\.fold_section.*C1 > 0"):
        WorkflowConfig.from_mapping(raw)


def test_the_command_line_bounds_are_the_configs() -> None:
    from fem.arguments import ANGLE_DEG

    angle = SCHEMA["definitions"]["angle"]
    assert (angle["minimum"], angle["maximum"]) == ANGLE_DEG


@pytest.mark.parametrize(("command", "args", "words"), [
    ("fem.cli", ["m.xdmf", "--c1", "1", "--phi", "1e300", "--out", "o"],
     "argument --phi: 1e300 is not an angle from -180 to 360 degrees"),
    ("fem.cli", ["m.xdmf", "--c1", "nan", "--phi", "0", "--out", "o"],
     "argument --c1: 'nan' is not a finite number"),
    ("fem.cli", ["m.xdmf", "--c1", "1", "--phi", "0", "--out", "{file}"],
     "argument --out: {file} is a file, not a folder to write into"),
    ("fem.reference", ["m.xdmf", "--c1", "1", "--phi", "0", "--out", "o", "--tolerance-mm", "0"],
     "argument --tolerance-mm: 0 is not above zero"),
    ("fem.reference", ["m.xdmf", "--c1", "-1", "--phi", "0", "--out", "o"],
     "argument --c1: C1 = -1 kPa is not above 0 and at most 1000 kPa"),
    ("surrogate.cli", ["predict", "m", "--c1", "1", "--phi", "0", "--from-phi", "inf"],
     "argument --from-phi: 'inf' is not a finite number"),
    ("studies.reference_state.stiffness", ["obs.xdmf", "--model", "m", "--phi", "1000"],
     "argument --phi: 1000 is not an angle from -180 to 360 degrees"),
    ("studies.reference_state.tracking", ["p.csv", "--imaged", "i", "--reference", "r", "--model",
        "m",
                          "--c1", "1", "--phi", "0", "--out", "{folder}"],
     "argument --out: {folder} is a folder, not a file to write"),
])
def test_the_commands_refuse_a_bad_value_before_any_work(
    command: str, args: list[str], words: str, tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    import importlib

    file = tmp_path / "a_file"
    file.write_text("")
    names = {"file": str(file), "folder": str(tmp_path)}
    main = importlib.import_module(command).main
    with pytest.raises(SystemExit) as stop:
        main([a.format(**names) for a in args])
    assert stop.value.code == 2
    assert words.format(**names) in capsys.readouterr().err


def test_a_sweep_too_small_for_the_splits_is_refused_naming_the_smallest_that_works() -> None:
    raw = read("tests/config.yaml")
    raw["sweep"] = {"C1_kPa": [1.0, 5.0], "phi_deg": [0.0, 180.0], "chains": False}
    with pytest.raises(ConfigError, match=r"sweep.*4 cases, 2 of them clinical .* needs at least "
                       r"3 other cases .* give the sweep at least 5 cases"):
        WorkflowConfig.from_mapping(raw)
    raw["sweep"]["phi_deg"] = [0.0, 90.0, 180.0]
    assert len(WorkflowConfig.from_mapping(raw).cases) == 6
