# Configuration validation, wildcard constraints and the helpers that derive targets
# (of the sweep, the FE study and the surrogate study), so that the rule files hold rules only.
import jsonschema
import yaml
from snakemake.exceptions import WorkflowError
from snakemake.utils import validate

from fem.sweep import clinical_cases
from studies.fe_variants import MESH_ID_PATTERN, VARIANT_ID_PATTERN, MeshSpec, Variant, expand_variants
from fem.contact import resolve_obstacle
from fem.exceptions import FEError
from fem.parameters import SolverSettings
from fem.sweep import ANGLE_PATTERN, C1_PATTERN, sweep_cases
from meshes.parametric import BreastGeometry, GeometryError
from surrogate.config import SurrogateConfig, SurrogateConfigError, parse_architecture

SCHEMA = workflow.source_path("../schemas/config.schema.yaml")


def config_errors(config, schema_path):
    """Every schema violation as 'dotted.key: message', sorted by key."""
    with open(schema_path) as fh:
        schema = yaml.safe_load(fh)
    validator = jsonschema.Draft202012Validator(schema)
    errors = sorted(validator.iter_errors(config), key=lambda e: [str(p) for p in e.absolute_path])
    return [f"{'.'.join(map(str, e.absolute_path)) or '<top level>'}: {e.message}" for e in errors]


def check_config(config):
    """Stop before any job if the config is out of bounds or inconsistent."""
    problems = config_errors(config, SCHEMA)
    if problems:
        raise WorkflowError("invalid configuration:\n  " + "\n  ".join(problems))
    validate(config, schema=SCHEMA)  # fills defaults
    try:
        BreastGeometry.from_mapping(config["mesh"].get("geometry", {}))
        SolverSettings.from_config(config)
        sweep_cases(config["sweep"])
    except (GeometryError, FEError, ValueError) as err:
        raise WorkflowError(f"invalid configuration: {err}") from None


def canonical(value):
    """``value`` with every mapping's keys sorted, recursively.

    Snakemake compares a rule's params with the last run's by their text, in which a
    mapping's key order shows; sorting makes two configs that differ only in key order
    (a file rewritten by a tool, keys moved by hand) the same experiment.
    """
    if isinstance(value, dict):
        return {key: canonical(value[key]) for key in sorted(value)}
    if isinstance(value, list):
        return [canonical(item) for item in value]
    return value


check_config(config)
_canonical = canonical(config)
config.clear()
config.update(_canonical)

CASES = sweep_cases(config["sweep"])
# The solve jobs' FE settings, a `chest` contact obstacle written out from mesh.geometry:
# the jobs need no mesh section, and without contact these are config["fe"] itself.
FE_SOLVE = resolve_obstacle(config["fe"], config["mesh"])
CASE_DIR = "results/cases/c1={c1}_phi={phi}_theta={theta}"
OUTSIDE_DIR = "results/outside/c1={c1}_phi={phi}_theta={theta}"
MESH = "results/mesh/mesh.xdmf"
DATASET = "results/dataset/dataset.h5"
MODEL = "results/surrogate/model/model.json"
REPORT = "results/report/index.html"


wildcard_constraints:
    c1=C1_PATTERN,
    phi=ANGLE_PATTERN,
    theta=ANGLE_PATTERN,


def case_files(name):
    """Path of file ``name`` in every case folder of the sweep."""
    return [f"results/cases/{case.id}/{name}" for case in CASES]


def all_cores():
    """Every core of a local run, so that a timed job has the machine to itself.

    A cluster run sets no total (each job gets its own node share): 2 there.
    """
    try:
        return workflow.cores
    except WorkflowError:
        return 2


# -- FE study (fe_study.smk) ---------------------------------------------------------------
FE_STUDY = config["fe_study"]
FE_STUDY_DIR = "results/fe_study"
FE_CLINICAL_JSON = f"{FE_STUDY_DIR}/clinical.json"
FE_SPEED_ACCURACY_JSON = f"{FE_STUDY_DIR}/speed_accuracy.json"
FE_STABILITY_JSON = f"{FE_STUDY_DIR}/stability.json"
FE_STUDY_RESULTS = [FE_CLINICAL_JSON, FE_SPEED_ACCURACY_JSON, FE_STABILITY_JSON]

try:
    FE_CLINICAL_CASES = clinical_cases(config["clinical"])
    FE_REFERENCE_MESH = MeshSpec.from_mapping(FE_STUDY["reference"]["mesh"])
    FE_VARIANTS = expand_variants(FE_STUDY["speed_accuracy"]["variants"])
    FE_STABILITY_MESH = MeshSpec.from_mapping(FE_STUDY["stability"]["mesh"])
    # what the reference and the variants depend on: not the default's discretisation
    FE_STUDY_BASE_CONFIG = Variant.base_config(config)
