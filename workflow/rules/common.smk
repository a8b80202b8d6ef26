# The configuration, validated and parsed once (run.config.WorkflowConfig), the wildcard
# constraints, and the small helpers that derive targets, so that the rule files hold rules only.
import re
from collections import namedtuple

from snakemake.exceptions import WorkflowError

from fem.adaptive import RoundPlan
from fem.sweep import (ANGLE_PATTERN, C1_PATTERN, CASE_WILDCARDS, DIRECTION_WILDCARDS, case_folder,
                       case_id)
from run.config import ConfigError, WorkflowConfig
from run.workdir import age_refused
from studies.fe_study.fe_variants import MESH_ID_PATTERN, FE_VARIANT_ID_PATTERN, FEVariant

# Every job's software under --use-conda (the env file says how it relates to `make setup`).
ENV = "../envs/fenicsx-jax.yaml"

try:
    CONFIG = WorkflowConfig.from_mapping(config, workflow.source_path("../schemas/config.schema.yaml"))
except ConfigError as err:
    # `--config sweep={chains: false}` hands the workflow 'false', a string: Snakemake reads the
    # values inside a mapping with YAML's BaseLoader, which types nothing
    hint = ("; if it was given with --config inside a mapping (sweep={chains: false}), Snakemake "
            "passed it on as text: set it in a file given with --configfile instead"
            if re.search(r"'[^']*' is not of type '(boolean|number|integer)'", str(err)) else "")
    raise WorkflowError(f"invalid configuration: {err}{hint}") from None
# `config` itself becomes the validated mapping (defaults filled, keys sorted), so that anything
# that still reads it agrees with CONFIG; the rules take their params from CONFIG.
config.clear()
config.update(CONFIG.section())


# A case's folder: the sweep's under results/cases, the others' (extrapolation, off the grid)
# under results/outside; its name is fem.sweep.Case.id, with wildcards in the rules' patterns.
CASES_ROOT = "results/cases"
OUTSIDE_ROOT = "results/outside"
CASE_DIR = case_folder(CASES_ROOT)
OUTSIDE_DIR = case_folder(OUTSIDE_ROOT)
MESH = "results/mesh/mesh.xdmf"
DATASET = "results/dataset/dataset.h5"
MODEL = "results/surrogate/model/model.json"
# A model is its card and its arrays: every rule that loads a model takes both, so that after
# its params.npz changed (replaced, or damaged) the model is loaded again, or refused by name.
MODEL_ARRAYS = "results/surrogate/model/params.npz"
REPORT = "results/report/index.html"
FIRST_REPORT = "results/report/first/index.html"
VIEWER = "results/viewer/index.html"


wildcard_constraints:
    c1=C1_PATTERN,
    phi=ANGLE_PATTERN,
    theta=ANGLE_PATTERN,


# The adaptive sweep (sweep.adaptive, fem.adaptive): the start design is CONFIG.cases; each
# round's cases are known once the checkpoint `sweep_round` (sweep.smk) has planned it from the
# cases before it, so the files of the whole sweep are an input function that walks the rounds.
ADAPTIVE = CONFIG.adaptive
SWEEP_ROUND = "results/sweep/round_{round}.json"
SWEEP_ROUNDS_JSON = "results/sweep/rounds.json"
SWEEP_ESTIMATE_JSON = "results/sweep/estimate.json"


def sweep_cases_through(last=None):
    """The sweep's cases through round ``last`` (0: the start design; None: through the round
    that ended the sweep), and the number of the last round read."""
    cases, k = list(CONFIG.cases), 0
    while last is None or k < last:
        k += 1
        plan = RoundPlan.read(checkpoints.sweep_round.get(round=str(k)).output[0])
        if plan.done:
            break
        cases += plan.new_cases()
    return cases, k


def sweep_rounds(wildcards=None):
    """Every round's plan file, through the one that ended the sweep (an input function's
    list: asking for it runs the rounds)."""
    return [SWEEP_ROUND.format(round=j) for j in range(1, sweep_cases_through()[1] + 1)]


def case_file(case, name, root=CASES_ROOT):
    """Path of file ``name`` in the folder of ``case`` (a fem.sweep.Case) under ``root``."""
    return f"{case_folder(root, case)}/{name}"


def case_files(name):
    """Path of file ``name`` in every case folder of the sweep (with sweep.adaptive, an input
    function over every round's cases)."""
    if ADAPTIVE is None:
        return [case_file(case, name) for case in CONFIG.cases]

    def every_round(wildcards):
        return [case_file(case, name) for case in sweep_cases_through()[0]]

    return every_round


