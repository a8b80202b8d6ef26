"""The workflow's configuration, validated once against its schema and parsed into typed objects.

:meth:`WorkflowConfig.from_mapping` is the one place that reads ``config.yaml``: it checks the
mapping against ``workflow/schemas/config.schema.yaml`` (which also fills the defaults), sorts
every mapping's keys and builds the objects of every layer from it: the mesh
(:class:`meshes.config.MeshConfig`), the solve jobs' FE settings
(:class:`fem.parameters.SolverSettings`), the sweep and the clinical cases
(:mod:`fem.sweep`), the FE study (:mod:`studies.fe_study.config`) and the surrogate with its
study (:class:`surrogate.config.SurrogateConfig`, :mod:`studies.surrogate_study.config`). It
lives in ``run/`` because it spans every layer below; the schema and its check are
:mod:`meshes.schema`, the error that names a key :mod:`studies.config_errors`. A job rebuilds
what it needs from its rule's params with one call (:func:`solver_settings` for the solver).

The schema states every bound and default; the dataclasses check what they need to stay
valid on their own, and ``tests/test_config.py`` keeps the bounds they repeat in step with it.
Snakemake records a rule's ``params`` by their text, so the mappings the rules pass on come from
:meth:`WorkflowConfig.section`, the validated mapping itself, not rebuilt from the objects.
"""

from __future__ import annotations

import copy
import sys
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import jsonschema
import numpy as np
from jsonschema import validators

from fem.adaptive import AdaptiveDesign
from fem.configfile import ConfigFileError, check_expansion
from fem.configfile import read_config_file as fem_read_config_file
from fem.contact import resolve_obstacle
from fem.directions import direction_keys
from fem.parameters import SolverSettings
from fem.splits import DatasetSplit, SplitFractions
from fem.sweep import Case, clinical_cases, sweep_cases
from meshes.config import MeshConfig
from meshes.parametric import BreastGeometry
from meshes.schema import SCHEMA_PATH, load_schema, schema_errors
from studies.config_errors import ConfigError, config_section
from studies.fe_study.config import FEStudyConfig
from studies.surrogate_study.config import SurrogateStudyConfig
from surrogate.config import SurrogateConfig


def read_config_file(path: str | Path) -> dict[str, Any]:
    """A config file (YAML) as a mapping (:func:`fem.configfile.read_config_file`).

    Raises:
        ConfigError: for a file that cannot be read, is not YAML (with the line and column
            where the parser stopped), or does not hold a mapping of sections.
    """
    try:
        return fem_read_config_file(path)
    except ConfigFileError as err:
        raise ConfigError(str(err)) from None


def _with_defaults(validator_class: type) -> type:
    """``validator_class`` that also writes each property's ``default`` into the instance.

    The recipe of the jsonschema FAQ, as ``snakemake.utils.validate`` applies it, so that a
    config filled here equals one filled by Snakemake.
    """
    validate_properties = validator_class.VALIDATORS["properties"]

    def set_defaults(validator, properties, instance, schema):
        for name, subschema in properties.items():
            if "default" in subschema and isinstance(instance, dict):
                instance.setdefault(name, subschema["default"])
        yield from validate_properties(validator, properties, instance, schema)

    return validators.extend(validator_class, {"properties": set_defaults})


def canonical(value: Any) -> Any:
    """``value`` with every mapping's keys sorted, recursively.

    Snakemake compares a rule's params with the last run's by their text, in which a mapping's
    key order shows; sorting makes two configs that differ only in key order (a file rewritten
    by a tool, keys moved by hand) the same experiment.
    """
    if isinstance(value, dict):
        return {key: canonical(value[key]) for key in sorted(value)}
    if isinstance(value, list):
        return [canonical(item) for item in value]
    return value


def validated(config: Mapping[str, Any], schema_path: str | Path = SCHEMA_PATH) -> dict[str, Any]:
    """``config`` checked against the schema, with its defaults filled and its keys sorted.

    Raises:
        ConfigError: listing every violation, each as ``dotted.key: message``.
    """
    try:  # before anything walks it: an alias bomb walked never ends
        check_expansion(config, "the config")
    except ConfigFileError as err:
        raise ConfigError(str(err)) from None
    schema = load_schema(schema_path)
    problems = schema_errors(config, schema)
    if problems:
        raise ConfigError(*problems)
    filled = copy.deepcopy(dict(config))
    # the defaults filled in are the schema's own objects: this call's schema, used once
    _with_defaults(jsonschema.Draft202012Validator)(schema).validate(filled)
    return canonical(filled)


def check_sweep_splits(cases: tuple[Case, ...], clinical: tuple[Case, ...],
                       split: SplitFractions) -> None:
    """Refuse a sweep too small for the dataset's by-case split to fill its parts.

    The clinical cases always go to the test part; of the other cases the split needs one to
    train on, one to validate on and (with a test fraction) one more to test on.

    Raises:
        ValueError: naming how many cases there are, and the smallest sweep that works.
    """
    free = len(set(cases) - set(clinical))
    needed = 3 if split.test > 0 else 2
    if free < needed:
        raise ValueError(
            f"{len(cases)} cases, {len(cases) - free} of them clinical (held out as test): the "
            f"dataset's by-case split needs at least {needed} other cases (train, validation"
            f"{', test' if split.test > 0 else ''}); give the sweep at least "
            f"{needed + len(cases) - free} cases")


