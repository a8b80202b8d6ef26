# Configuration validation, wildcard constraints and the helpers that derive targets.
import jsonschema
import yaml
from snakemake.exceptions import WorkflowError
from snakemake.utils import validate

from fem.parameters import SolverSettings
from fem.exceptions import FEError
from fem.sweep import ANGLE_PATTERN, C1_PATTERN, sweep_cases
from meshes.parametric import BreastGeometry, GeometryError

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
