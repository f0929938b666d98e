"""The report's model sections beyond the paper's tests: the full factorial ANOVA, its
sensitivity to the exclusions, the trial-level GLMM and the ordinal models of the ratings."""

from __future__ import annotations

from typing import Any

from cfteach.analysis.report_doc import Doc
from cfteach.analysis.report_format import ci_text, fmt_F, fmt_num, fmt_p, glmm_term

TERM_LABELS = {
    "counterfactual": "Counterfactual (CF)",
    "feature_scaffolding": "Feature scaffolding (FS)",
    "difficulty": "Difficulty",
    "counterfactual:feature_scaffolding": "CF × FS",
    "counterfactual:difficulty": "CF × difficulty",
    "feature_scaffolding:difficulty": "FS × difficulty",
    "counterfactual:feature_scaffolding:difficulty": "CF × FS × difficulty",
}


def full_anova_section(doc: Doc, results: dict[str, Any]) -> None:
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
                ci_text(t.get("eta2_partial_ci95"), 3),
            ]
        )
    doc.table(
        ["Term", "Test" + (" (GG where within)" if rejected else ""), "p (GG)", "ηp²", "95% CI"],
        rows,
    )
    if detail.get("note"):
        doc.p(f"Note: {detail['note']}.")


def sensitivity_section(doc: Doc, sens: dict[str, Any] | None) -> None:
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


def ordinal_section(doc: Doc, ordinal: dict[str, Any] | None) -> None:
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
                    glmm_term(t["term"]),
                    f"{fmt_num(t['odds_ratio'])} [{fmt_num(t['ci_low'])}, {fmt_num(t['ci_high'])}]",
                    fmt_p(t["p"]),
                ]
            )
    doc.table(["Rating", "Term", "OR [95% CI]", "p"], rows)


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


def glmm_section(doc: Doc, g: dict[str, Any] | None) -> None:
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
                glmm_term(t["term"]),
                fmt_num(t["odds_ratio"]),
                f"[{fmt_num(t['ci_low'])}, {fmt_num(t['ci_high'])}]",
                fmt_p(t["p"]),
            ]
            for t in g["terms"]
        ],
    )