# A chain job's cases: every C1 of the sweep at one direction (solve.smk). Its one wildcard,
# {direction} = "phi=<deg>_theta=<deg>" (fem.sweep.direction_id), matches the sweep's directions only (as pairs: a sphere's
# Phi and theta values combine into directions it lacks), so a case at another direction is
# solved alone. With sweep.adaptive it matches any direction: the rounds' directions are not
# known when the workflow is read, and each is solved as a chain of the sweep's C1 values.
ChainRule = namedtuple("ChainRule", "name c1s direction")


def _chain_rules():
    c1s = sorted({f"{case.C1:.2f}" for case in CONFIG.cases}, key=float)
    if ADAPTIVE is not None:
        any_direction = DIRECTION_WILDCARDS.format(phi=ANGLE_PATTERN, theta=ANGLE_PATTERN)
        return [ChainRule("solve_chain", c1s, any_direction)]
    directions = sorted({case.direction_id for case in CONFIG.cases})
    return [ChainRule("solve_chain", c1s, "|".join(map(re.escape, directions)))]


CHAIN_RULES = _chain_rules()


def chain_files(name, c1s):
    """File ``name`` of every case of one direction's chain ({direction} left open)."""
    return [f"{CASES_ROOT}/{case_id(c1, '{direction}')}/{name}" for c1 in c1s]


def all_cores():
    """Every core of a local run, so that a timed job has the machine to itself.

    A cluster run sets no total (each job gets its own node share): 2 there.
    """
    try:
        return workflow.cores
    except WorkflowError:
        return 2


# -- FE study (fe_study.smk) ---------------------------------------------------------------
FE_STUDY_DIR = "results/fe_study"
FE_CLINICAL_JSON = f"{FE_STUDY_DIR}/fe_clinical.json"
FE_SPEED_ACCURACY_JSON = f"{FE_STUDY_DIR}/speed_accuracy.json"
FE_CONVERGENCE_MAP_JSON = f"{FE_STUDY_DIR}/convergence_map.json"
FE_FAILURE_EDGES_JSON = f"{FE_STUDY_DIR}/failure_edges.json"
FE_STABILITY_AUDIT_JSON = f"{FE_STUDY_DIR}/stability_audit.json"
FE_FOLD_SECTION_JSON = f"{FE_STUDY_DIR}/fold_section.json"
FE_SKIN_JSON = f"{FE_STUDY_DIR}/skin.json"
FE_STUDY_RESULTS = [FE_CLINICAL_JSON, FE_SPEED_ACCURACY_JSON, FE_CONVERGENCE_MAP_JSON]
CORPUS_DIR = "results/corpus"
CORPUS_JSON = f"{CORPUS_DIR}/corpus.json"
CORPUS_ANATOMIES = CONFIG.section("corpus", "anatomies")
REFERENCE_ROUNDTRIP_JSON = "results/reference/roundtrip.json"
# With reference_state.imaged the mesh rule writes the imaged (loaded) shape, and the reference
# estimated from it is MESH, the geometry every later rule takes.
IMAGED = CONFIG.imaged
IMAGED_MESH = "results/mesh/imaged.xdmf"
BUILT_MESH = IMAGED_MESH if IMAGED is not None else MESH
REFERENCE_RECORD = "results/mesh/reference.json"
STIFFNESS_JSON = "results/stiffness/stiffness.json"
TRACKING = [f"results/tracking/{name}.csv" for name in (IMAGED.points if IMAGED else {})]
TRACKING_JSON = [f"results/tracking/{name}.json" for name in (IMAGED.points if IMAGED else {})]


def imaged_results():
    """What the imaged chain adds to `all` and the report: the reference's record, the
    tracked points, the stiffness (each where configured)."""
    if IMAGED is None:
        return []
    return [REFERENCE_RECORD, *TRACKING, *([STIFFNESS_JSON] if IMAGED.observation else [])]


def fe_study_mesh(spec):
    """Path of the study mesh with sizes ``spec`` (a MeshSpec)."""
    return f"{FE_STUDY_DIR}/meshes/{spec.id}/mesh.xdmf"


def fe_references(wildcards=None):
    """The reference displacement of every clinical case (input function: only a run that
    needs the FE study requires the `clinical` list to be non-empty)."""
    if not CONFIG.clinical:
        raise WorkflowError("invalid configuration: the FE study needs at least one case in `clinical`")
    return [f"{FE_STUDY_DIR}/reference/{case.id}.h5" for case in CONFIG.clinical]


