"""The workflow's report: one self-contained HTML page with its PNG figures beside it.

The page answers the user's request ("both speed and accuracy count: chart one against
the other, test stability where methods fail, and model no more than a scene needs")
and sets our results beside the paper's. Every number on it is read from the files the
workflow wrote (the dataset, the mesh quality, the FE study's and the surrogate's JSON
results, the clinical error fields) or from :mod:`studies.paper` (the paper's);
a file or key that is absent shows as "n/a" or as a note, never as a guess.

:func:`build_report` is the entry point; it decides what goes in and writes the HTML.
The figures are drawn by :mod:`studies.figures.fe` and :mod:`studies.figures.surrogate`.
"""

from __future__ import annotations

import html
import json
import logging
import math
import re
import shutil
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from fem.sweep import Case
from studies import paper
from studies.figures import fe as fem_plots
from studies.figures import surrogate as surrogate_plots
from surrogate.config import parse_architecture

log = logging.getLogger(__name__)

#: Accuracy needs (mm) of the "model no more than a scene needs" section; the paper's
#: clinically accepted error is 5 mm.
NEEDS_MM = (0.5, 1.0, 5.0)
#: The paper's C1 range (kPa).
PAPER_C1_RANGE = (0.8, 5.0)

#: (id, heading) of every section, in page order.
SECTIONS = (
    ("mesh", "Mesh"),
    ("fe-speed-accuracy", "FE speed against accuracy"),
    ("surrogate-speed-accuracy", "Surrogate speed against accuracy"),
    ("scene-needs", "Model no more than a scene needs"),
    ("stability", "Stability"),
    ("paper", "The paper side by side"),
    ("sweep-cost", "Sweep cost"),
    ("training", "Surrogate training"),
)

#: Input names :func:`build_report` reads (the report rule's named inputs).
INPUT_NAMES = (
    "dataset", "quality", "mesh_png", "model", "history", "table2", "variants", "clinical",
    "extrapolation", "benchmark", "clinical_fields", "fe_clinical", "fe_speed_accuracy",
    "fe_stability",
)

TARGET_NAMES = {
    "median_wall_s": "median wall time per case (s)",
    "factorization_equivalents": "factorisation equivalents (largest over the cases)",
    "relative_max_error": "max |u − u_ref| / max |u_ref| (%, largest over the cases)",
}
GOAL_NAMES = {
    "validation_error_mm": "best validation error (mm)",
    "worst_clinical_rmse_mm": "worst clinical-case error, Eq. 3 (mm, by-sample)",
    "worst_clinical_relative_rmse": "worst clinical-case error / max |u| (by-sample)",
    "predict_one_core_ms": "one whole-field prediction on one core (ms)",
    "train_3x32_s": "training a 3x32 network (s)",
}
COST_LABELS = {
    "median_cpu_s": "median CPU time per clinical case (s)",
    "median_wall_s": "median wall time per clinical case (s)",
}
_VARIANT_ID = re.compile(
    r"g=(?P<g>[0-9.]+)_m=(?P<m>[0-9.]+)(?:_f=(?P<f>[0-9.]+))?_o=(?P<o>[12])_el=(?P<el>[a-z0-9-]+)"
    r"_solver=(?P<solver>[a-z-]+)_q=(?P<q>[0-9]+)$"
)

STYLE = """
body{font-family:sans-serif;max-width:1250px;margin:auto;padding:0 1em;line-height:1.4}
h2{border-bottom:2px solid #ccc;margin-top:2em}
table{border-collapse:collapse;margin:0.8em 0;font-size:0.9em}
td,th{border:1px solid #999;padding:3px 8px;text-align:right;vertical-align:top}
td:first-child,th:first-child{text-align:left}
th{background:#eee}
tr.highlight td{background:#fff3c4;font-weight:bold}
figure{margin:1em 0}
figure img{max-width:100%;height:auto;border:1px solid #ddd}
figcaption,p.caption{color:#333;font-size:0.95em}
p.note{color:#666;font-size:0.9em}
p.error{color:#a00;font-weight:bold}
"""


