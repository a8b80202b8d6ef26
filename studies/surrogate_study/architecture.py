"""The architecture study (the paper's Table 2), model selection and the ablations.

Each training run is a model folder (see :mod:`surrogate.checkpoint`) whose
``model.json`` holds its metrics. This module only reads those folders: it groups
runs by architecture, gives mean ± SD of validation error, training time and
epochs, selects the architecture with the lowest mean validation error (the
paper's rule; optionally only among those that predict within a time budget),
and within it the run with the lowest validation error, which becomes the model
used downstream. :func:`plan_repeats` decides, from every architecture's first run,
which of them train their repeats: those between which the choice is close.
"""

from __future__ import annotations

import itertools
import json
import shutil
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from fem.dataset import Dataset
from studies import paper
from studies.results import Record, Result
from surrogate.checkpoint import HISTORY_JSON, MODEL_JSON, PARAMS_NPZ, unconverged_cases, write_json
from surrogate.config import SurrogateConfig, parse_architecture
from surrogate.structures import structure_for

if TYPE_CHECKING:
    from surrogate.epochs import TrainResult


@dataclass(frozen=True, slots=True)
class MeanSD(Record):
    """Mean and sample SD over training runs (and their range, where runs were ours)."""

    mean: float
    sd: float
    min: float | None = None
    max: float | None = None


@dataclass(frozen=True, slots=True)
class RunSummary(Record):
    """A group of training runs (one architecture, or one ablation of the settings).

    The architecture study adds the paper's row, the one-core prediction timing and whether
    it is within the budget; the ablations add the ratios to the baseline and what each
    changes.
    """

    runs: int
    validation_error_mm: MeanSD
    validation_error_domain_mm: MeanSD
    train_s: MeanSD
    epochs: MeanSD
    best_run: str
    best_validation_error_mm: float
    parameters: int
    paper: dict[str, MeanSD] | None = None
    predict_one_core: dict[str, Any] | None = None
    within_prediction_budget: bool | None = None
    error_ratio_to_baseline: float | None = None
    time_ratio_to_baseline: float | None = None
    boundary: str | None = None
    changed: dict[str, Any] | None = None


@dataclass(frozen=True, slots=True)
class ArchitectureTable(Result):
    """``results/surrogate/study/table2.json``: the paper's Table 2 and the selection.

    ``repeats`` and ``repeat_within`` are the study's settings: each row's ``runs`` is
    ``repeats``, or one where ``repeat_within`` left an architecture unrepeated
    (:func:`plan_repeats`).
    """

    rows: dict[str, RunSummary]
    paper_selected_architecture: str
    selected_architecture: str
    selected_run: str
    most_accurate_architecture: str
    rule: str
    prediction_budget_ms: float | None = None
    timing: dict[str, Any] | None = None
    repeats: int | None = None
    repeat_within: float | None = None


@dataclass(frozen=True, slots=True)
class AblationComparison(Result):
    """``results/surrogate/ablations.json``: ablations of the settings against the baseline."""

    baseline: RunSummary
    ablations: dict[str, RunSummary]
    architecture: str | None = None


class StudyError(ValueError):
    """The study's runs are missing or inconsistent."""


@dataclass(frozen=True, slots=True)
class RepeatPlan(Result):
    """``results/surrogate/study/repeats.json``: the runs each architecture trains.

    Every architecture trains once; the repeats beyond the first (``repeats`` runs in all)
    only where its first run's validation error is within ``within`` (a fraction) of the best
    first run's: the architectures between which the choice is close. ``within`` None
    repeats every architecture (the paper's protocol).
    """

    repeats: int
    within: float | None
    first_error_mm: dict[str, float]
    runs: dict[str, int]

    def folders(self, study_dir: str, name: str) -> list[str]:
        """File ``name`` of every planned run, ``<study_dir>/<arch>/r<repeat>/<name>``."""
        return [f"{study_dir}/{arch}/r{r}/{name}"
                for arch, n in self.runs.items() for r in range(n)]


def plan_repeats(first_runs: Iterable[dict[str, Any]], repeats: int,
                 within: float | None) -> RepeatPlan:
    """The runs each architecture of the study trains, from each one's first run.

    ``first_runs`` are :func:`read_run` records, one per architecture (in the study's order);
    an architecture whose first run's validation error is at most ``(1 + within)`` times the
    lowest trains ``repeats`` runs, any other one its first run only.

    Raises:
        StudyError: if there are no runs, an architecture has two, a validation error is not
            finite, or ``within`` or ``repeats`` is out of range.
    """
    if repeats < 1 or (within is not None and not within >= 0):
        raise StudyError(f"repeats must be >= 1 and within >= 0 or None, got {repeats}, {within}")
    errors: dict[str, float] = {}
    for run in first_runs:
        arch, error = run["architecture"], run["validation_error_mm"]
        if arch in errors:
            raise StudyError(f"two first runs of {arch}: {run['folder']}")
        if error is None or not np.isfinite(error):
            raise StudyError(f"run {run['folder']} has a non-finite validation error")
        errors[arch] = float(error)
    if not errors:
        raise StudyError("the architecture study has no runs")
    bound = (1.0 + within) * min(errors.values()) if within is not None else np.inf
    runs = {arch: repeats if error <= bound else 1 for arch, error in errors.items()}
    return RepeatPlan(repeats=repeats, within=within, first_error_mm=errors, runs=runs)


