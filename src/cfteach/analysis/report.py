"""The written report: `report.md` and `report.html` from one list of blocks.

Statistics are written the way the paper writes them ("F(2, 422) = 289.78, p < .001");
every number shown here is also in `results.json`.
"""

from __future__ import annotations

import html
from pathlib import Path
from typing import Any

from cfteach.analysis.descriptives import CONDITION_LABELS
from cfteach.analysis.io import DIFFICULTIES, LIKERT_ITEMS

FACTOR_TITLES = {
    "counterfactual": ("H2", "counterfactual scaffolding"),
    "feature_scaffolding": ("H3", "feature scaffolding"),
    "condition": ("H4", "condition (4 levels)"),
}
LEVEL_NAMES: dict[str, dict[str, str]] = {
    "condition": CONDITION_LABELS,
    "counterfactual": {"0": "no counterfactual", "1": "counterfactual"},
    "feature_scaffolding": {"0": "no feature scaffolding", "1": "feature scaffolding"},
}


def fmt_p(p: float | None) -> str:
    """APA-style p: 'p < .001', 'p = .048', 'p > .999'."""
    if p is None:
        return "p = n/a"
    if p < 0.001:
        return "p < .001"
    if p > 0.999:
        return "p > .999"
    return "p = " + f"{p:.3f}".lstrip("0")


def fmt_df(x: float | None) -> str:
    if x is None:
        return "n/a"
    return str(int(round(x))) if abs(x - round(x)) < 1e-9 else f"{x:.2f}"


def fmt_num(x: float | None, digits: int = 2, lead: bool = True) -> str:
    """A number with `digits` decimals; without the leading zero if `lead` is False."""
    if x is None:
        return "n/a"
    s = f"{x:.{digits}f}"
    if not lead:
        s = s.replace("0.", ".", 1) if s.startswith(("0.", "-0.")) else s
    return s


def fmt_F(df1: float | None, df2: float | None, F: float | None, p: float | None) -> str:
    """'F(2, 422) = 289.78, p < .001'."""
    return f"F({fmt_df(df1)}, {fmt_df(df2)}) = {fmt_num(F)}, {fmt_p(p)}"


def _level(factor: str, lvl: str) -> str:
    return LEVEL_NAMES.get(factor, {}).get(str(lvl), str(lvl))


class Doc:
    """A tiny document model rendered to both Markdown and HTML."""

    def __init__(self) -> None:
        self.blocks: list[tuple] = []

    def h(self, level: int, text: str) -> None:
        self.blocks.append(("h", level, text))

    def p(self, text: str) -> None:
        self.blocks.append(("p", text))

    def table(self, headers: list[str], rows: list[list[str]]) -> None:
        self.blocks.append(("table", headers, rows))

    def img(self, src: str, alt: str) -> None:
        self.blocks.append(("img", src, alt))

    def markdown(self) -> str:
        out = []
        for b in self.blocks:
            if b[0] == "h":
                out.append("#" * b[1] + " " + b[2])
            elif b[0] == "p":
                out.append(b[1])
            elif b[0] == "table":
                hdr, rows = b[1], b[2]
                lines = ["| " + " | ".join(hdr) + " |", "|" + "---|" * len(hdr)]
                lines += ["| " + " | ".join(c.replace("|", "\\|") for c in r) + " |" for r in rows]
                out.append("\n".join(lines))
            elif b[0] == "img":
                out.append(f"![{b[2]}]({b[1]})")
        return "\n\n".join(out) + "\n"

    def html(self, title: str) -> str:
        e = html.escape
        body = []
        for b in self.blocks:
            if b[0] == "h":
                body.append(f"<h{b[1]}>{e(b[2])}</h{b[1]}>")
            elif b[0] == "p":
                body.append(f"<p>{_inline(e(b[1]))}</p>")
            elif b[0] == "table":
                head = "".join(f"<th>{e(c)}</th>" for c in b[1])
                rows = "".join(
                    "<tr>" + "".join(f"<td>{_inline(e(c))}</td>" for c in r) + "</tr>" for r in b[2]
                )
                body.append(f"<table><thead><tr>{head}</tr></thead><tbody>{rows}</tbody></table>")
            elif b[0] == "img":
                body.append(
                    f'<figure><img src="{e(b[1])}" alt="{e(b[2])}">'
                    f"<figcaption>{e(b[2])}</figcaption></figure>"
                )
        css = (
            "body{font-family:system-ui,sans-serif;max-width:1100px;margin:2em auto;"
            "padding:0 1em;line-height:1.45;color:#222}"
            "table{border-collapse:collapse;margin:1em 0;font-size:.9em}"
            "th,td{border:1px solid #ccc;padding:.25em .6em;text-align:left}"
            "th{background:#f3f3f3}img{max-width:100%}figure{margin:1em 0}"
            "figcaption{font-size:.85em;color:#555}"
        )
        return (
            '<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
            f"<title>{e(title)}</title><style>{css}</style></head><body>\n"
            + "\n".join(body)
            + "\n</body></html>\n"
        )