# -- formatting ---------------------------------------------------------------------------------
def _finite(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _fmt(value: Any, spec: str = ".3g", suffix: str = "") -> str:
    """``value`` formatted, or "n/a" when it is missing or not a finite number."""
    return f"{value:{spec}}{suffix}" if _finite(value) else "n/a"


def _pm(mean: Any, sd: Any, spec: str = ".3g") -> str:
    if not _finite(mean):
        return "n/a"
    return f"{mean:{spec}} ± {sd:{spec}}" if _finite(sd) else f"{mean:{spec}}"


def _seconds(value: Any) -> str:
    """A duration with a unit that keeps it readable (µs to h)."""
    if not _finite(value):
        return "n/a"
    if value < 1e-3:
        return f"{1e6 * value:.3g} µs"
    if value < 1.0:
        return f"{1e3 * value:.3g} ms"
    if value < 600.0:
        return f"{value:.3g} s"
    return f"{value:.4g} s ({value / 3600:.2g} h)"


def _times(ratio: Any) -> str:
    """A speed-up or ratio, e.g. ``6850×``."""
    if not _finite(ratio):
        return "n/a"
    return f"{ratio:,.0f}×" if ratio >= 1000 else f"{ratio:.3g}×"


def _pct(fraction: Any, spec: str = ".3g") -> str:
    """A fraction as a percentage (without the % sign), or "n/a"."""
    return _fmt(100 * fraction, spec) if _finite(fraction) else "n/a"


def _range(values: Any, spec: str = ".3g") -> str:
    if not values or len(values) != 2 or not all(_finite(v) for v in values):
        return "n/a"
    return f"[{values[0]:{spec}}, {values[1]:{spec}}]"


def _yes(flag: Any) -> str:
    return "n/a" if flag is None else ("yes" if flag else "no")


def _e(text: Any) -> str:
    return html.escape(str(text))


def _p(text: str, cls: str = "") -> str:
    """A paragraph of plain text (escaped)."""
    return f'<p class="{cls}">{_e(text)}</p>' if cls else f"<p>{_e(text)}</p>"


def _h3(text: str) -> str:
    return f"<h3>{_e(text)}</h3>"


def _table(header: Sequence[str], rows: Iterable[Sequence[Any]], highlight: Iterable[int] = (),
           table_id: str = "") -> str:
    """An HTML table of escaped cells; rows whose index is in ``highlight`` stand out."""
    marked = set(highlight)
    head = "".join(f"<th>{_e(h)}</th>" for h in header)
    body = []
    for i, row in enumerate(rows):
        cls = ' class="highlight"' if i in marked else ""
        body.append(f"<tr{cls}>" + "".join(f"<td>{_e(c)}</td>" for c in row) + "</tr>")
    ident = f' id="{_e(table_id)}"' if table_id else ""
    return f"<table{ident}><thead><tr>{head}</tr></thead><tbody>{''.join(body)}</tbody></table>"


def _figure(src: str, alt: str, caption: str) -> str:
    return (f'<figure><img src="{_e(src)}" alt="{_e(alt)}">'
            f"<figcaption>{_e(caption)}</figcaption></figure>")


def _missing(what: str) -> str:
    return _p(f"Not available: {what} was not found among the report's inputs.", "note")


def variant_label(variant_id: str) -> str:
    """A short, readable name of an FE study variant, e.g. ``P2/P1, h 15/10 mm, direct``
    (``h 15/10/4 mm`` with 4 mm elements over the fold)."""
    match = _VARIANT_ID.match(str(variant_id))
    if match is None:
        return str(variant_id)
    g, m = 1e3 * float(match["g"]), 1e3 * float(match["m"])
    sizes = f"{g:.3g}/{m:.3g}" + (f"/{1e3 * float(match['f']):.3g}" if match["f"] else "")
    label = f"{fem_plots.ELEMENT_NAMES.get(match['el'], match['el'])}, h {sizes} mm"
    if match["o"] == "2":
        label += " curved"
    label += f", {match['solver']}"
    if match["q"] != "0":
        label += f", q = {match['q']}"
    return label


# -- inputs -------------------------------------------------------------------------------------
def _read_json(path: Path | None) -> dict[str, Any] | None:
    if path is None:
        return None
    if not path.is_file():
        log.warning("report input %s does not exist", path)
        return None
    return json.loads(path.read_text())


def _as_path(value: Any) -> Path | None:
    if value is None or value == "" or (isinstance(value, (list, tuple)) and not value):
        return None
    if isinstance(value, (list, tuple)):
        value = value[0]
    return Path(str(value))


@dataclass
class _Context:
    """What every section builder reads: the loaded inputs and where figures go."""

    out_dir: Path
    clinical: list[dict[str, Any]]
    paths: dict[str, Path | None]
    clinical_fields: list[Path]
    json: dict[str, dict[str, Any] | None] = field(default_factory=dict)
    _dataset: Any = None
    _cases: dict[str, np.ndarray] | None = None

    def dataset(self) -> Any:
        """The dataset (:func:`surrogate.data.load_dataset`), read once; None if absent."""
        if self._dataset is None and self.paths.get("dataset") is not None:
            from surrogate.data import load_dataset

            if self.paths["dataset"].is_file():
                self._dataset = load_dataset(self.paths["dataset"])
        return self._dataset

    def case_columns(self) -> dict[str, np.ndarray]:
        """Every per-case column under the dataset's ``/cases``, read once; {} if absent.

        Strings come back as ``str`` arrays. A column an older dataset lacks is simply not
        a key, so each section checks for the columns it needs.
        """
        if self._cases is None:
            self._cases = {}
            path = self.paths.get("dataset")
            if path is not None and path.is_file():
                import h5py

                with h5py.File(path, "r") as h5:
                    group = h5.get("cases")
                    for key, column in (group.items() if group is not None else ()):
                        if isinstance(column, h5py.Dataset):
                            self._cases[key] = (column.asstr()[...] if column.dtype.kind == "O"
                                                else column[...])
        return self._cases

    def figure(self, name: str, draw: Callable[[Path], None], alt: str, caption: str) -> str:
        """Draw a figure into the report folder and return its HTML."""
        draw(self.out_dir / name)
        return _figure(name, alt, caption)

    def case_label(self, case_id: str) -> str:
        """The config's label of a clinical case, or its id."""
        for item in self.clinical:
            if _case_id(item) == case_id:
                return str(item.get("label", case_id))
        return case_id


def _case_id(item: Mapping[str, Any]) -> str:
    return Case(float(item["C1"]), float(item["phi"]), float(item.get("theta", 0.0))).id


# -- sections -----------------------------------------------------------------------------------
def _mesh_section(ctx: _Context) -> str:
    quality = ctx.json.get("quality")
    if quality is None:
        return _missing("results/mesh/quality.json")
    anatomy = quality.get("anatomy") or {}
    dofs = quality.get("dofs") or {}
    rows = [
        ["tetrahedra", _fmt(quality.get("cells"), "d")],
        ["vertices (material points)", _fmt(quality.get("vertices"), "d")],
        ["P2/P1 unknowns", _fmt(dofs.get("P2/P1"), "d")],
        ["volume (ml)", _fmt(quality.get("volume_ml"), ".0f")],
        ["breast (mound) volume (ml)", _fmt(anatomy.get("breast_volume_ml"), ".0f")],
        ["projection from the chest wall (mm)",
         _fmt(1e3 * anatomy["projection_from_chest_wall_m"], ".0f")
         if _finite(anatomy.get("projection_from_chest_wall_m")) else "n/a"],
        ["min / mean SICN", f"{_fmt(quality.get('min_minSICN'), '.3f')} / "
                            f"{_fmt(quality.get('mean_minSICN'), '.3f')}"],
        ["min / max dihedral angle (deg)", f"{_fmt(quality.get('min_dihedral_deg'), '.1f')} / "
                                           f"{_fmt(quality.get('max_dihedral_deg'), '.1f')}"],
        ["inverted / degenerate cells", f"{_fmt(quality.get('inverted_cells'), 'd')} / "
                                        f"{_fmt(quality.get('degenerate_cells'), 'd')}"],
        ["meshing time", _seconds(quality.get("mesh_wall_s"))],
    ]
    out = [_p("The tetrahedral mesh of the breast on which the FE sweep was solved; its "
              "vertices are the material points the surrogate learns. SICN is the "
              "signed inverse condition number of a cell (1 for a regular tetrahedron, "
              "≤ 0 for an inverted one).", "caption"),
           _table(["quantity", "value"], rows)]
    png = ctx.paths.get("mesh_png")
    if png is not None and png.is_file():
        shutil.copyfile(png, ctx.out_dir / "mesh.png")
        out.append(_figure("mesh.png", "the mesh",
                           "The mesh with its named surfaces coloured (rib/chest wall clamped)."))
    return "".join(out)


def _fe_variant_points(sa: Mapping[str, Any]) -> list[dict[str, Any]]:
    """The solved variants of the speed-accuracy study, as points of its chart."""
    cost_key = sa.get("cost") or "median_cpu_s"
    front = set(sa.get("pareto_front") or [])
    points = []
    for v in sa.get("variants") or []:
        error, cost = v.get("max_relative_error"), v.get(cost_key)
        if v.get("skipped") or not (_finite(error) and _finite(cost)):
            continue
        points.append({
            "variant": v["variant"], "cost_s": cost, "relative_error": error,
            "element": v.get("element"), "solver": v.get("solver"),
            "pareto": v["variant"] in front or bool(v.get("pareto")),
            "default": v["variant"] == sa.get("default_variant"),
            "cheapest": v["variant"] == sa.get("cheapest_meeting_target"),
        })
    return points


def _overlap(record: Mapping[str, Any] | None) -> str:
    """``k of n`` boundary vertices inside other cells of the deformed body, or n/a."""
    if not record:
        return "n/a"
    return f"{record['overlapping_vertices']} of {record['boundary_vertices']}"


def _worst_case(cases: Sequence[Mapping[str, Any]], key: str) -> float | None:
    """The largest ``accuracy[key]`` over the cases, or None unless every case has one."""
    values = [(c.get("accuracy") or {}).get(key) for c in cases]
    if not values or not all(_finite(v) for v in values):
        return None
    return float(max(values))


def _meets(error: Any, target: Any) -> bool:
    return _finite(error) and _finite(target) and error <= target


def _cheapest_and_default(sa: Mapping[str, Any]) -> str:
    """A sentence naming the cheapest variant meeting the target and placing the default."""
    cost_key = sa.get("cost") or "median_cpu_s"
    target = sa.get("target_relative_max_error")
    default_id, cheapest = sa.get("default_variant"), sa.get("cheapest_meeting_target")
    by_id = {v["variant"]: v for v in sa.get("variants") or []}

    def described(variant_id: str) -> str:
        v = by_id.get(variant_id, {})
        return (f"{variant_label(variant_id)}: {_seconds(v.get(cost_key))} per case, error "
                f"{_pct(v.get('max_relative_error'))} %")

    if cheapest is None:
        text = [f"No variant meets the accuracy target of {_pct(target)} %."]
    else:
        text = [f"The cheapest variant meeting the target of {_pct(target)} % is "
                f"{described(cheapest)}."]
    if default_id is None:
        text.append("The default configuration is not recorded in the study.")
    elif default_id not in by_id:
        text.append(f"The default configuration ({variant_label(default_id)}) is not among the "
                    "variants studied, so it cannot be placed on this chart.")
    elif default_id == cheapest:
        text.append("The default configuration is that cheapest variant.")
    else:
        meets = _meets(by_id[default_id].get("max_relative_error"), target)
        text.append(f"The default configuration ({described(default_id)}) is not the cheapest "
                    f"variant meeting the target; it {'meets' if meets else 'does not meet'} "
                    "the target.")
    return " ".join(text)


def _fe_variant_table(sa: Mapping[str, Any]) -> str:
    """Every variant of the speed-accuracy study, cheapest first."""
    cost_key = sa.get("cost") or "median_cpu_s"
    target = sa.get("target_relative_max_error")
    default_id, cheapest = sa.get("default_variant"), sa.get("cheapest_meeting_target")
    ordered = sorted(sa.get("variants") or [],
                     key=lambda v: (not _finite(v.get(cost_key)), v.get(cost_key) or 0.0))
    rows, highlight = [], []
    for i, v in enumerate(ordered):
        error = v.get("max_relative_error")
        notes = []
        if v["variant"] == default_id:
            notes.append("default")
        if v["variant"] == cheapest:
            notes.append("cheapest meeting the target")
            highlight.append(i)
        if v.get("skipped"):
            notes.append(f"skipped: {v['skipped']}")
        elif not _finite(error):
            notes.append("not every case converged or was compared")
        rows.append([
            variant_label(v["variant"]), _fmt(v.get("dofs"), "d"), _fmt(v.get("cells"), "d"),
            _seconds(v.get("median_cpu_s")), _seconds(v.get("median_wall_s")), _pct(error),
            _fmt(v.get("max_error_mm"), ".3g"), _fmt(v.get("max_factorization_equivalents"), ".3g"),
            _yes(v.get("pareto")) if "pareto" in v else "n/a", _yes(_meets(error, target)),
            _fmt(v.get("max_overlapping_vertices"), "d"), "; ".join(notes),
        ])
    return _table(["variant", "DOFs", "cells", "median CPU / case", "median wall / case",
                   "max rel. error (%)", "max error (mm)", "factorisation equivalents", "Pareto",
                   "meets target", "self-overlapping vertices", "note"], rows, highlight,
                  table_id="fe-variants")


def _fe_clinical_tables(ctx: _Context) -> str:
    """The default configuration on the clinical cases: targets, then one row per case."""
    fe = ctx.json.get("fe_clinical")
    if fe is None:
        return _missing("results/fe_study/clinical.json")
    out = [_p(
        "The clinical cases solved with the sweep's own settings, timed on one core; each is "
        f"solved again with a fixed {fe.get('baseline_steps', 'n/a')}-step Newton baseline in "
        "the same process, and compared with the refined reference. A factorisation "
        "equivalent is the solve time divided by the time of one Jacobian assembly, "
        "factorisation and solve of the same system; factorisations counts those the "
        "solve itself did (the default solver keeps one across Newton iterations while "
        "GMRES converges on it in few Krylov iterations). Self-overlap counts the boundary "
        "vertices of the deformed body that lie inside another of its cells: the model has no "
        "contact, so a fold that closes can pass through itself.", "caption")]
    rows = []
    for name, item in ((fe.get("summary") or {}).get("targets") or {}).items():
        value, goal = item.get("value"), item.get("target")
        shown = ((_pct(value), _pct(goal)) if name == "relative_max_error"
                 else (_fmt(value, ".3g"), _fmt(goal, ".3g")))
        rows.append([TARGET_NAMES.get(name, name.replace("_", " ")), *shown,
                     _yes(item.get("met"))])
    out.append(_table(["measure", "value", "target", "met"], rows, table_id="fe-targets"))
    rows = []
    for c in fe.get("cases") or []:
        acc, base = c.get("accuracy") or {}, c.get("baseline") or {}
        rows.append([
            ctx.case_label(c["case"]), _yes(c.get("converged")), _seconds(c.get("wall_s")),
            _fmt(c.get("load_steps"), "d"), _fmt(c.get("total_newton_iterations"), "d"),
            _fmt(c.get("linear_iterations"), "d"), _fmt(c.get("preconditioner_builds"), "d"),
            _fmt(c.get("factorization_equivalents"), ".3g"), _pct(acc.get("relative_max_error")),
            _fmt(acc.get("max_error_mm"), ".3g"), _fmt(acc.get("mean_error_mm"), ".3g"),
            _seconds(base.get("wall_s")), _fmt(c.get("baseline_over_adaptive_wall"), ".3g"),
            _overlap(c.get("self_overlap")),
        ])
    out.append(_table(["case", "converged", "wall time", "load steps", "Newton its",
                       "Krylov its", "factorisations",
                       "factorisation equivalents", "max rel. error (%)", "max error (mm)",
                       "mean error (mm)", "fixed-step baseline", "baseline / adaptive",
                       "self-overlap"], rows, table_id="fe-clinical"))
    return "".join(out)


def _fe_speed_accuracy_section(ctx: _Context) -> str:
    sa = ctx.json.get("fe_speed_accuracy")
    out = []
    if sa is None:
        out.append(_missing("results/fe_study/speed_accuracy.json"))
    else:
        cost_key = sa.get("cost") or "median_cpu_s"
        cost_label = COST_LABELS.get(cost_key, f"{cost_key} per clinical case (s)")
        target = sa.get("target_relative_max_error")
        points = _fe_variant_points(sa)
        out.append(_p(
            "Each point is one FE discretisation of the study (mesh size × element × linear "
            f"solver preset): its cost, the {cost_label.replace(' (s)', '')}, against its "
            "discretisation error, the largest displacement difference from a refined "
            "reference solution over the clinical cases, relative to the largest reference "
            "displacement. Lower left is better. Colour gives the element, marker shape the "
            "solver; the black staircase joins the Pareto front (variants no other variant "
            "beats in both cost and error); the dashed red line is the accuracy target; the "
            "red ring marks the default configuration the sweep uses and the green diamond "
            "the cheapest variant meeting the target.", "caption"))
        if points:
            out.append(ctx.figure(
                "fe_speed_accuracy.png",
                lambda p: fem_plots.plot_speed_accuracy(points, p, cost_label, target),
                "FE cost against discretisation error",
                "FE speed against accuracy: cost per case (log) against relative error (log)."))
        else:
            out.append(_p("No variant of the study was solved with an error measured.", "note"))
        out.append(_p(_cheapest_and_default(sa)))
        out.append(_fe_variant_table(sa))
    out.append(_h3("Default configuration on the clinical cases"))
    out.append(_fe_clinical_tables(ctx))
    return "".join(out)


def _fe_points_for_surrogate(ctx: _Context) -> list[dict[str, Any]]:
    """FE configurations as (solve time per case, worst clinical-case mean error)."""
    points = []
    fe = ctx.json.get("fe_clinical")
    if fe is not None:
        err = _worst_case(fe.get("cases") or [], "mean_error_mm")
        time_s = (fe.get("summary") or {}).get("median_wall_s")
        if err is not None and _finite(time_s):
            points.append({"label": "FE default", "time_s": time_s, "error_mm": err,
                           "default": True})
    sa = ctx.json.get("fe_speed_accuracy")
    for v in (sa or {}).get("variants") or []:
        if v.get("skipped"):
            continue
        err = _worst_case(v.get("cases") or [], "mean_error_mm")
        if err is not None and _finite(v.get("median_wall_s")):
            points.append({"label": variant_label(v["variant"]), "time_s": v["median_wall_s"],
                           "error_mm": err, "default": False})
    return points


def _predict_s(row: Mapping[str, Any]) -> float | None:
    ms = ((row.get("predict_one_core") or {}).get("api") or {}).get("median_ms")
    return 1e-3 * ms if _finite(ms) else None


def _surrogate_speed_accuracy_section(ctx: _Context) -> str:
    table = ctx.json.get("table2")
    if table is None:
        return _missing("results/surrogate/study/table2.json")
    selected = table.get("selected_architecture")
    archs = []
    for name, row in (table.get("rows") or {}).items():
        err, train = row.get("validation_error_mm") or {}, row.get("train_s") or {}
        if not (_finite(err.get("mean")) and _finite(train.get("mean"))):
            continue
        archs.append({"name": name, "error_mm": err["mean"], "error_sd_mm": err.get("sd") or 0.0,
                      "train_s": train["mean"], "train_sd_s": train.get("sd") or 0.0,
                      "predict_s": _predict_s(row), "selected": name == selected})
    fe_points = _fe_points_for_surrogate(ctx)
    out = [_p(
        "Left: each network architecture's validation error (mean over the validation "
        "points of |u − û|; dot = mean over the training repeats, bars = ± 1 SD) against its "
        "training time. Right: the same error against the time of one whole-field "
        "prediction on one CPU core. The FE model is drawn on both panels at its solve time "
        "per clinical case and its error against the refined reference (the worst clinical "
        "case's mean |u − u_ref|): the star is the default configuration, grey triangles the "
        "other FE study variants. On the left a surrogate is worth training when its "
        "training time is a small multiple of the FE solve times it replaces; on the right "
        "the horizontal gap is the speed-up per query and the vertical gap the price in "
        "accuracy. The selected architecture has a black ring.", "caption")]
    if archs:
        out.append(ctx.figure(
            "surrogate_speed_accuracy.png",
            lambda p: surrogate_plots.plot_speed_accuracy(archs, fe_points, p),
            "surrogate error against training and prediction time",
            "Surrogate speed against accuracy, with the FE on the same axes."))
    else:
        out.append(_p("The architecture study holds no complete row.", "note"))
    out.append(_p(f"Selected architecture: {selected} (rule: {table.get('rule', 'n/a')}); the "
                  f"paper selected {table.get('paper_selected_architecture', 'n/a')}."))
    variants = ctx.json.get("variants")
    out.append(_h3("Variants of the training settings at the selected architecture"))
    if variants is None:
        out.append(_missing("results/surrogate/variants.json"))
        return "".join(out)
    out.append(_p(
        "Each variant changes the listed settings of the selected model and is trained with "
        "the same seeds; a ratio below 1 means smaller error (or shorter training) than the "
        "baseline.", "caption"))
    def stats(v: Mapping[str, Any], key: str) -> str:
        item = v.get(key) or {}
        return _pm(item.get("mean"), item.get("sd"))

    base = variants.get("baseline") or {}
    rows = [["baseline", "none", stats(base, "validation_error_mm"),
             stats(base, "train_s"), _fmt(base.get("parameters"), "d"), "1", "1"]]
    for name, v in (variants.get("variants") or {}).items():
        changed = v.get("changed")
        changed = (", ".join(f"{k} = {val}" for k, val in changed.items()) if changed is not None
                   else f"boundary = {v.get('boundary', 'n/a')}")
        rows.append([name, changed or "none", stats(v, "validation_error_mm"),
                     stats(v, "train_s"), _fmt(v.get("parameters"), "d"),
                     _fmt(v.get("error_ratio_to_baseline"), ".3g"),
                     _fmt(v.get("time_ratio_to_baseline"), ".3g")])
    out.append(_table(["variant", "settings changed", "validation error (mm)",
                       "training time (s)", "parameters", "error ratio", "time ratio"], rows))
    return "".join(out)


# -- model no more than a scene needs -----------------------------------------------------------
@dataclass(frozen=True, slots=True)
class Candidate:
    """A model that can answer a query, with its worst clinical-case errors and its cost.

    Attributes:
        name: readable name.
        max_error_mm: the largest point error over the clinical cases.
        mean_error_mm: the largest per-case mean point error over the clinical cases.
        cost_s: seconds per prediction (surrogate) or per solve (FE), one core.
        against: what the errors are measured against.
    """

    name: str
    max_error_mm: float | None
    mean_error_mm: float | None
    cost_s: float | None
    against: str


def candidates(ctx: _Context) -> list[Candidate]:
    """Every model with clinical-case errors and a cost on record."""
    out = []
    clinical = ctx.json.get("clinical") or {}
    bench = ctx.json.get("benchmark") or {}
    table = ctx.json.get("table2") or {}
    for split, name in (("by_sample", "surrogate, by-sample split"),
                        ("by_case", "surrogate, by-case split (clinical cases unseen)")):
        block = clinical.get(split)
        if not block or not block.get("rows"):
            continue
        rows = block["rows"]
        max_err = [r.get("max_error_mm") for r in rows]
        mean_err = [r.get("rmse_mm") for r in rows]
        cost = None
        if split == "by_sample" and bench.get("selected_architecture") == block.get("architecture"):
            cost = _predict_s(bench)
        if cost is None:  # the same architecture's timing in the study
            cost = _predict_s((table.get("rows") or {}).get(block.get("architecture"), {}))
        out.append(Candidate(
            f"{name} ({block.get('architecture', '?')})",
            max(max_err) if all(_finite(v) for v in max_err) else None,
            max(mean_err) if all(_finite(v) for v in mean_err) else None,
            cost, "FE default solution"))
    fe = ctx.json.get("fe_clinical")
    if fe is not None:
        cases = fe.get("cases") or []
        out.append(Candidate("FE default configuration", _worst_case(cases, "max_error_mm"),
                             _worst_case(cases, "mean_error_mm"),
                             (fe.get("summary") or {}).get("median_wall_s"),
                             "refined FE reference"))
    sa = ctx.json.get("fe_speed_accuracy") or {}
    for v in sa.get("variants") or []:
        if v.get("skipped"):
            continue
        cases = v.get("cases") or []
        default = (" (the default's discretisation)"
                   if v["variant"] == sa.get("default_variant") else "")
        out.append(Candidate(f"FE {variant_label(v['variant'])}{default}",
                             _worst_case(cases, "max_error_mm"),
                             _worst_case(cases, "mean_error_mm"), v.get("median_wall_s"),
                             "refined FE reference"))
    return out


def c1_effect(
    C1: np.ndarray, phi: np.ndarray, theta: np.ndarray, displacement: np.ndarray,
    converged: np.ndarray,
) -> dict[str, np.ndarray]:
    """How much C1 changes the displacement at each gravity direction of a sweep.

    For each (Φ, θ) with at least two converged C1 values: ``spread_mm``, the largest
    point difference between the softest and the stiffest case; ``single_mm``, the
    error of the best single C1 (for each candidate C1, the largest point difference to
    any other C1 at that angle; the smallest over the candidates); ``relative``, the
    spread over the largest |u| at that angle; ``best_C1``, the candidate achieving
    ``single_mm``.

    Args:
        C1: per case, kPa.
        phi: per case, degrees.
        theta: per case, degrees.
        displacement: (cases, points, 3), mm.
        converged: per case.
    """
    keys = sorted({(round(float(p), 6), round(float(t), 6)) for p, t in zip(phi, theta)})
    out: dict[str, list[float]] = {k: [] for k in ("phi", "theta", "spread_mm", "single_mm",
                                                   "relative", "best_C1", "C1_min", "C1_max")}
    for p, t in keys:
        cases = np.flatnonzero(np.isclose(phi, p) & np.isclose(theta, t) & converged)
        if len(np.unique(C1[cases])) < 2:
            continue
        cases = cases[np.argsort(C1[cases])]
        u = displacement[cases]
        spread = float(np.linalg.norm(u[-1] - u[0], axis=1).max())
        worst = np.array([np.linalg.norm(u - u[i], axis=2).max() for i in range(len(cases))])
        best = int(np.argmin(worst))
        peak = float(np.linalg.norm(u, axis=2).max())
        for key, value in (("phi", p), ("theta", t), ("spread_mm", spread),
                           ("single_mm", float(worst[best])),
                           ("relative", spread / peak if peak > 0 else np.nan),
                           ("best_C1", float(C1[cases[best]])), ("C1_min", float(C1[cases[0]])),
                           ("C1_max", float(C1[cases[-1]]))):
            out[key].append(value)
    return {k: np.asarray(v, float) for k, v in out.items()}


def _scene_needs_section(ctx: _Context) -> str:
    cands = candidates(ctx)
    out = [_p(
        "Which model is enough for a given accuracy need? For each model: its worst "
        "error over the clinical cases (the largest error at any material point, and the "
        "largest per-case mean error) and its cost per answer on one core. The surrogates' "
        "errors are measured against the default FE solution (so they add to the FE "
        "default's own error against the refined reference, listed in its row); the FE "
        "variants' errors are against the refined reference. A surrogate's cost is one "
        "whole-field prediction on one pinned core (the by-case model's is its "
        "architecture's timing in the architecture study); an FE model's is the median "
        "wall time of a clinical-case solve, set-up excluded. A model meets a need when its "
        "error is at most the need; the cheapest such model is named. The paper's "
        "clinically accepted error is 5 mm.", "caption")]
    if not cands:
        out.append(_p("No model has clinical-case errors on record.", "note"))
    else:
        rows = [[c.name, _fmt(c.max_error_mm, ".3g"), _fmt(c.mean_error_mm, ".3g"),
                 _seconds(c.cost_s), c.against] for c in sorted(
                     cands, key=lambda c: (c.cost_s is None, c.cost_s or 0.0))]
        out.append(_table(["model", "worst max error (mm)", "worst mean error (mm)",
                           "cost per answer", "errors against"], rows, table_id="candidates"))
        rows = []
        for need in NEEDS_MM:
            row = [f"{need:g} mm"]
            for attr in ("max_error_mm", "mean_error_mm"):
                meeting = [c for c in cands if _meets(getattr(c, attr), need)]
                costed = [c for c in meeting if _finite(c.cost_s)]
                cheapest = min(costed, key=lambda c: c.cost_s) if costed else None
                row.append("; ".join(c.name for c in meeting) or "none")
                row.append("none" if cheapest is None
                           else f"{cheapest.name} ({_seconds(cheapest.cost_s)})")
            rows.append(row)
        out.append(_table(["accuracy need", "meet it at every point", "cheapest (every point)",
                           "meet it on average", "cheapest (on average)"], rows,
                          table_id="needs"))
    out.append(_h3("Can C1's effect be skipped?"))
    ds = ctx.dataset()
    if ds is None:
        out.append(_missing("results/dataset/dataset.h5"))
        return "".join(out)
    effect = c1_effect(ds.C1, ds.phi, ds.theta, ds.displacement, ds.converged)
    if effect["phi"].size == 0:
        out.append(_p("The sweep has fewer than two converged C1 values at every angle, so "
                      "C1's effect cannot be measured.", "note"))
        return "".join(out)
    C1_range = (float(effect["C1_min"].min()), float(effect["C1_max"].max()))
    out.append(_p(
        "For each gravity angle Φ of the sweep: the largest difference, over the material "
        "points, between the displacement of the softest and the stiffest tissue (circles), "
        "and the error left if one modelled that angle with a single, best-chosen C1 "
        "(squares: the largest difference from it to any other C1 of the sweep). A scene "
        "whose accuracy need (grey lines) lies above the squares can use one C1 at that "
        "angle. Right: the spread as a share of the largest displacement at that angle.",
        "caption"))
    out.append(ctx.figure(
        "c1_effect.png",
        lambda p: fem_plots.plot_c1_effect(effect["phi"], effect["spread_mm"], effect["single_mm"],
                                           effect["relative"], p, NEEDS_MM, C1_range),
        "C1's effect on the displacement per gravity angle",
        "Displacement spread across the C1 range against the gravity angle Φ."))
    sentences = []
    for need in NEEDS_MM:
        ok = effect["single_mm"] <= need
        if ok.all():
            sentences.append(f"For a {need:g} mm need, every angle can use a single C1.")
        elif not ok.any():
            sentences.append(f"For a {need:g} mm need, no angle can use a single C1 (the "
                             f"smallest single-C1 error is {effect['single_mm'].min():.3g} mm).")
        else:
            angles = ", ".join(f"{p:g}°" for p in effect["phi"][ok])
            sentences.append(f"For a {need:g} mm need, a single C1 is enough at Φ = {angles}.")
    out.append(_p(f"Over C1 = {C1_range[0]:g}–{C1_range[1]:g} kPa: " + " ".join(sentences)))
    rows = [[f"{p:g}", f"{t:g}", f"{s:.3g}", f"{100 * r:.3g}", f"{w:.3g}", f"{b:g}"]
            for p, t, s, r, w, b in zip(effect["phi"], effect["theta"], effect["spread_mm"],
                                        effect["relative"], effect["single_mm"], effect["best_C1"])]
    out.append(_table(["Φ (deg)", "θ (deg)", "spread (mm)", "spread / max |u| (%)",
                       "best single-C1 error (mm)", "best single C1 (kPa)"], rows,
                      table_id="c1-effect"))
    return "".join(out)


# -- stability ----------------------------------------------------------------------------------
def _stability_section(ctx: _Context) -> str:
    out = []
    stab = ctx.json.get("fe_stability")
    if stab is None:
        out.append(_missing("results/fe_study/stability.json"))
    else:
        records = stab.get("records") or []
        schemes = stab.get("schemes") or {}
        described = "; ".join(
            f"{name}: " + (f"{s.get('fixed_steps')} equal load steps"
                           if s.get("fixed_steps") else
                           f"adaptive steps from {s.get('initial_step', 'n/a')} of the load, "
                           f"cut back on failure down to {_fmt(s.get('min_step'), '.3g')}")
            for name, s in schemes.items())
        out.append(_p(
            "Where the nonlinear FE solve struggles or fails: each cell is one solve from rest "
            "at a tissue stiffness C1 (rows) and gravity angle Φ (columns), extended below the "
            f"paper's range (C1 ≥ {PAPER_C1_RANGE[0]:g} kPa, dashed line). One column of panels "
            "per loading scheme, the same colour scale along each row: accepted load steps, "
            "Newton iterations over all attempts, and rejected load steps (attempts that "
            "failed and were retried with a smaller step). A cross marks a case that did not "
            "reach the full load; its colour names the first failure. "
            f"Schemes — {described}. Mesh: {Path(str(stab.get('mesh', 'n/a'))).parent.name}, "
            f"{_fmt(stab.get('dofs'), 'd')} DOFs.", "caption"))
        if records:
            out.append(ctx.figure(
                "stability_maps.png",
                lambda p: fem_plots.plot_stability_maps(records, p, PAPER_C1_RANGE[0]),
                "stability maps over C1 and gravity angle",
                "Load steps, Newton iterations and rejected steps over (Φ, C1) per scheme."))
        lowest = stab.get("lowest_converging") or {}
        if lowest:
            out.append(_p("The lowest C1 from which every stiffer C1 of the grid converged, per "
                          "scheme and angle, and what went wrong at the next C1 below "
                          "(\"—\": nothing failed down to the grid's lowest C1).", "caption"))
            out.append(_lowest_converging_table(lowest, "lowest-converging"))
        failed = [r for r in records if not r.get("converged")]
        if failed:
            out.append(_table(
                ["scheme", "C1 (kPa)", "Φ (deg)", "load reached (%)", "first failure",
                 "failure kinds (count)", "reason"],
                [[r["scheme"], f"{r['C1']:g}", f"{r['phi']:g}",
                  _pct(r.get("load_fraction")),
                  r.get("first_failure") or "n/a",
                  ", ".join(f"{k} {v}" for k, v in (r.get("failure_kinds") or {}).items()) or "n/a",
                  r.get("reason", "")] for r in failed], table_id="failed-cases"))
        else:
            out.append(_p("Every case of the stability grid converged under every scheme."))
    out.append(_h3("The sweep on its own mesh"))
    out.append(_sweep_stability(ctx))
    out.append(_h3("Surrogate outside its training data"))
    out.append(_extrapolation(ctx))
    return "".join(out)


def _lowest_converging_table(lowest: Mapping[str, Any], table_id: str) -> str:
    """Per Φ and scheme: the lowest converging C1 and the first failure below it."""
    names = list(lowest)
    phis = sorted({k for s in lowest.values() for k in s if k != "all_phi"}, key=float)
    rows = []
    for phi in phis:
        row = [f"{float(phi):g}"]
        for name in names:
            item = lowest[name].get(phi) or {}
            below = item.get("failed_below")
            row.append(_fmt(item.get("lowest_C1"), "g"))
            row.append("—" if not below else
                       f"C1 {_fmt(below.get('C1'), 'g')}: "
                       f"{below.get('first_failure') or 'n/a'} at "
                       f"{_pct(below.get('load_fraction'))} % of the load")
        rows.append(row)
    rows.append(["every Φ"] + [v for name in names
                               for v in (_fmt(lowest[name].get("all_phi"), "g"), "")])
    header = ["Φ (deg)"] + [h for name in names
                            for h in (f"{name}: lowest converging C1 (kPa)",
                                      f"{name}: first failure below it")]
    return _table(header, rows, highlight=[len(rows) - 1], table_id=table_id)


def _sweep_stability(ctx: _Context) -> str:
    """The sweep's convergence over (C1, Φ), on the mesh the dataset was solved on."""
    from studies.stability import lowest_converging, sweep_records

    columns = ctx.case_columns()
    if not columns:
        return _missing("results/dataset/dataset.h5")
    keys = ("C1", "phi", "theta", "converged", "load_fraction", "first_failure", "reason",
            "min_detF")
    if any(k not in columns for k in keys):
        return _p("The dataset predates the first-failure record; rebuild it "
                  "(snakemake --forcerun aggregate) to map the sweep's failures.", "note")
    cases = {k: columns[k] for k in keys}
    records = sweep_records(cases)
    if not records:
        return _p("The sweep has no case at θ = 0, so there is no (C1, Φ) map of it.", "note")
    failed = ~cases["converged"].astype(bool)
    out = [_p(
        f"The sweep itself is a stability map at the paper's resolution, solved on the mesh "
        f"of the dataset: {int(failed.sum())} of {len(failed)} cases did not reach the full "
        "load. Per Φ: the lowest C1 from which every stiffer C1 of the sweep converged, and "
        "what failed first at the next C1 below it (\"—\": every C1 of the sweep converged).",
        "caption")]
    out.append(_lowest_converging_table(lowest_converging(records), "sweep-lowest-converging"))
    if failed.any():
        rows = [[f"{cases['C1'][i]:g}", f"{cases['phi'][i]:g}", f"{cases['theta'][i]:g}",
                 _pct(cases["load_fraction"][i]), cases["first_failure"][i] or "n/a",
                 _fmt(cases["min_detF"][i], ".2g"), cases["reason"][i]]
                for i in np.flatnonzero(failed)]
        out.append(_table(["C1 (kPa)", "Φ (deg)", "θ (deg)", "load reached (%)",
                           "first failure", "min det F of the last converged state", "reason"],
                          rows, table_id="sweep-failed-cases"))
    out.append(_sweep_contact_and_overlap(columns, failed))
    return "".join(out)


def _cases_end(n: int) -> str:
    """'1 case ends' or 'n cases end'."""
    return f"{n} case ends" if n == 1 else f"{n} cases end"


def _sweep_contact_and_overlap(columns: dict[str, np.ndarray], failed: np.ndarray) -> str:
    """Which cases end in contact with the chest, and which pass through themselves."""
    def case(i: int) -> str:
        return f"C1 = {columns['C1'][i]:g} kPa at Φ = {columns['phi'][i]:g}°"

    out = []
    if "contact_force_N" in columns:
        force = np.asarray(columns["contact_force_N"], dtype=float)
        if np.isnan(force).all():
            out.append("The sweep was solved without contact (fe.contact): nothing "
                       "keeps the skin out of the chest below the fold.")
        else:
            touching = np.flatnonzero(np.nan_to_num(force) > 0)
            largest = (f", the largest force {force[touching].max():.2g} N "
                       f"({case(touching[np.argmax(force[touching])])})" if len(touching) else "")
            out.append("Solved with contact of the skin with the chest: "
                       f"{_cases_end(len(touching))} in contact{largest}.")
    if "self_overlap" in columns:
        overlap = np.asarray(columns["self_overlap"])
        through = np.flatnonzero(overlap > 0)
        if len(through):
            itself = "itself" if len(through) == 1 else "themselves"
            out.append(f"{_cases_end(len(through))} passing through {itself} (boundary vertices "
                       "inside another cell: the fold's skin creasing into itself), "
                       + ", ".join(f"{case(i)} ({overlap[i]}{', failed' if failed[i] else ''})"
                                   for i in through) + ".")
        else:
            out.append("No case ends passing through itself.")
    return _p(" ".join(out), "caption") if out else ""


def _extrapolation(ctx: _Context) -> str:
    extra = ctx.json.get("extrapolation")
    if extra is None:
        return _missing("results/surrogate/extrapolation.json")
    splits = [s for s in ("by_sample", "by_case") if (extra.get(s) or {}).get("rows")]
    if not splits:
        failed = sum(len((extra.get(s) or {}).get("failed_fe") or []) for s in extra)
        return _p(f"No extrapolation case was compared ({failed} FE solves outside the sweep "
                  "failed).", "note")
    ids = list(dict.fromkeys(r["case"] for s in splits for r in extra[s]["rows"]))
    rows_of = {s: {r["case"]: r for r in extra[s]["rows"]} for s in splits}
    first = {cid: next(rows_of[s][cid] for s in splits if cid in rows_of[s]) for cid in ids}
    labels = [f"C1 {first[c]['C1']:g} kPa, Φ {first[c]['phi']:g}°, θ {first[c]['theta']:g}°\n"
              f"({first[c].get('kind', 'n/a')})" for c in ids]
    series: dict[str, list[float | None]] = {}
    for s in splits:
        name = s.replace("_", "-")
        series[f"{name} model at the case"] = [rows_of[s].get(c, {}).get("rmse_mm") for c in ids]
        series[f"{name} model at the nearest sweep case"] = [
            (rows_of[s].get(c, {}).get("nearest_sweep_case") or {}).get("rmse_mm") for c in ids]
    out = [_p(
        "The surrogate asked about cases outside its training data — C1 below "
        f"{PAPER_C1_RANGE[0]:g} or above {PAPER_C1_RANGE[1]:g} kPa (or the sweep's range), "
        "gravity angles Φ it never saw, gravity out of the plane (θ ≠ 0) — against FE "
        "solutions of those cases. Each bar is the mean point error |u − û| (the paper's Eq. "
        "3); beside it, the same model's error at the nearest case of the sweep, so that the "
        "growth of error outside the data can be read off. The label under each case says "
        f"how it lies outside the {splits[0].replace('_', '-')} model's training data; the "
        "by-case model never saw the clinical cases, so its training range can be narrower "
        "(the table gives both).", "caption")]
    out.append(ctx.figure(
        "extrapolation.png",
        lambda p: surrogate_plots.plot_extrapolation(labels, series, p),
        "surrogate error outside the training data",
        "Mean error per extrapolation case (log), next to the nearest sweep case's error."))
    rows = []
    for cid, label in zip(ids, labels):
        fe_range = first[cid].get("fe_range_mm") or [None, None]
        row = [label.split("\n")[0], _fmt(fe_range[-1], ".3g")]
        for s in splits:
            r = rows_of[s].get(cid, {})
            near = r.get("nearest_sweep_case") or {}
            row += [r.get("kind", "n/a"), _fmt(r.get("rmse_mm"), ".3g"),
                    _fmt(r.get("max_error_mm"), ".3g"), _fmt(near.get("rmse_mm"), ".3g"),
                    _fmt(r.get("error_ratio_to_nearest"), ".3g")]
        rows.append(row)
    header = ["case", "FE max |u| (mm)"]
    for s in splits:
        name = s.replace("_", "-")
        header += [f"{name}: outside its training by", f"{name}: mean error (mm)",
                   f"{name}: max error (mm)", f"{name}: at nearest sweep case (mm)",
                   f"{name}: ratio"]
    out.append(_table(header, rows, table_id="extrapolation"))
    failed = [f for s in splits for f in (extra[s].get("failed_fe") or [])]
    if failed:
        out.append(_p("FE solves outside the sweep that failed (no comparison): " + "; ".join(
            f"{f.get('case')}: {f.get('reason', '')}" for f in failed), "note"))
    return "".join(out)


# -- the paper side by side ---------------------------------------------------------------------
def _table2(ctx: _Context) -> str:
    table = ctx.json.get("table2")
    if table is None:
        return _missing("results/surrogate/study/table2.json")
    ours = table.get("rows") or {}
    selected = table.get("selected_architecture")
    names = sorted(set(ours) | set(paper.TABLE2), key=parse_architecture)
    rows, highlight = [], []
    for i, name in enumerate(names):
        row = ours.get(name) or {}
        published = paper.TABLE2.get(name) or {}
        err, train = row.get("validation_error_mm") or {}, row.get("train_s") or {}
        p_err, p_train = published.get("validation_error_mm"), published.get("train_s")
        mark = []
        if name == selected:
            mark.append("selected by us")
            highlight.append(i)
        if name == paper.BEST_ARCHITECTURE:
            mark.append("selected by the paper")
        if name == table.get("most_accurate_architecture") and name != selected:
            mark.append("most accurate, over the prediction budget")
        rows.append([name, _fmt(row.get("parameters"), "d"), _fmt(row.get("runs"), "d"),
                     _pm(err.get("mean"), err.get("sd"), ".3f"),
                     _pm(*p_err, ".2f") if p_err else "n/a",
                     _pm(train.get("mean"), train.get("sd"), ".3g"),
                     _pm(*p_train, ".0f") if p_train else "n/a",
                     _fmt((row.get("epochs") or {}).get("mean"), ".0f"),
                     _fmt(1e3 * _predict_s(row) if _predict_s(row) is not None else None, ".3g"),
                     "; ".join(mark)])
    return "".join([
        _h3("Table 2: architecture study"),
        _p("Validation error (mean |u − û| over the validation points, mean ± SD over the "
           "repeats) and training time per architecture (hidden layers × width), ours beside "
           "the paper's (trained on an NVIDIA V100). Our prediction time is one whole-field "
           "prediction on one CPU core. The highlighted row is our selection: "
           f"{table.get('rule', 'n/a')}.", "caption"),
        _table(["architecture", "parameters", "runs", "validation error (mm)",
                "paper: validation error (mm)", "training time (s)", "paper: training time (s)",
                "epochs", "prediction (ms)", "selected"], rows, highlight, table_id="table2"),
    ])


def _table3(ctx: _Context) -> str:
    clinical = ctx.json.get("clinical")
    out = [_h3("Table 3: clinical cases")]
    if clinical is None:
        return "".join(out) + _missing("results/surrogate/clinical.json")
    out.append(_p(
        "Mean displacement and displacement range of the FE and the surrogate, and the "
        "surrogate's error as the paper's Eq. 3 (mean over the points of |u − û|, ± SD), "
        "ours beside the paper's, for each clinical case. The by-sample model trained on "
        "points of every case (the paper's split); the by-case model never saw the clinical "
        "cases.", "caption"))
    for split in ("by_sample", "by_case"):
        block = clinical.get(split)
        if not block or not block.get("rows"):
            continue
        cases = block["rows"]
        published = [paper.table3_row(r["C1"], r["phi"]) or {} for r in cases]
        metrics = [
            ("FE mean displacement (mm)", lambda r: _fmt(r.get("fe_mean_mm"), ".3g"),
             lambda p: _fmt(p.get("fe_mean_mm"), ".3g")),
            ("FE displacement range (mm)", lambda r: _range(r.get("fe_range_mm")),
             lambda p: _range(p.get("fe_range_mm"))),
            ("surrogate mean displacement (mm)", lambda r: _fmt(r.get("surrogate_mean_mm"), ".3g"),
             lambda p: _fmt(p.get("surrogate_mean_mm"), ".3g")),
            ("RMSE ± SD (mm, Eq. 3)", lambda r: _pm(r.get("rmse_mm"), r.get("sd_mm")),
             lambda p: _pm(p.get("rmse_mm"), p.get("sd_mm"))),
            ("surrogate displacement range (mm)", lambda r: _range(r.get("surrogate_range_mm")),
             lambda p: _range(p.get("surrogate_range_mm"))),
        ]
        rows = []
        for name, ours, theirs in metrics:
            rows.append([f"{name}: ours"] + [ours(r) for r in cases])
            rows.append([f"{name}: paper"] + [theirs(p) for p in published])
        rows.append(["max error (mm): ours"] + [_fmt(r.get("max_error_mm"), ".3g") for r in cases])
        rows.append(["max error (mm): paper (Fig. 5 caption)"] + [
            _fmt(paper.fig5_max_error_mm(r["C1"], r["phi"]), ".3g") for r in cases])
        out.append(_p(f"{split.replace('_', '-')} model ({block.get('architecture', 'n/a')}, "
                      f"boundary: {block.get('boundary', 'n/a')}):"))
        out.append(_table(["metric"] + [r.get("label", r["case"]) for r in cases], rows,
                          highlight=range(0, len(rows), 2), table_id=f"table3-{split}"))
    return "".join(out)


def _table4(ctx: _Context) -> str:
    bench = ctx.json.get("benchmark")
    out = [_h3("Table 4: wall time per case")]
    if bench is None:
        return "".join(out) + _missing("results/surrogate/benchmark.json")
    speed = bench.get("speed") or []
    if not speed:
        return "".join(out) + _p("The benchmark holds no timed case.", "note")
    items = {_case_id(c): c for c in ctx.clinical}
    published = []
    for row in speed:
        item = items.get(row["case"])
        published.append(paper.table4_row(item["C1"], item["phi"]) if item else None)
    out.append(_p(
        "Wall time of one FE solve (set-up excluded) and one surrogate prediction, both on the "
        "same pinned CPU core in one job, ours beside the paper's (an Intel Core i7 at 2.3 GHz, "
        "mean ± SD), and the speed-up FE / surrogate.", "caption"))
    rows = [
        ["FE: ours"] + [_seconds(r.get("fe_solve_s")) for r in speed],
        ["FE: paper"] + [_pm(*p["fe_s"], ".3g") + " s" if p else "n/a" for p in published],
        ["surrogate: ours"] + [_seconds(1e-3 * r["surrogate_ms"]) if _finite(r.get("surrogate_ms"))
                               else "n/a" for r in speed],
        ["surrogate: paper"] + [_pm(*p["surrogate_s"], ".3g") + " s" if p else "n/a"
                                for p in published],
        ["speed-up: ours"] + [_times(r.get("speedup")) for r in speed],
        ["speed-up: paper"] + [_times(p["fe_s"][0] / p["surrogate_s"][0]) if p else "n/a"
                               for p in published],
    ]
    out.append(_table(["model"] + [ctx.case_label(r["case"]) for r in speed], rows,
                      highlight=(0, 2, 4), table_id="table4"))
    machine = bench.get("machine") or {}
    out.append(_p(f"Machine: {machine.get('processor', 'n/a')}, {machine.get('cpus', 'n/a')} CPUs, "
                  f"pinned core {machine.get('pinned_core', 'n/a')}, load average "
                  f"{_fmt((machine.get('loadavg') or [None])[0], '.2f')}.", "note"))
    goals = bench.get("goals") or {}
    if goals:
        out.append(_table(["benchmark goal", "value", "goal", "met"],
                          [[GOAL_NAMES.get(k, k.replace("_", " ")), _fmt(g.get("value"), ".4g"),
                            _fmt(g.get("goal"), "g"),
                            _yes(g.get("met"))] for k, g in goals.items()], table_id="goals"))
    return "".join(out)


def _read_point_fields(path: Path) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    import meshio

    mesh = meshio.read(str(path))
    return np.asarray(mesh.points), {k: np.asarray(v) for k, v in mesh.point_data.items()}


def _figure5(ctx: _Context) -> str:
    out = [_h3("Figure 5: displacement and surrogate error on the material points")]
    by_key = {(p.parent.name, p.stem): p for p in ctx.clinical_fields if p.suffix == ".xdmf"}
    clinical = ctx.json.get("clinical") or {}
    rows = {s: {r["case"]: r for r in (clinical.get(s) or {}).get("rows") or []}
            for s in ("by_sample", "by_case")}
    out.append(_p(
        "For each clinical case, the material points seen from the front (projected on the "
        "y–z plane, the front-most point of each line of sight drawn on top): the FE "
        "displacement magnitude |u|, and the magnitude of the surrogate's error |u − û| for "
        "the by-sample and the by-case model. Each panel has its own colour bar in mm; the "
        "table below gives the largest error beside the paper's Fig. 5 caption.", "caption"))
    figures, table_rows = [], []
    for item in ctx.clinical:
        cid = _case_id(item)
        label = str(item.get("label", cid))
        panels: list[tuple[np.ndarray, str]] = []
        X = None
        for split in ("by_sample", "by_case"):
            path = by_key.get((split, cid))
            if path is None or not path.is_file():
                continue
            points, data = _read_point_fields(path)
            if X is None:
                X = points
                panels.append((data["fe_displacement_norm_mm"], "FE displacement |u|"))
            panels.append((data["error_norm_mm"], f"{split.replace('_', '-')} error |u − û|"))
        if X is None:
            figures.append(_p(f"{label}: no error field among the inputs.", "note"))
            continue
        name = f"fig5_{re.sub(r'[^A-Za-z0-9.-]+', '_', cid)}.png"
        figures.append(ctx.figure(name, lambda p, X=X, panels=panels, label=label:
                                  surrogate_plots.plot_point_fields(X, panels, p, label),
                                  f"FE displacement and surrogate error, {label}",
                                  f"{label}: FE |u| and surrogate error, seen from the front."))
        paper_max = paper.fig5_max_error_mm(item["C1"], item["phi"])
        table_rows.append([label] + [
            _fmt(rows[s].get(cid, {}).get("max_error_mm"), ".3g") for s in ("by_sample", "by_case")
        ] + [_fmt(paper_max, ".3g")])
    out += figures
    if table_rows:
        out.append(_table(["case", "by-sample: max error (mm)", "by-case: max error (mm)",
                           "paper (Fig. 5 caption): max error (mm)"], table_rows,
                          table_id="fig5"))
    return "".join(out)


def _paper_section(ctx: _Context) -> str:
    return "".join([
        _p("The paper's Tables 2–4 and Fig. 5 with our figures beside theirs. Our mesh, "
           "training data and hardware differ from the paper's, so agreement is expected in "
           "magnitude and trend, not digit by digit.", "caption"),
        _table2(ctx), _table3(ctx), _table4(ctx), _figure5(ctx),
    ])


def _sweep_cost_section(ctx: _Context) -> str:
    ds = ctx.dataset()
    if ds is None:
        return _missing("results/dataset/dataset.h5")
    columns = ctx.case_columns()
    wall = columns.get("wall_s")
    steps = columns.get("load_steps")
    its = columns.get("newton_iterations")
    if wall is None:
        return _p("The dataset holds no solve times.", "note")
    out = [_p(
        "The FE solve wall time of every case of the sweep over stiffness C1 and gravity "
        "angle Φ: one square per case, its colour the time in seconds (colour bar); a red "
        "cross marks a case that failed. The table gives the totals.", "caption")]
    out.append(ctx.figure(
        "sweep_cost.png",
        lambda p: fem_plots.plot_sweep_map(ds.C1, ds.phi, wall, p, "FE solve wall time (s)",
                                           failed=~ds.converged, title="FE cost per case"),
        "FE solve time per case over C1 and gravity angle", "FE solve time per case."))
    rows = [
        ["cases", f"{len(wall)}"],
        ["converged", f"{int(ds.converged.sum())}"],
        ["total solve time", _seconds(float(np.nansum(wall)))],
        ["median per case", _seconds(float(np.nanmedian(wall)))],
        ["slowest case", _seconds(float(np.nanmax(wall)))],
    ]
    if steps is not None:
        rows.append(["load steps (min–max)", f"{int(steps.min())}–{int(steps.max())}"])
    if its is not None:
        rows.append(["Newton iterations (min–max)", f"{int(its.min())}–{int(its.max())}"])
    out.append(_table(["sweep", "value"], rows, table_id="sweep-cost"))
    return "".join(out)


def _training_section(ctx: _Context) -> str:
    history = ctx.json.get("history")
    if history is None:
        return _missing("results/surrogate/model/history.json")
    summary = history.get("summary") or {}
    arch = summary.get("architecture", "n/a")
    out = [_p(
        "The selected model's training: the loss (the paper's Eq. 2) on the training and "
        "validation samples, and the validation error in mm, per epoch. Training stops when "
        "the validation loss has not improved for the configured patience; the best epoch's "
        "weights are kept.", "caption")]
    if history.get("history"):
        out.append(ctx.figure(
            "training_history.png",
            lambda p: surrogate_plots.plot_history(
                history["history"], p, f"training of the selected model ({arch})",
                summary.get("best_epoch") if _finite(summary.get("best_epoch")) else None),
            "training history", f"Training history of the selected model ({arch})."))
    out.append(_table(["quantity", "value"], [
        ["architecture", arch], ["boundary", summary.get("boundary", "n/a")],
        ["split", summary.get("split", "n/a")], ["seed", summary.get("seed", "n/a")],
        ["epochs (best epoch)",
         f"{_fmt(summary.get('epochs'), 'd')} ({_fmt(summary.get('best_epoch'), 'd')})"],
        ["validation error (mm)", _fmt(summary.get("validation_error_mm"), ".4g")],
        ["training time", _seconds(summary.get("train_s"))],
        ["training cases", _fmt(summary.get("n_train_cases"), "d")],
        ["training range", _training_range((ctx.json.get("model") or {}).get("training_range"))],
    ], table_id="training"))
    return "".join(out)


def _training_range(rng: Mapping[str, Any] | None) -> str:
    if not rng:
        return "n/a"
    parts = []
    if rng.get("C1_kPa"):
        parts.append(f"C1 {_range(rng['C1_kPa'], 'g')} kPa")
    for key, name in (("phi_deg", "Φ"), ("theta_deg", "θ")):
        if rng.get(key):
            parts.append(f"{name} ∈ {{{', '.join(f'{v:g}' for v in rng[key])}}}°")
    return "; ".join(parts) or "n/a"


_BUILDERS: dict[str, Callable[[_Context], str]] = {
    "mesh": _mesh_section,
    "fe-speed-accuracy": _fe_speed_accuracy_section,
    "surrogate-speed-accuracy": _surrogate_speed_accuracy_section,
    "scene-needs": _scene_needs_section,
    "stability": _stability_section,
    "paper": _paper_section,
    "sweep-cost": _sweep_cost_section,
    "training": _training_section,
}

_JSON_INPUTS = ("quality", "model", "history", "table2", "variants", "clinical", "extrapolation",
                "benchmark", "fe_clinical", "fe_speed_accuracy", "fe_stability")


def build_report(
    inputs: Mapping[str, Any], html_path: str | Path, clinical: Sequence[Mapping[str, Any]]
) -> Path:
    """Write the report page and its figures.

    Args:
        inputs: paths by the names of :data:`INPUT_NAMES` (the report rule's named inputs);
            a name that is absent leaves its part of the page as a note.
            ``clinical_fields`` is a list of the clinical error fields
            (``.../{by_sample,by_case}/<case>.xdmf`` with their ``.h5``).
        html_path: the page to write; the PNG figures are written beside it.
        clinical: the config's ``clinical`` entries (``C1``, ``phi``, ``theta``, ``label``).

    Returns:
        The page's path.
    """
    html_path = Path(html_path)
    out_dir = html_path.parent
    out_dir.mkdir(parents=True, exist_ok=True)
    unknown = sorted(set(inputs) - set(INPUT_NAMES))
    if unknown:
        log.warning("report inputs not used: %s", ", ".join(unknown))
    fields = inputs.get("clinical_fields") or []
    if isinstance(fields, (str, Path)):
        fields = [fields]
    ctx = _Context(
        out_dir=out_dir,
        clinical=[dict(c) for c in clinical],
        paths={name: _as_path(inputs.get(name)) for name in INPUT_NAMES
               if name != "clinical_fields"},
        clinical_fields=[Path(str(p)) for p in fields],
    )
    ctx.json = {name: _read_json(ctx.paths.get(name)) for name in _JSON_INPUTS}
    body = []
    for section_id, title in SECTIONS:
        try:
            content = _BUILDERS[section_id](ctx)
        except (KeyError, TypeError, ValueError, IndexError, OSError) as err:
            # one section's unexpected input must not cost the whole page; the page says so
            log.exception("section %r could not be built", title)
            content = _p(f"This section could not be built: {type(err).__name__}: {err}", "error")
        body.append(f'<section id="{section_id}"><h2>{_e(title)}</h2>{content}</section>')
    toc = "".join(f'<li><a href="#{sid}">{_e(title)}</a></li>' for sid, title in SECTIONS)
    page = (
        '<!doctype html><html lang="en"><head><meta charset="utf-8">'
        "<title>Breast biomechanics under gravity: FE and surrogate report</title>"
        f"<style>{STYLE}</style></head><body>"
        "<h1>Breast biomechanics under gravity: FE and surrogate report</h1>"
        + _p("Both speed and accuracy count: this page charts one against the other for the "
             "finite-element (FE) model and the neural-network surrogate, tests where the "
             "solvers fail, says which model a given accuracy need calls for, and sets our "
             "results beside the paper's (Babarenda Gamage et al.). Every number comes from "
             "the workflow's result files.")
        + f"<nav><ol>{toc}</ol></nav>" + "".join(body) + "</body></html>\n"
    )
    html_path.write_text(page)
    log.info("wrote %s with %d sections", html_path, len(SECTIONS))
    return html_path


__all__ = ["NEEDS_MM", "SECTIONS", "Candidate", "build_report", "c1_effect", "candidates",
           "variant_label"]
