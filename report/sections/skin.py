"""What the skin changes: the clinical cases homogeneous and with the skin membrane."""

from __future__ import annotations

from collections.abc import Sequence

from report.context import Context
from report.html import fmt, h3, missing, para, table
from studies.fe_study.skin import SkinCase, SkinSetting, SkinStudy, TumourPath
from studies.figures.tissues import plot_skin

HEADER = ["setting", "skin C1 / fat C1", "skin thickness (mm)", "outcome", "load steps",
          "Newton iterations", "solve (s)", "max |u| (mm)", "max |u| / homogeneous"]


def skin_section(ctx: Context) -> str:
    """The cases' max |u| and the tumour's path per setting, a figure, and what holds."""
    study = ctx.results.get("fe_skin")
    if study is None:
        return missing("results/fe_study/skin.json")
    default = study.varying("default")[0]
    case_ids = list(dict.fromkeys(c.case for c in study.cases))
    out = [para(
        "What the skin changes: the clinical cases on the workflow's mesh without skin "
        "(homogeneous) and with the skin as a membrane on the skin boundary "
        f"({_describe(default)}: material.tissues.skin and material.skin, else the defaults of "
        "docs/tissues.md), then with each other ratio of the skin's C1 to the fat's at that "
        "thickness and each other thickness at that ratio (fe_study.skin). The tumour point, "
        f"{_point(study.tumour_mm)} mm in the reference ({study.tumour_from}), is followed "
        "from each prone clinical case (Φ 180°) to the supine one (Φ 0°) of the same C1. "
        f"{study.seconds:.0f} s in all, on one core.", "caption")]
    out.append(para(" ".join(_findings(study, case_ids))))
    labels = {cid: ctx.case_label(cid) for cid in case_ids}
    out.append(ctx.figure(
        "skin.png", lambda p: plot_skin(study.to_json(), p, labels),
        "max |u| and the tumour's prone-to-supine way against the skin's ratio and thickness",
        "Top: each clinical case's max |u| against the skin's ratio to the fat (left, at the "
        "default thickness) and its thickness (right, at the default ratio), the homogeneous "
        "model's dotted; a hollow marker did not converge (the load it reached). Bottom: how "
        "far the tumour point moves from prone to supine at each C1."))
    for cid in case_ids:
        out.append(h3(ctx.case_label(cid)))
        out.append(table(HEADER, [_row(study, s, cid) for s in study.settings],
                         table_id=f"skin-{cid}"))
    out.append(h3("The tumour's way from prone to supine"))
    c1s = sorted({p.C1 for p in study.paths})
    if not c1s:
        out.append(para("The clinical cases hold no prone (Φ 180°) and supine (Φ 0°) case of "
                        "one C1: there is no way to follow.", "note"))
        return "".join(out)
    header = ["setting"] + [f"C1 = {c1:g} kPa: {what}" for c1 in c1s
                            for what in ("distance (mm)", "supine − prone, x, y, z (mm)")]
    rows = []
    for setting in study.settings:
        row = [setting.name]
        for c1 in c1s:
            path = next((p for p in study.paths if p.setting == setting.name and p.C1 == c1),
                        None)
            row += _path_cells(study, path)
        rows.append(row)
    out.append(table(header, rows, table_id="skin-tumour"))
    return "".join(out)


def _describe(setting: SkinSetting) -> str:
    wrinkles = "wrinkling" if setting.wrinkles else "not wrinkling"
    return (f"{setting.ratio:g} × the fat's C1, {1e3 * setting.thickness_m:g} mm thick, "
            f"{wrinkles}")


def _point(mm: Sequence[float]) -> str:
    return "(" + ", ".join(f"{x:.1f}" for x in mm) + ")"


def _outcome(case: SkinCase) -> str:
    return "converged" if case.converged else \
        f"not converged (stopped at λ = {case.load_fraction:.3f})"