@dataclass(frozen=True, slots=True)
class ImagedConfig:
    """The mesh as an image of the loaded breast (``reference_state.imaged``) and what follows.

    Attributes:
        case: the imaged posture and the stiffness assumed for it.
        points: named points files and the case (C1 of ``case``) each is tracked to.
        point_files: the points files by name.
        observation: a second observation's file, or None.
        observed_in: its posture (C1 of ``case``), or None.
    """

    case: Case
    points: dict[str, Case]
    point_files: dict[str, str]
    observation: str | None
    observed_in: Case | None

    @classmethod
    def fromconfig_section(cls, section: Mapping[str, Any]) -> ImagedConfig | None:
        """Parse ``reference_state``; None when ``imaged`` is unset.

        Raises:
            ConfigError: for points or an observation without ``imaged``.
        """
        imaged = section.get("imaged")
        if imaged is None:
            extra = [k for k in ("points", "observation") if section.get(k)]
            if extra:
                raise ConfigError(
                    f"reference_state.{extra[0]} needs reference_state.imaged (the stiffness "
                    "and posture of the imaged mesh)"
                )
            return None
        c1 = float(imaged["C1_kPa"])
        case = Case(c1, imaged["phi"], imaged.get("theta", 0.0))
        points = {name: Case(c1, p["phi"], p.get("theta", 0.0))
                  for name, p in section.get("points", {}).items()}
        files = {name: str(p["file"]) for name, p in section.get("points", {}).items()}
        observation = section.get("observation")
        return cls(
            case, points, files,
            None if observation is None else str(observation["file"]),
            None if observation is None else Case(c1, observation["phi"],
                                                  observation.get("theta", 0.0)),
        )

    def posture(self) -> dict[str, Any]:
        """The imaged posture as the 3D view names a posture: movement is measured from it."""
        return {"name": "as imaged", "phi": self.case.phi, "theta": self.case.theta}

    def view_query(self) -> dict[str, float]:
        """Where the 3D view opens, so that the movement from the image shows at once.

        The first tracked set's target posture at the imaged C1, else the imaged posture.
        """
        case = next(iter(self.points.values()), self.case)
        return {"C1": case.C1, "phi": case.phi, "theta": case.theta}

    def input_files(self) -> list[str]:
        """The points and observation files (inputs of the workflow)."""
        return [*self.point_files.values(), *([self.observation] if self.observation else [])]