def read_run(folder: str | Path) -> dict[str, Any]:
    """Metrics and settings of one training run (its ``model.json``).

    Raises:
        StudyError: if the run has no readable ``model.json``.
    """
    folder = Path(folder)
    if folder.name == MODEL_JSON:
        folder = folder.parent
    try:
        meta = json.loads((folder / MODEL_JSON).read_text())
    except (OSError, json.JSONDecodeError) as err:
        raise StudyError(f"run {folder} has no readable {MODEL_JSON}: {err}") from None
    cfg = meta["config"]
    return {
        "folder": str(folder),
        "architecture": f"{cfg['hidden_layers']}x{cfg['width']}",
        "seed": cfg["seed"],
        "boundary": cfg.get("boundary", "network"),
        "split": cfg.get("split", "by_sample"),
        **{k: meta["metrics"].get(k) for k in (
            "validation_error_mm", "validation_error_domain_mm", "train_s", "compile_s",
            "epochs", "best_epoch")},
        "parameters": count_parameters(cfg),
        "config": cfg,
    }


def count_parameters(cfg: dict[str, Any]) -> int:
    """Weights and biases of every network of a run's config (``model.json``'s ``config``)."""
    structure = structure_for(SurrogateConfig.from_mapping(cfg))
    return sum(
        a * b + b
        for net in structure.network_names()
        for a, b in itertools.pairwise(structure.layer_sizes(net))
    )


def _mean_sd(values: Sequence[float]) -> dict[str, float]:
    arr = np.asarray(values, dtype=float)
    return {"mean": float(arr.mean()), "sd": float(arr.std(ddof=1)) if arr.size > 1 else 0.0,
            "min": float(arr.min()), "max": float(arr.max())}


def summarise(runs: Iterable[dict[str, Any]]) -> dict[str, Any]:
    """Mean ± SD (sample SD, n − 1) of a group of runs' error, time and epochs."""
    runs = list(runs)
    if not runs:
        raise StudyError("no runs to summarise")
    best = min(runs, key=lambda r: r["validation_error_mm"])
    return {
        "runs": len(runs),
        "validation_error_mm": _mean_sd([r["validation_error_mm"] for r in runs]),
        "validation_error_domain_mm": _mean_sd([r["validation_error_domain_mm"] for r in runs]),
        "train_s": _mean_sd([r["train_s"] for r in runs]),
        "epochs": _mean_sd([r["epochs"] for r in runs]),
        "best_run": best["folder"],
        "best_validation_error_mm": best["validation_error_mm"],
        "parameters": runs[0]["parameters"],
    }


def architecture_table(runs: Iterable[dict[str, Any]]) -> dict[str, Any]:
    """Table 2: one row per architecture, the paper's figures beside ours, and the selection.

    Raises:
        StudyError: if there are no runs or a run's validation error is not finite.
    """
    groups: dict[str, list[dict[str, Any]]] = {}
    for run in runs:
        if not np.isfinite(run["validation_error_mm"]):
            raise StudyError(f"run {run['folder']} has a non-finite validation error")
        groups.setdefault(run["architecture"], []).append(run)
    if not groups:
        raise StudyError("the architecture study has no runs")
    order = sorted(groups, key=parse_architecture)
    rows = {arch: {**summarise(groups[arch]), "paper": _paper_row(arch)} for arch in order}
    table = {"rows": rows, "paper_selected_architecture": paper.BEST_ARCHITECTURE}
    return select_architecture(table)


def select_architecture(table: dict[str, Any], budget_ms: float | None = None) -> dict[str, Any]:
    """Select the architecture used downstream, in place, and return the table.

    Without a budget: the lowest mean validation error (the paper's rule). With
    ``budget_ms``: the lowest mean validation error among the architectures whose
    one-core prediction time (``predict_one_core.api.median_ms`` of each row, see
    :func:`studies.surrogate_study.timing.time_on_one_core`) is within the budget: a larger network
    that is a little more accurate but too slow for the view it serves is not chosen.
    If none is within the budget, the fastest is chosen and the table says so.
    Within the architecture, the run with the lowest validation error is the model.

    Raises:
        StudyError: if a budget is given and a row has no prediction time.
    """
    rows = table["rows"]
    error = lambda a: (rows[a]["validation_error_mm"]["mean"], parse_architecture(a))  # noqa: E731
    rule = "lowest mean validation error over the repeats (the paper's rule)"
    candidates = list(rows)
    if budget_ms is not None:
        missing = [a for a in rows if "predict_one_core" not in rows[a]]
        if missing:
            raise StudyError(
                f"no prediction time for {', '.join(missing)}: cannot apply the budget"
            )
        speed = {a: rows[a]["predict_one_core"]["api"]["median_ms"] for a in rows}
        within = [a for a in rows if speed[a] <= budget_ms]
        for a in rows:
            rows[a]["within_prediction_budget"] = a in within
        if within:
            candidates = within
            rule = (
                f"lowest mean validation error among the architectures that predict a case "
                f"within {budget_ms:g} ms on one core"
            )
        else:
            candidates = [min(rows, key=lambda a: speed[a])]
            rule = f"no architecture predicts within {budget_ms:g} ms on one core: the fastest"
    selected = min(candidates, key=error)
    table.update(
        selected_architecture=selected,
        selected_run=rows[selected]["best_run"],
        most_accurate_architecture=min(rows, key=error),
        prediction_budget_ms=budget_ms,
        rule=rule + "; within it the run with the lowest validation error",
    )
    return table