except (FEError, KeyError, TypeError, ValueError) as err:
    raise WorkflowError(f"invalid configuration: fe_study: {err}") from None


def fe_study_mesh(spec):
    """Path of the study mesh with sizes ``spec`` (a MeshSpec)."""
    return f"{FE_STUDY_DIR}/meshes/{spec.id}/mesh.xdmf"


def fe_references(wildcards=None):
    """The reference displacement of every clinical case (input function: only a run that
    needs the FE study requires the `clinical` list to be non-empty)."""
    if not FE_CLINICAL_CASES:
        raise WorkflowError("invalid configuration: the FE study needs at least one case in `clinical`")
    return [f"{FE_STUDY_DIR}/reference/{case.id}.h5" for case in FE_CLINICAL_CASES]


def fe_default_variant():
    """Id of the study variant that the workflow's own mesh and fe settings amount to."""
    size, disc = config["mesh"]["size"], config["fe"]["discretisation"]
    degree = disc["degree"]
    element = "p1-penalty" if disc["element"] == "p1-penalty" else f"p{degree}p{degree - 1}"
    spec = MeshSpec.from_mapping(size)
    return Variant(spec, element, config["fe"]["solver"], disc["quadrature_degree"]).id


def fe_variant_mesh(wildcards):
    """The study mesh of the variant in ``wildcards``."""
    return fe_study_mesh(Variant.from_id(wildcards.fe_variant).mesh)


# -- surrogate study (surrogate.smk) --------------------------------------------------------
STUDY = config["surrogate_study"]
SURROGATE_DIR = "results/surrogate"
STUDY_DIR = f"{SURROGATE_DIR}/study"
STUDY_TABLE = f"{STUDY_DIR}/table2.json"
VARIANT_DIR = f"{SURROGATE_DIR}/variants"
MODEL_BY_CASE = f"{SURROGATE_DIR}/model_by_case/model.json"
CLINICAL_JSON = f"{SURROGATE_DIR}/clinical.json"
EXTRAPOLATION_JSON = f"{SURROGATE_DIR}/extrapolation.json"
VARIANTS_JSON = f"{SURROGATE_DIR}/variants.json"
BENCHMARK_JSON = f"{SURROGATE_DIR}/benchmark.json"
MODEL_FILES = ("model.json", "params.npz", "history.json")


def surrogate_settings(overrides=None):
    """The `surrogate` section with a variant's overrides, checked (raises before any job)."""
    try:
        return SurrogateConfig.from_mapping({**config["surrogate"], **(overrides or {})})
    except SurrogateConfigError as err:
        raise WorkflowError(f"invalid configuration: {err}") from None


def check_surrogate_config():
    surrogate_settings()
    for name, overrides in STUDY["variants"].items():
        surrogate_settings(overrides)
    try:
        archs = [parse_architecture(a) for a in STUDY["architectures"]]
    except SurrogateConfigError as err:
        raise WorkflowError(f"invalid configuration: surrogate_study.architectures: {err}") from None
    if len(set(archs)) != len(archs):
        raise WorkflowError("invalid configuration: surrogate_study.architectures lists one twice")


check_surrogate_config()
ARCHITECTURES = ["{}x{}".format(*parse_architecture(a)) for a in STUDY["architectures"]]
REPEATS = list(range(STUDY["repeats"]))


def extrapolation_cases():
    """The extra FE cases of `surrogate_study.extrapolation` that are not in the sweep."""
    extra = set()
    for block in STUDY["extrapolation"]:
        extra.update(sweep_cases(block))
    return sorted(extra - set(CASES))


EXTRA_CASES = extrapolation_cases()


def clinical_ids():
    """Case folder names of the clinical cases (FE_CLINICAL_CASES, above)."""
    return [case.id for case in FE_CLINICAL_CASES]


def study_runs(name="model.json"):
    return expand(f"{STUDY_DIR}/{{arch}}/r{{repeat}}/{name}", arch=ARCHITECTURES, repeat=REPEATS)


def variant_runs(name="model.json"):
    return expand(f"{VARIANT_DIR}/{{variant}}/r{{repeat}}/{name}", variant=list(STUDY["variants"]),
                  repeat=REPEATS)


def variant_params(wildcards):
    """Settings of one variant (its architecture comes from the study's selection)."""
    return surrogate_settings(STUDY["variants"][wildcards.variant]).as_dict()


def clinical_fields():
    return expand(f"{SURROGATE_DIR}/clinical/{{split}}/{{case}}.{{ext}}",
                  split=["by_sample", "by_case"], case=clinical_ids(), ext=["xdmf", "h5"])


SURROGATE_RESULTS = [STUDY_TABLE, VARIANTS_JSON, CLINICAL_JSON, EXTRAPOLATION_JSON, BENCHMARK_JSON]