def _inline(escaped: str) -> str:
    """Markdown **bold** and `code` spans to HTML (the only inline markup we emit)."""
    import re

    escaped = re.sub(r"\*\*(.+?)\*\*", r"<strong>\1</strong>", escaped)
    return re.sub(r"`(.+?)`", r"<code>\1</code>", escaped)


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
                _ci_text(e.get("np2_ci95"), 3),
            ]
        )
    doc.table(["Source", "df1", "df2", "F", "p", "p (GG)", "ηp²", "ηp² 95% CI"], rows)


def _means_table(doc: Doc, factor: str, means: list[dict[str, Any]]) -> None:
    by = {}
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
        rows.append([_level(factor, lvl), str(d[DIFFICULTIES[0]]["n"]), *cells])
    doc.table(["Group", "N", *(f"{d} M [95% CI]" for d in DIFFICULTIES)], rows)


def _tukey_table(doc: Doc, factor: str, rows: list[dict], with_diff: bool, holm: bool) -> None:
    out = []
    for r in rows:
        row = [r["difficulty"]] if with_diff else []
        row += [
            _level(factor, r["A"]),
            _level(factor, r["B"]),
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


def _mixed_section(doc: Doc, factor: str, label: str, res: dict[str, Any]) -> None:
    inter, betw = res["effects"]["interaction"], res["effects"]["between"]
    doc.p(
        f"Two-way mixed ANOVA (N = {res['n_participants']}; "
        + ", ".join(f"{_level(factor, k)}: {v}" for k, v in res["n_by_level"].items())
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


def _likert_section(doc: Doc, factor: str, lk: dict[str, Any]) -> None:
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
                    f"{_level('condition', c)} {fmt_num(m, 1)}" for c, m in kw["medians"].items()
                )
                + "."
            )
            doc.table(
                ["A", "B", "U", "p (unc.)", f"p ({lk['padjust']})", "Mdn A", "Mdn B"],
                [
                    [
                        _level("condition", r["A"]),
                        _level("condition", r["B"]),
                        fmt_num(r["U"], 1),
                        fmt_p(r["p"]),
                        fmt_p(r["p_corr"]),
                        fmt_num(r["median_x"], 1),
                        fmt_num(r["median_y"], 1),
                    ]
                    for r in lk[item]["condition_pairwise"]["rows"]
                ],
            )


def _h1_section(doc: Doc, h1: dict[str, Any], figures: dict[str, list[str]]) -> None:
    rm = h1["rm_anova"]
    doc.h(2, "H1: test difficulty")
    if "skipped" in rm:
        doc.p(f"Repeated-measures ANOVA not computed: {rm['skipped']}.")
    else:
        _rm_anova_text(doc, rm)
    ph = h1["posthoc"]["paired"]
    if "skipped" in ph:
        doc.p(f"Post hoc paired t-tests not computed: {ph['skipped']}.")
    else:
        _posthoc_tables(doc, h1)
    if "difficulty" in figures:
        doc.img(f"figures/{figures['difficulty'][0]}", "Proportion optimal by test difficulty")
    sp = h1["spearman"]
    if "skipped" in sp:
        doc.p(f"Spearman correlation of confidence with difficulty not computed: {sp['skipped']}.")
    else:
        _spearman_text(doc, sp)
    _rm_corr_text(doc, h1.get("rm_corr"))
    if "confidence" in figures:
        doc.img(f"figures/{figures['confidence'][0]}", "Confidence by test difficulty")