def _paper_row(arch: str) -> dict[str, Any] | None:
    row = paper.TABLE2.get(arch)
    if row is None:
        return None
    return {k: {"mean": v[0], "sd": v[1]} for k, v in row.items()}


def compare_ablations(
    baseline: Sequence[dict[str, Any]], ablations: dict[str, Sequence[dict[str, Any]]]
) -> dict[str, Any]:
    """Ablations of the settings at one architecture against the baseline runs (same seeds).

    ``ratio`` is the ablation's mean validation error over the baseline's (< 1: better).
    """
    base = summarise(baseline)
    base_config = baseline[0].get("config") or {}
    out = {"baseline": base, "ablations": {}}
    for name, runs in ablations.items():
        s = summarise(runs)
        s["error_ratio_to_baseline"] = (
            s["validation_error_mm"]["mean"] / base["validation_error_mm"]["mean"]
        )
        s["time_ratio_to_baseline"] = s["train_s"]["mean"] / base["train_s"]["mean"]
        s["boundary"] = runs[0]["boundary"]
        # what the ablation changes (the seed differs between repeats, not between ablations)
        s["changed"] = {
            k: v
            for k, v in (runs[0].get("config") or {}).items()
            if k != "seed" and base_config.get(k) != v
        }
        out["ablations"][name] = s
    return out


def refit_model(source: str | Path, dataset: Dataset, target: str | Path) -> TrainResult:
    """The run at ``source`` trained again on its validation data too, saved to ``target``.

    Its own config and held-out cases, on ``dataset`` (the one it was trained on), for the
    epochs its validation chose (its ``best_epoch``), keeping the last weights
    (:func:`surrogate.train.train_and_evaluate`'s ``refit_epochs``): the validation data has
    chosen the architecture and the epochs, and the model used downstream then learns from it
    too. For a pod model, whose validation data is whole cases, a case the run never trained on
    is one where it extrapolates in C1 or direction.

    Raises:
        ModelFileError: if ``source`` holds no model.
        ValueError: if the run was trained on another dataset (its points, or a held-out case
            the dataset lacks) or never improved on its validation data (no best epoch).
    """
    from surrogate.checkpoint import read_model_card, save_model
    from surrogate.train import train_and_evaluate

    card = read_model_card(source)
    if card.get("n_points") != dataset.n_points:
        raise ValueError(f"{source} has {card.get('n_points')} material points, the dataset "
                         f"{dataset.n_points}: it was not trained on this dataset")
    ids = {str(case): i for i, case in enumerate(dataset.ids)}
    held_out = [str(case) for case in card.get("held_out_cases") or []]
    missing = [case for case in held_out if case not in ids]
    if missing:
        raise ValueError(f"{source} held out {', '.join(missing)}, which the dataset lacks")
    held = [ids[case] for case in held_out]
    epochs = int(card.get("metrics", {}).get("best_epoch") or 0)
    if epochs < 1:
        raise ValueError(f"{source} has no best epoch to train again for")
    result = train_and_evaluate(dataset, SurrogateConfig.from_mapping(card["config"]),
                                progress=False, holdout=np.asarray(held) if held else None,
                                refit_epochs=epochs)
    save_model(target, result, dataset)
    return result


def copy_model(source: str | Path, target: str | Path, dataset: Dataset | None = None) -> None:
    """Copy a model folder's files (model.json, params.npz, history.json) to ``target``.

    With ``dataset`` (the one the model was trained on), the copy's
    ``training_range.unconverged`` is set to that dataset's failed cases, so that the
    deployed model warns where no FE solution backs a prediction even when the source
    run was saved without that record.
    """
    source, target = Path(source), Path(target)
    target.mkdir(parents=True, exist_ok=True)
    for name in (PARAMS_NPZ, HISTORY_JSON):
        shutil.copyfile(source / name, target / name)
    meta = json.loads((source / MODEL_JSON).read_text())
    if dataset is not None:
        if meta.get("n_points") != dataset.n_points:
            raise ValueError(
                f"{source} has {meta.get('n_points')} material points, the dataset "
                f"{dataset.n_points}: it was not trained on this dataset"
            )
        meta.setdefault("training_range", {})["unconverged"] = unconverged_cases(dataset)
    write_json(target / MODEL_JSON, meta)  # model.json last: it marks completion
