"""The report's H2-H4 sections: the two-way mixed ANOVAs of difficulty by each
between-subjects factor, their simple effects, and the Likert rank tests."""

from __future__ import annotations

from typing import Any

from cfteach.analysis.io import DIFFICULTIES, LIKERT_ITEMS
from cfteach.analysis.report_doc import Doc
from cfteach.analysis.report_format import ci_text, fmt_df, fmt_F, fmt_num, fmt_p, level_name


def _effects_table(doc: Doc, res: dict[str, Any]) -> None:
    rows = []
    for key in ("between", "within", "interaction"):
        e = res["effects"].get(key)
        if not e:
            continue
        rows.append(
            [
                e["source"],
                fmt_df(e["df1"]),
                fmt_df(e["df2"]),
                fmt_num(e["F"]),
                fmt_p(e["p"]),
                fmt_p(e["p_gg"]) if e["p_gg"] is not None else "",
                fmt_num(e["np2"], 3, lead=False),
                ci_text(e.get("np2_ci95"), 3),
            ]
        )
    doc.table(["Source", "df1", "df2", "F", "p", "p (GG)", "ηp²", "ηp² 95% CI"], rows)


def _means_table(doc: Doc, factor: str, means: list[dict[str, Any]]) -> None:
    by: dict[str, dict[str, dict[str, Any]]] = {}
    for m in means:
        by.setdefault(m["level"], {})[m["difficulty"]] = m
    rows = []
    for lvl, d in by.items():
        cells = []
        for diff in DIFFICULTIES:
            m = d[diff]
            ci = m["ci95"]
            cells.append(
                f"{fmt_num(m['mean'])} [{fmt_num(ci[0])}, {fmt_num(ci[1])}]"
                if m["mean"] is not None
                else "n/a"
            )
        rows.append([level_name(factor, lvl), str(d[DIFFICULTIES[0]]["n"]), *cells])
    doc.table(["Group", "N", *(f"{d} M [95% CI]" for d in DIFFICULTIES)], rows)


def _tukey_table(doc: Doc, factor: str, rows: list[dict], with_diff: bool, holm: bool) -> None:
    out = []
    for r in rows:
        row = [r["difficulty"]] if with_diff else []
        row += [
            level_name(factor, r["A"]),
            level_name(factor, r["B"]),
            fmt_num(r["mean_A"]),
            fmt_num(r["mean_B"]),
            fmt_num(r["T"]),
            fmt_p(r["p_tukey"]),
        ]
        if holm:
            row.append(fmt_p(r.get("p_holm_across")))
        out.append(row)
    hdr = (["Difficulty"] if with_diff else []) + ["A", "B", "M A", "M B", "T", "p (Tukey)"]
    if holm:
        hdr.append("p (Holm across difficulties)")
    doc.table(hdr, out)


def _mwu_sentence(name_x: str, name_y: str, r: dict[str, Any]) -> str:
    return (
        f"U(N_{name_x} = {r['n_x']}, N_{name_y} = {r['n_y']}) = {fmt_num(r['U'], 1)}, "
        f"{fmt_p(r['p'])}, r_rb = {fmt_num(r['rbc'], 2, lead=False)} "
        f"(Mdn {fmt_num(r['median_x'], 1)} vs {fmt_num(r['median_y'], 1)})"
    )


def _within_test(e: dict[str, Any]) -> str:
    """A within term's F: GG-corrected df and p when Mauchly's test rejects sphericity."""
    mp, eps = e.get("mauchly_p"), e.get("eps_gg")
    if mp is None or mp >= 0.05 or eps is None or e.get("p_gg") is None:
        return fmt_F(e["df1"], e["df2"], e["F"], e["p"])
    gg = fmt_F(e["df1"] * eps, e["df2"] * eps, e["F"], e["p_gg"])
    return f"{gg} (Greenhouse-Geisser; sphericity rejected, {fmt_p(mp)})"


def mixed_section(doc: Doc, factor: str, label: str, res: dict[str, Any]) -> None:
    inter, betw = res["effects"]["interaction"], res["effects"]["between"]
    doc.p(
        f"Two-way mixed ANOVA (N = {res['n_participants']}; "
        + ", ".join(f"{level_name(factor, k)}: {v}" for k, v in res["n_by_level"].items())
        + "). Interaction: "
        + _within_test(inter)
        + f"; main effect of {label}: "
        + fmt_F(betw["df1"], betw["df2"], betw["F"], betw["p"])
        + "."
    )
    _effects_table(doc, res)
    _means_table(doc, factor, res["means"])
    two = factor != "condition"
    doc.p(
        "Simple effects at each difficulty: Tukey HSD between groups on that difficulty's "
        "participant means"
        + (" (two groups: equal to Student's t-test)" if two else "")
        + "; the last column adjusts each comparison across the three difficulties (Holm), "
        "and that is the p to use."
    )
    _tukey_table(doc, factor, res["simple_effects"]["rows"], with_diff=True, holm=True)
    if "overall_pairwise" in res:
        doc.p(
            "Overall pairwise comparison of conditions (Tukey HSD on each participant's "
            "mean over all tests, one value per participant)."
        )
        _tukey_table(doc, factor, res["overall_pairwise"]["rows"], False, False)


def likert_section(doc: Doc, factor: str, lk: dict[str, Any]) -> None:
    if factor in ("counterfactual", "feature_scaffolding"):
        names = ("without", "with")
        for item in LIKERT_ITEMS:
            name = item.replace("_", " ").capitalize()
            r = lk[item] if "skipped" in lk[item] else lk[item][factor]
            if "skipped" in r:
                doc.p(f"{name}: Mann-Whitney U skipped ({r['skipped']}).")
                continue
            doc.p(
                f"{name} (Mann-Whitney U, per-participant median over domains): "
                + _mwu_sentence(*names, r)
                + "."
            )
    else:
        for item in LIKERT_ITEMS:
            kw = lk[item] if "skipped" in lk[item] else lk[item]["condition"]
            name = item.replace("_", " ").capitalize()
            if "skipped" in kw:
                doc.p(f"{name}: Kruskal-Wallis skipped ({kw['skipped']}).")
                continue
            doc.p(
                f"{name}: Kruskal-Wallis H({fmt_df(kw['df'])}) = {fmt_num(kw['H'])}, "
                f"{fmt_p(kw['p'])}, ε² = {fmt_num(kw['epsilon_sq'], 3, lead=False)}, "
                f"N = {kw['n']}; medians "
                + ", ".join(
                    f"{level_name('condition', c)} {fmt_num(m, 1)}"
                    for c, m in kw["medians"].items()
                )
                + "."
            )
            doc.table(
                ["A", "B", "U", "p (unc.)", f"p ({lk['padjust']})", "Mdn A", "Mdn B"],
                [
                    [
                        level_name("condition", r["A"]),
                        level_name("condition", r["B"]),
                        fmt_num(r["U"], 1),
                        fmt_p(r["p"]),
                        fmt_p(r["p_corr"]),
                        fmt_num(r["median_x"], 1),
                        fmt_num(r["median_y"], 1),
                    ]
                    for r in lk[item]["condition_pairwise"]["rows"]
                ],
            )