def _rm_anova_text(doc: Doc, rm: dict[str, Any]) -> None:
    doc.p(
        "A one-way repeated-measures ANOVA on the proportion of optimal responses: "
        + fmt_F(rm["df1"], rm["df2"], rm["F"], rm["p"])
        + f", η²G = {fmt_num(rm['ng2'], 2, lead=False)} (N = {rm['n_participants']} "
        f"participants, {rm['n_observations']} test responses). Mauchly's W = "
        f"{fmt_num(rm['mauchly_W'])}, {fmt_p(rm['mauchly_p'])}; Greenhouse-Geisser "
        f"ε = {fmt_num(rm['eps_gg'])}, corrected {fmt_p(rm['p_gg'])}." + _gg_sentence(rm)
    )
    doc.table(
        ["Difficulty", "N", "M", "SD", "95% CI"],
        [
            [
                d,
                str(m["n"]),
                fmt_num(m["mean"]),
                fmt_num(m["sd"]),
                f"[{fmt_num(m['ci95'][0])}, {fmt_num(m['ci95'][1])}]",
            ]
            for d, m in rm["means"].items()
        ],
    )


def _gg_sentence(rm: dict[str, Any]) -> str:
    """When Mauchly rejects sphericity, the GG-corrected test is the one to report."""
    mp, eps = rm.get("mauchly_p"), rm.get("eps_gg")
    if mp is None or mp >= 0.05 or eps is None:
        return ""
    return (
        " Sphericity is rejected, so the test to report is the GG-corrected "
        + fmt_F(rm["df1"] * eps, rm["df2"] * eps, rm["F"], rm["p_gg"])
        + " (the paper reported the uncorrected df)."
    )


def _posthoc_tables(doc: Doc, h1: dict[str, Any]) -> None:
    ph = h1["posthoc"]["paired"]
    doc.p(f"Post hoc: paired t-tests (within-subjects), {ph['padjust']} correction.")
    doc.table(
        [
            "A",
            "B",
            "M A",
            "M B",
            f"t({fmt_df(ph['rows'][0]['dof']) if ph['rows'] else ''})",
            "p (unc.)",
            f"p ({ph['padjust']})",
            "Hedges g [95% CI]",
        ],
        [
            [
                r["A"],
                r["B"],
                fmt_num(r["mean_A"]),
                fmt_num(r["mean_B"]),
                fmt_num(r["T"]),
                fmt_p(r["p_unc"]),
                fmt_p(r["p_corr"]),
                fmt_num(r["hedges"]) + " " + _ci_text(r.get("hedges_ci95"), 2),
            ]
            for r in ph["rows"]
        ],
    )
    at = h1["posthoc"].get("authors_tukey")
    if at:
        doc.p(
            "For comparison, the **authors' variant**: Tukey HSD treating the "
            f"{at['n_observations']} participant × difficulty means as independent groups "
            "(it ignores the pairing, so its p values are not valid for a within factor)."
        )
        doc.table(
            ["A", "B", "M A", "M B", "T", "p (Tukey)"],
            [
                [
                    r["A"],
                    r["B"],
                    fmt_num(r["mean_A"]),
                    fmt_num(r["mean_B"]),
                    fmt_num(r["T"]),
                    fmt_p(r["p_tukey"]),
                ]
                for r in at["rows"]
            ],
        )


def _ci_text(ci: list | None, digits: int) -> str:
    if not ci or ci[0] is None:
        return ""
    return f"[{fmt_num(ci[0], digits, lead=False)}, {fmt_num(ci[1], digits, lead=False)}]"


def _rm_corr_text(doc: Doc, rc: dict[str, Any] | None) -> None:
    if not rc:
        return
    if "skipped" in rc:
        doc.p(f"Repeated-measures correlation not computed: {rc['skipped']}.")
        return
    doc.p(
        "At the right level, the repeated-measures correlation (each participant's three "
        "cells as repeated measures of one person): "
        f"r_rm({fmt_df(rc['dof'])}) = {fmt_num(rc['r'], 2, lead=False)}, 95% CI "
        f"{_ci_text(rc['ci95'], 2)}, {fmt_p(rc['p'])}, {rc['n_participants']} participants. "
        "The paper used the Spearman correlation above, which treats the 3N cells as "
        "independent observations."
    )