def fe_variant_mesh(wildcards):
    """The study mesh of the variant in ``wildcards``."""
    return fe_study_mesh(FEVariant.from_id(wildcards.fe_variant).mesh)


# -- surrogate study (surrogate.smk) --------------------------------------------------------
SURROGATE_DIR = "results/surrogate"
STUDY_DIR = f"{SURROGATE_DIR}/study"
STUDY_TABLE = f"{STUDY_DIR}/table2.json"
STUDY_REPEATS = f"{STUDY_DIR}/repeats.json"
ABLATION_DIR = f"{SURROGATE_DIR}/ablations"
MODEL_BY_CASE = f"{SURROGATE_DIR}/model_by_case/model.json"
MODEL_BY_CASE_ARRAYS = f"{SURROGATE_DIR}/model_by_case/params.npz"
CLINICAL_JSON = f"{SURROGATE_DIR}/clinical.json"
EXTRAPOLATION_JSON = f"{SURROGATE_DIR}/extrapolation.json"
ABLATIONS_JSON = f"{SURROGATE_DIR}/ablations.json"
SURROGATE_BENCHMARK_JSON = f"{SURROGATE_DIR}/surrogate_benchmark.json"
HELD_OUT_JSON = f"{SURROGATE_DIR}/held_out.json"
POSTURES_JSON = f"{SURROGATE_DIR}/postures.json"
OFF_GRID_JSON = f"{SURROGATE_DIR}/off_grid.json"
WARNING_COVERAGE_JSON = f"{SURROGATE_DIR}/warning_coverage.json"


def clinical_ids():
    """Case folder names of the clinical cases."""
    return [case.id for case in CONFIG.clinical]


def first_study_runs(name="model.json"):
    """File ``name`` of every architecture's first run."""
    return expand(f"{STUDY_DIR}/{{arch}}/r0/{name}", arch=CONFIG.surrogate_study.architectures)


def study_runs(name="model.json"):
    """File ``name`` of every run of the architecture study.

    Every repeat of every architecture; with ``repeat_within``, an input function giving the
    runs that the checkpoint ``study_repeats`` planned from the first runs.
    """
    study = CONFIG.surrogate_study
    if study.repeat_within is None:
        return expand(f"{STUDY_DIR}/{{arch}}/r{{repeat}}/{name}", arch=study.architectures,
                      repeat=range(study.repeats))

    def planned(wildcards):
        # imported here: the study's module loads JAX, which planning a run never needs
        from studies.surrogate_study.architecture import RepeatPlan

        plan = RepeatPlan.read(checkpoints.study_repeats.get().output[0])
        return plan.folders(STUDY_DIR, name)

    return planned


def ablation_runs(name="model.json"):
    """File ``name`` of every run of every ablation."""
    study = CONFIG.surrogate_study
    return expand(f"{ABLATION_DIR}/{{ablation}}/r{{repeat}}/{name}",
                  ablation=[a.name for a in study.ablations], repeat=range(study.repeats))


def ablation_settings(wildcards):
    """Settings of one ablation (its architecture comes from the study's selection)."""
    return CONFIG.surrogate_study.ablation(wildcards.ablation).settings.as_dict()


def posture_files(name):
    """File ``name`` of every posture's FE case: the sweep's where it has it, else outside."""
    return [f"results/{posture.folder}/{name}" for posture in CONFIG.surrogate_study.postures]


def extrapolation_files(name):
    """File ``name`` of every extrapolation case outside the sweep."""
    return [case_file(case, name, OUTSIDE_ROOT) for case in CONFIG.surrogate_study.extrapolation]


def off_grid_files(name):
    """File ``name`` of every random test case off the sweep's grid (solved outside it)."""
    return [case_file(case, name, OUTSIDE_ROOT) for case in CONFIG.surrogate_study.off_grid]


def held_out_models(name="model.json"):
    """File ``name`` of the model of every held-out split the sweep can form."""
    return [f"{SURROGATE_DIR}/model_{split}/{name}" for split in CONFIG.held_out_splits]


def clinical_fields():
    """The surrogate's field files of every clinical case, by split."""
    return expand(f"{SURROGATE_DIR}/clinical/{{split}}/{{case}}.{{ext}}",
                  split=["by_sample", "by_case"], case=clinical_ids(), ext=["xdmf", "h5"])


SURROGATE_RESULTS = [STUDY_TABLE, ABLATIONS_JSON, CLINICAL_JSON, EXTRAPOLATION_JSON, SURROGATE_BENCHMARK_JSON,
                     HELD_OUT_JSON, POSTURES_JSON, OFF_GRID_JSON, WARNING_COVERAGE_JSON]
