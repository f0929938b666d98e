"""The report's H1 section: the repeated-measures ANOVA of difficulty, its post hocs and
the correlations of confidence with difficulty."""

from __future__ import annotations

from typing import Any

from cfteach.analysis.report_doc import Doc
from cfteach.analysis.report_format import ci_text, fmt_df, fmt_F, fmt_num, fmt_p


def h1_section(doc: Doc, h1: dict[str, Any], figures: dict[str, list[str]]) -> None:
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
                fmt_num(r["hedges"]) + " " + ci_text(r.get("hedges_ci95"), 2),
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
        f"{ci_text(rc['ci95'], 2)}, {fmt_p(rc['p'])}, {rc['n_participants']} participants. "
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