def _spearman_text(doc: Doc, sp: dict[str, Any]) -> None:
    doc.p(
        "Spearman's rank correlation of confidence (median per participant × difficulty) "
        f"with difficulty: r_s = {fmt_num(sp['r'], 2, lead=False)}, {fmt_p(sp['p'])}, "
        f"N = {sp['n']}. Median confidence: "
        + ", ".join(
            f"{d} {fmt_num(v, 1)}" for d, v in sp["confidence_median_by_difficulty"].items()
        )
        + "."
    )


TERM_LABELS = {
    "counterfactual": "Counterfactual (CF)",
    "feature_scaffolding": "Feature scaffolding (FS)",
    "difficulty": "Difficulty",
    "counterfactual:feature_scaffolding": "CF × FS",
    "counterfactual:difficulty": "CF × difficulty",
    "feature_scaffolding:difficulty": "FS × difficulty",
    "counterfactual:feature_scaffolding:difficulty": "CF × FS × difficulty",
}


def _full_anova_section(doc: Doc, results: dict[str, Any]) -> None:
    doc.h(2, "Full factorial model: counterfactual × feature scaffolding × difficulty")
    terms = results.get("full_anova") or []
    if not terms:
        doc.p(f"Not computed: {results.get('full_anova_skipped') or 'no data'}.")
        return
    detail = results.get("full_anova_detail", {})
    sph = detail.get("sphericity", {})
    rejected = bool(sph.get("rejected"))
    doc.p(
        "One 2 × 2 (between) × 3 (within) split-plot ANOVA with all seven terms (type III "
        f"sums of squares, sum-to-zero coding; N = {len(results['full_anova_participants'])} "
        "participants with all three difficulties). Mauchly's test of sphericity: "
        f"W = {fmt_num(sph.get('mauchly_W'), 3)}, {fmt_p(sph.get('mauchly_p'))}; "
        f"Greenhouse-Geisser ε = {fmt_num(sph.get('eps_gg'), 3)}. "
        + (
            "Sphericity is rejected, so the within terms are reported with the GG-corrected "
            "df and p."
            if rejected
            else "Sphericity is not rejected; the uncorrected within tests are used (the GG "
            "p is shown alongside)."
        )
        + " The paper ran the three separate two-way models below instead, which cannot test "
        "CF × FS or the three-way term."
    )
    rows = []
    for t in terms:
        gg = rejected and t.get("df1_gg") is not None
        df1, df2, p = (t["df1_gg"], t["df2_gg"], t["p_gg"]) if gg else (t["df1"], t["df2"], t["p"])
        rows.append(
            [
                TERM_LABELS.get(t["term"], t["term"]),
                fmt_F(df1, df2, t["F"], p),
                fmt_p(t["p_gg"]) if t["p_gg"] is not None else "",
                fmt_num(t["eta2_partial"], 3, lead=False),
                _ci_text(t.get("eta2_partial_ci95"), 3),
            ]
        )
    doc.table(
        ["Term", "Test" + (" (GG where within)" if rejected else ""), "p (GG)", "ηp²", "95% CI"],
        rows,
    )
    if detail.get("note"):
        doc.p(f"Note: {detail['note']}.")


def _sensitivity_section(doc: Doc, sens: dict[str, Any] | None) -> None:
    if not sens:
        return
    doc.h(2, "Sensitivity to the exclusions")
    if "skipped" in sens:
        doc.p(f"Not computed: {sens['skipped']}.")
        return
    doc.p(
        "The H1 ANOVA and the full model again, without the outlier and manual exclusions and "
        "with the robust outlier rule; " + sens["note"] + "."
    )
    terms = list(TERM_LABELS)
    rows = []
    for v in sens["variants"]:
        h1 = v.get("h1") or {}
        h1_txt = (
            "n/a" if h1.get("skipped") or not h1 else fmt_F(h1["df1"], h1["df2"], h1["F"], h1["p"])
        )
        full = v.get("full_anova") or {}
        rows.append(
            [
                v["name"],
                str(v["n_retained"]),
                h1_txt,
                *(fmt_p(full[t]["p"]) if t in full else "n/a" for t in terms),
            ]
        )
    doc.table(["Exclusions", "N", "H1", *(TERM_LABELS[t] for t in terms)], rows)


