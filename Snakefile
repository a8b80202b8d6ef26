# Breast biomechanics under gravity: mesh -> FE sweep -> HDF5 dataset -> surrogate -> report.
# Wiring only: the stages live in workflow/rules, the config is parsed once by run/config.py,
# the science is in meshes/, fem/, surrogate/ and studies/.
from snakemake.exceptions import WorkflowError
from snakemake.utils import min_version

min_version("9.0")


# First: a run refused by the working directory's run lock writes nothing there.
include: "workflow/rules/workdir.smk"


# config.yaml is the study; a --configfile replaces it rather than being merged into it, so that
# a config such as tests/config.yaml stands alone. A syntax error is reported with its line.
if not workflow.overwrite_configfiles:
    from run.config import ConfigError, read_config_file

    try:
        read_config_file("config.yaml")
    except ConfigError as err:
        raise WorkflowError(str(err)) from None

    configfile: "config.yaml"


include: "workflow/rules/common.smk"
include: "workflow/rules/mesh.smk"
include: "workflow/rules/solve.smk"
include: "workflow/rules/sweep.smk"
include: "workflow/rules/fe_study.smk"
include: "workflow/rules/corpus.smk"
include: "workflow/rules/reference.smk"
include: "workflow/rules/aggregate.smk"
include: "workflow/rules/surrogate.smk"
include: "workflow/rules/report.smk"


rule all:
    default_target: True
    input:
        FIRST_REPORT,
        REPORT,
        SURROGATE_RESULTS,
        imaged_results(),