@dataclass(frozen=True, slots=True)
class WorkflowConfig:
    """The whole configuration of the workflow, validated and parsed.

    Attributes:
        mesh: the geometry and its meshing.
        solver: the FE settings of the solve jobs.
        solve_fe: the ``fe`` section as the solve jobs receive it: a ``chest`` contact
            obstacle written out from ``mesh.geometry`` (the jobs need no mesh section);
            without contact, ``fe`` itself.
        cases: the sweep, sorted.
        clinical: the clinical cases, in the config's order.
        fe_study: the FE study.
        surrogate: the surrogate settings.
        surrogate_study: the surrogate's study.
        imaged: the mesh as an image of the loaded breast, or None (stress-free).
        sections: the validated mapping (defaults filled, keys sorted), the source of the
            rules' params; read it through :meth:`section`.
        adaptive: the adaptive sweep (``cases`` is then its start design), or None.
        dataset: the dataset's split and its seed.
    """

    mesh: MeshConfig
    solver: SolverSettings
    solve_fe: dict[str, Any]
    cases: tuple[Case, ...]
    clinical: tuple[Case, ...]
    fe_study: FEStudyConfig
    surrogate: SurrogateConfig
    surrogate_study: SurrogateStudyConfig
    imaged: ImagedConfig | None
    sections: dict[str, Any]
    adaptive: AdaptiveDesign | None = None
    dataset: DatasetSplit = DatasetSplit()

    @classmethod
    def from_mapping(
        cls, config: Mapping[str, Any], schema_path: str | Path = SCHEMA_PATH
    ) -> WorkflowConfig:
        """Validate ``config`` against the schema and parse every section.

        Args:
            config: the configuration as read from ``config.yaml`` (not modified).
            schema_path: the JSON schema (YAML) that states the bounds and defaults.

        Raises:
            ConfigError: naming the offending key(s), before any object is used.
        """
        sections = validated(config, schema_path)
        with config_section("mesh.geometry"):
            BreastGeometry.from_mapping(sections["mesh"]["geometry"])  # its errors named apart
        with config_section("mesh", tuple(sections["mesh"])):
            mesh = MeshConfig.from_mapping(sections["mesh"])
        with config_section("fe", tuple(sections["fe"])):
            solver = SolverSettings.from_config(sections)
            solve_fe = resolve_obstacle(sections["fe"], sections["mesh"])
        with config_section("sweep"):
            cases = tuple(sweep_cases(sections["sweep"]))
            adaptive = AdaptiveDesign.from_sweep(sections["sweep"])
        with config_section("clinical"):
            clinical = tuple(clinical_cases(sections["clinical"]))
        with config_section("dataset.split"):  # checked here, not after every solve at aggregation
            dataset = DatasetSplit.from_mapping(sections["dataset"])
        with config_section("sweep"):
            check_sweep_splits(cases, clinical, dataset.fractions)
        fe_study = FEStudyConfig.from_sections(sections)
        with config_section("surrogate"):
            surrogate = SurrogateConfig.from_mapping(sections["surrogate"])
        surrogate_study = SurrogateStudyConfig.from_sections(
            sections["surrogate_study"], surrogate, cases)
        with config_section("reference_state"):
            imaged = ImagedConfig.fromconfig_section(sections["reference_state"])
        return cls(mesh, solver, solve_fe, cases, clinical, fe_study, surrogate, surrogate_study,
                   imaged, sections, adaptive, dataset)

    def section(self, *keys: str) -> Any:
        """A copy of the validated value at ``keys``, e.g. ``section("mesh", "fixed")``."""
        value: Any = self.sections
        for key in keys:
            value = value[key]
        return copy.deepcopy(value)

    def sections_of(self, *names: str) -> dict[str, Any]:
        """Copies of the top-level sections ``names``, in that order."""
        return {name: self.section(name) for name in names}

    @property
    def solver_params(self) -> dict[str, Any]:
        """What a solve job's settings depend on, as its rule's ``params`` (``**`` them).

        ``fe`` as the solve jobs receive it (:attr:`solve_fe`), ``material`` and ``mesh.fixed``:
        the job builds its settings from them with one call, :func:`solver_settings`.
        """
        return {"fe": copy.deepcopy(self.solve_fe), "material": self.section("material"),
                "fixed": self.section("mesh", "fixed")}

    @property
    def fe_self_contact(self) -> dict[str, Any]:
        """The ``fe`` keys that the skin's pairs at rest depend on (self-contact, elements)."""
        fe = self.sections["fe"]
        return copy.deepcopy({"self_contact": fe.get("self_contact"),
                              "discretisation": fe.get("discretisation", {})})

    @property
    def chains(self) -> bool:
        """Whether the sweep's cases of one direction are solved as one chain (``fem.chain``)."""
        return bool(self.sections["sweep"]["chains"])

    def surrogate_held_out(self, split: str) -> SurrogateConfig:
        """The surrogate settings of the model trained on ``split`` (a held-out split).

        Raises:
            KeyError: if the sweep cannot form that split (:attr:`held_out_splits`).
        """
        if split not in self.held_out_splits:
            raise KeyError(f"the sweep forms no {split!r} split (it has {self.held_out_splits})")
        return self.surrogate.replace(split=split)

    @property
    def held_out_splits(self) -> tuple[str, ...]:
        """The splits that hold out whole groups of the sweep and can be formed from it.

        ``by_case`` always; ``by_direction`` with at least three directions; ``by_c1`` with
        at least three C1 values besides the softest and the stiffest, which always train
        (:func:`fem.splits.group_partition`).
        """
        phi = np.array([case.phi for case in self.cases], dtype=float)
        theta = np.array([case.theta for case in self.cases], dtype=float)
        directions = len(set(direction_keys(phi, theta))) if self.cases else 0
        c1_values = len({round(case.C1, 9) for case in self.cases})
        return tuple(
            split
            for split, enough in (
                ("by_case", True), ("by_direction", directions >= 3), ("by_c1", c1_values >= 5)
            )
            if enough
        )


def solver_settings(params: Any) -> SolverSettings:
    """A job's solver settings from its rule's ``params`` (:attr:`WorkflowConfig.solver_params`).

    Args:
        params: anything with the attributes ``fe``, ``material`` and ``fixed`` (a job's
            ``snakemake.params``).
    """
    return SolverSettings.from_config(
        {"fe": params.fe, "material": params.material, "mesh": {"fixed": params.fixed}})


def main(argv: list[str] | None = None) -> int:
    """``python -m run.config FILE...``: check config files as a run would, before it starts.

    Prints one line per file (its number of cases, or what is wrong) and exits 2 if any is
    invalid. ``make reproduce`` runs it first: Snakemake reads a ``--configfile`` itself and
    reports a YAML syntax error without its line.
    """
    import argparse

    parser = argparse.ArgumentParser(prog="python -m run.config", description=main.__doc__)
    parser.add_argument("files", nargs="+", type=Path, help="config files (YAML)")
    args = parser.parse_args(argv)
    status = 0
    for path in args.files:
        try:
            config = WorkflowConfig.from_mapping(read_config_file(path))
        except ConfigError as err:
            print(f"{path}: invalid configuration: {err}", file=sys.stderr)
            status = 2
        else:
            print(f"{path}: valid, {len(config.cases)} cases")
    return status


if __name__ == "__main__":
    sys.exit(main())