def _ordinal_section(doc: Doc, ordinal: dict[str, Any] | None) -> None:
    if not ordinal:
        return
    doc.h(2, "Ordinal models of the ratings")
    doc.p(
        "Beside the paper's rank tests: every rating as one observation of a cumulative-logit "
        "(proportional odds) model with cluster-robust SEs by participant. OR > 1: answers in "
        "higher categories with the scaffolding (or at that difficulty vs the mean). The "
        "cluster-robust SEs use the CR1 small-sample correction, G/(G - 1) x (N - 1)/(N - K) "
        "for G participants, N ratings and K parameters (statsmodels' default)."
    )
    if "skipped" in ordinal and isinstance(ordinal["skipped"], str):
        doc.p(f"Not computed: {ordinal['skipped']}.")
        return
    rows = []
    for name, res in ordinal.items():
        label = name.replace("_", " ").capitalize()
        if "skipped" in res:
            rows.append([label, "not computed: " + res["skipped"], "", ""])
            continue
        for t in res["terms"]:
            rows.append(
                [
                    f"{label} (N = {res['n_participants']}, {res['n_observations']} ratings)",
                    _glmm_term(t["term"]),
                    f"{fmt_num(t['odds_ratio'])} [{fmt_num(t['ci_low'])}, {fmt_num(t['ci_high'])}]",
                    fmt_p(t["p"]),
                ]
            )
    doc.table(["Rating", "Term", "OR [95% CI]", "p"], rows)


def _glmm_term(term: str) -> str:
    """'counterfactual:difficulty[high]' -> 'CF × difficulty (high vs mean)'."""
    short = {
        "counterfactual": "CF",
        "feature_scaffolding": "FS",
        "domain_position": "domain position",
    }
    parts = []
    for part in term.split(":"):
        if "[" in part:
            name, lvl = part.rstrip("]").split("[")
            parts.append(f"{name} ({lvl} vs mean)")
        else:
            parts.append(short.get(part, part))
    return " × ".join(parts)


def _covariate_text(g: dict[str, Any]) -> str:
    """The covariates the model really has (a constant one is dropped, and said so)."""
    cov = g.get("covariates")
    if cov is None:  # results.json written before the field existed
        return " with domain and domain position as covariates"
    names = []
    if any(c.startswith("domain[") for c in cov):
        names.append("domain")
    if "domain_position" in cov:
        names.append("domain position")
    return f" with {' and '.join(names)} as covariates" if names else " without covariates"


def _glmm_section(doc: Doc, g: dict[str, Any] | None) -> None:
    if not g:
        return
    doc.h(2, "Trial-level logistic mixed model")
    if "skipped" in g:
        doc.p(f"Not computed: {g['skipped']}.")
        return
    sd = g["random_effect_sd"]
    doc.p(
        f"Each of the {g['n_observations']} answers ({g['n_participants']} participants, "
        f"{g['n_items']} test items) as one binary trial: {g['method']}; fixed effects "
        f"counterfactual × feature scaffolding × difficulty{_covariate_text(g)}. "
        f"Random-intercept SDs (logit): participant {fmt_num(sd['participant'])}"
        f", item {fmt_num(sd['item'])}. Coding: {g['coding']}. Wald 95% CIs."
        + ("" if g.get("converged", True) else " **The fit did not converge.**")
    )
    for note in g.get("notes") or []:
        doc.p(f"**Note**: {note}")
    doc.table(
        ["Term", "OR", "95% CI", "p"],
        [
            [
                _glmm_term(t["term"]),
                fmt_num(t["odds_ratio"]),
                f"[{fmt_num(t['ci_low'])}, {fmt_num(t['ci_high'])}]",
                fmt_p(t["p"]),
            ]
            for t in g["terms"]
        ],
    )