def _row(study: SkinStudy, setting: SkinSetting, cid: str) -> list[str]:
    case = study.case(setting.name, cid)
    ratio = "none" if setting.ratio is None else f"{setting.ratio:g}"
    thickness = "none" if setting.thickness_m is None else f"{1e3 * setting.thickness_m:g}"
    if case is None:
        return [setting.name, ratio, thickness, "not solved", *["—"] * 5]
    base = study.case("homogeneous", cid)
    if not case.converged:
        relative = "not converged"
    elif base is None or not base.converged:
        relative = "homogeneous not converged"
    else:
        relative = fmt(case.max_disp_mm / base.max_disp_mm, ".3f")
    disp = fmt(case.max_disp_mm, ".2f") + ("" if case.converged else " (not converged)")
    return [setting.name, ratio, thickness, _outcome(case), str(case.load_steps),
            str(case.newton_iterations), fmt(case.wall_s, ".1f"), disp, relative]


def _path_cells(study: SkinStudy, path: TumourPath | None) -> list[str]:
    if path is None:
        return ["not solved", "—"]
    if path.distance_mm is None:
        failed = [name for name, cid in (("prone", path.prone), ("supine", path.supine))
                  if not (c := study.case(path.setting, cid)) or not c.converged]
        text = f"not converged ({' and '.join(failed)})"
        return [text, text]
    return [fmt(path.distance_mm, ".2f"), _point(path.vector_mm or [])]


def _ratios(study: SkinStudy, setting: str, case_ids: list[str]) -> list[float]:
    """Each case's max |u| with ``setting`` over the homogeneous one, where both converged."""
    out = []
    for cid in case_ids:
        a, b = study.case(setting, cid), study.case("homogeneous", cid)
        if a and b and a.converged and b.converged:
            out.append(a.max_disp_mm / b.max_disp_mm)
    return out


def _trend(values: list[float]) -> str:
    """``falls``, ``rises`` or ``neither`` (not monotonic) along ``values``."""
    steps = [b - a for a, b in zip(values, values[1:], strict=False)]
    if steps and all(s < 0 for s in steps):
        return "falls"
    if steps and all(s > 0 for s in steps):
        return "rises"
    return "neither"


def _findings(study: SkinStudy, case_ids: list[str]) -> list[str]:
    """What the data say, in words: convergence, the default skin, the trends, the path."""
    out = []
    failed = [f"{c.setting} at {c.case}" for c in study.cases if not c.converged]
    out.append(f"Every case converged with every setting ({len(study.cases)} solves)."
               if not failed else
               f"{len(failed)} of {len(study.cases)} solves did not converge: "
               f"{', '.join(failed)}.")
    ratios = _ratios(study, "skin", case_ids)
    if ratios:
        lo, hi = min(ratios), max(ratios)
        way = ("less than" if hi < 1 else "more than" if lo > 1 else
               "less than in some cases and more than in others")
        out.append(f"The default skin moves the breast {way} the homogeneous model: max |u| "
                   f"{fmt(100 * lo, '.0f')}–{fmt(100 * hi, '.0f')} % of the homogeneous "
                   f"value in the {len(ratios)} case(s) where both converged.")
    for varied, word in (("ratio", "stiffer"), ("thickness", "thicker")):
        series = sorted([*study.varying("default"), *study.varying(varied)],
                        key=lambda s: s.ratio if varied == "ratio" else s.thickness_m)
        if len(series) < 2:
            continue
        trends = []
        for cid in case_ids:
            cases = [study.case(s.name, cid) for s in series]
            if all(c and c.converged for c in cases):
                trends.append(_trend([c.max_disp_mm for c in cases]))
        if not trends:
            continue
        if all(t == "falls" for t in trends):
            out.append(f"A {word} skin moves the breast less, in each of the {len(trends)} "
                       "case(s) that converged with every such setting.")
        elif all(t == "rises" for t in trends):
            out.append(f"A {word} skin moves the breast more, in each of the {len(trends)} "
                       "case(s) that converged with every such setting.")
        else:
            out.append(f"A {word} skin does not change max |u| the same way in every case "
                       f"({trends.count('falls')} of {len(trends)} fall throughout).")
    for c1 in sorted({p.C1 for p in study.paths}):
        pair = {p.setting: p for p in study.paths if p.C1 == c1}
        base, skin = pair.get("homogeneous"), pair.get("skin")
        if base and skin and base.distance_mm is not None and skin.distance_mm is not None:
            out.append(f"At C1 = {c1:g} kPa the tumour moves {skin.distance_mm:.1f} mm from "
                       f"prone to supine with the default skin, against {base.distance_mm:.1f} "
                       "mm homogeneous.")
    return out