def _descriptives_section(doc: Doc, desc: dict[str, Any] | None) -> None:
    if not desc:
        return
    doc.h(2, "Descriptives per condition")
    if "skipped" in desc:
        doc.p(f"Not computed: {desc['skipped']}.")
        return
    doc.p(
        "Means (SD) over participants; proportion optimal is each participant's share of "
        "optimal answers; confidence 1-5; Likert medians of the per-participant medians."
    )
    rows = []
    for r in desc["rows"]:
        genders = ", ".join(f"{k} {v}" for k, v in r["gender"].items()) or "n/a"
        rows.append(
            [
                r["label"],
                str(r["n"]),
                _m_sd(r["proportion_optimal"]),
                *(_m_sd(r["by_difficulty"][d]) for d in DIFFICULTIES),
                _m_sd(r["confidence"]),
                *(fmt_num(r["likert_median"][it], 1) for it in LIKERT_ITEMS),
                _m_sd(r["age"], 1),
                genders,
            ]
        )
    doc.table(
        [
            "Condition",
            "N",
            "Optimal",
            *(f"Optimal ({d})" for d in DIFFICULTIES),
            "Confidence",
            "Informativeness (Mdn)",
            "Mental effort (Mdn)",
            "Age",
            "Gender",
        ],
        rows,
    )


def _m_sd(m: dict[str, Any], digits: int = 2) -> str:
    if m["mean"] is None:
        return "n/a"
    sd = f" ({fmt_num(m['sd'], digits)})" if m["sd"] is not None else ""
    return fmt_num(m["mean"], digits) + sd


def build_document(results: dict[str, Any], figures: dict[str, list[str]]) -> Doc:
    """The report as a `Doc` (rendered by `write_report`)."""
    doc = Doc()
    meta = results["meta"]
    doc.h(1, "Study analysis report")
    doc.p(
        f"Export: `{meta['export_dir']}`. Generated by cfteach {meta['cfteach_version']} with "
        f"pingouin {meta['pingouin_version']}, scipy {meta['scipy_version']}. "
        "All numbers are also in `results.json`. Tests are two-sided; α = .05."
    )
    if meta.get("note"):
        doc.p(meta["note"])
    part = results["participants"]
    doc.h(2, "Participants and exclusions")
    n_cl = part.get("n_closed_loop", 0)
    doc.p(
        _sessions(part["n_sessions"])
        + " in the export"
        + (
            f" ({n_cl} closed_loop, compared in their own section below)"
            if n_cl
            else ""
        )
        + f"; {part['n_retained']} participants of the paper's conditions retained ("
        + ", ".join(
            f"{_level('condition', c)}: {n}" for c, n in part["retained_by_condition"].items()
        )
        + ")."
    )
    exc = results["exclusions"]
    if exc:
        by_rule: dict[str, int] = {}
        for e in exc:
            by_rule[e["rule"]] = by_rule.get(e["rule"], 0) + 1
        doc.p("Excluded by rule: " + ", ".join(f"{k}: {v}" for k, v in by_rule.items()) + ".")
        doc.table(
            ["participant_id", "condition", "rule", "reason"],
            [[e["participant_id"], e["condition"], e["rule"], e["reason"]] for e in exc],
        )
    else:
        doc.p("No participant was excluded.")
    flags = results.get("quality_flags") or []
    if flags:
        doc.p(
            "Data-quality flags among the retained participants (reported, not excluded; "
            "the authors' soft flags):"
        )
        doc.table(
            ["participant_id", "condition", "flag", "detail"],
            [[f["participant_id"], f["condition"], f["rule"], f["reason"]] for f in flags],
        )
    rules = {
        k: (f"{len(v)} id(s)" if v else "none") if k == "manual" else v
        for k, v in results["config"]["exclusions"].items()
    }
    doc.p("Rules and thresholds: " + ", ".join(f"{k} = {v}" for k, v in rules.items()) + ".")

    _descriptives_section(doc, results.get("descriptives"))

    icc = results["icc"]
    doc.h(2, "Consistency across domains (ICC)")
    if "skipped" in icc:
        doc.p(f"ICC not computed: {icc['skipped']}.")
    else:
        doc.p(
            f"Mean-rating (k = {icc['k']}), two-way mixed, consistency ICC over "
            f"{icc['n_targets']} participants: ICC = {fmt_num(icc['icc'])}, 95% CI "
            f"[{fmt_num(icc['ci95'][0])}, {fmt_num(icc['ci95'][1])}], "
            + fmt_F(icc["df1"], icc["df2"], icc["F"], icc["p"])
            + "."
        )
        doc.table(
            ["Domain", "M proportion optimal"],
            [[d, fmt_num(v)] for d, v in icc["per_domain_mean"].items()],
        )

    _h1_section(doc, results["h1"], figures)

    _full_anova_section(doc, results)
    _sensitivity_section(doc, results.get("sensitivity"))
    _glmm_section(doc, results.get("glmm"))

    for factor, (hyp, label) in FACTOR_TITLES.items():
        res = results["mixed"][factor]
        doc.h(2, f"{hyp}: difficulty × {label} (the paper's two-way analysis)")
        if "skipped" in res:
            doc.p(f"Mixed ANOVA skipped: {res['skipped']}.")
        else:
            _mixed_section(doc, factor, label, res)
        _likert_section(doc, factor, results["likert"])
    if "interaction" in figures:
        doc.img(
            f"figures/{figures['interaction'][0]}",
            "Proportion optimal by difficulty and group (mean, 95% CI)",
        )
    if "paper_bars" in figures:
        doc.img(
            f"figures/{figures['paper_bars'][0]}",
            "The paper's Fig. 5 form (counterfactual scaffolding), with 95% CIs",
        )
    if "likert" in figures:
        doc.img(f"figures/{figures['likert'][0]}", "Likert ratings by condition")
    _ordinal_section(doc, results.get("ordinal"))

    doc.h(2, "Exploratory measures")
    expl = results["exploratory"]
    if isinstance(expl.get("skipped"), str):
        doc.p(f"Not computed: {expl['skipped']}.")
        expl = {}
    for res in expl.values():
        if "skipped" in res:
            doc.p(f"{res['label']}: skipped ({res['skipped']}).")
            continue
        rows = []
        for factor in ("counterfactual", "feature_scaffolding", "condition"):
            a = res[factor]
            if "skipped" in a:
                rows.append([factor, "skipped: " + a["skipped"], "", ""])
                continue
            ms = ", ".join(
                f"{_level(factor, k)} {fmt_num(v['mean'])}" for k, v in a["means"].items()
            )
            rows.append(
                [
                    factor,
                    fmt_F(a["df1"], a["df2"], a["F"], a["p"]),
                    fmt_num(a["np2"], 3, lead=False),
                    ms,
                ]
            )
        n = max(
            (res[f].get("n", 0) for f in ("counterfactual", "feature_scaffolding", "condition")),
            default=0,
        )
        doc.p(f"**{res['label']}** (per-participant mean; one-way ANOVA, N = {n}):")
        doc.table(["Factor", "Test", "ηp²", "Means"], rows)
    if "exploratory" in figures:
        doc.img(f"figures/{figures['exploratory'][0]}", "Exploratory measures by condition")
    return doc


def _sessions(n: int) -> str:
    return f"{n} session" + ("" if n == 1 else "s")


def write_closed_loop_only_report(results: dict[str, Any], out_dir: Path) -> None:
    """The report of an export that holds only closed_loop sessions."""
    doc = Doc()
    meta = results["meta"]
    doc.h(1, "Study analysis report")
    doc.p(f"Export: `{meta['export_dir']}`. Generated by cfteach {meta['cfteach_version']}.")
    if meta.get("note"):
        doc.p(meta["note"])
    doc.h(2, "Participants")
    n = results["participants"]["n_sessions"]
    doc.p(
        f"{_sessions(n)} in the export, all closed_loop. The paper's statistics were not "
        f"computed: {results['paper_analysis']['skipped']}."
    )
    cl = results.get("closed_loop") or {}
    if "skipped" in cl:
        doc.p(f"Closed-loop comparison not computed: {cl['skipped']}.")
    (out_dir / "report.md").write_text(doc.markdown(), encoding="utf-8")
    (out_dir / "report.html").write_text(doc.html("Study analysis report"), encoding="utf-8")


def write_report(results: dict[str, Any], figures: dict[str, list[str]], out_dir: Path) -> None:
    """Write report.md and report.html into `out_dir`."""
    doc = build_document(results, figures)
    (out_dir / "report.md").write_text(doc.markdown(), encoding="utf-8")
    (out_dir / "report.html").write_text(doc.html("Study analysis report"), encoding="utf-8")
