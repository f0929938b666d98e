"""The full 2 x 2 x 3 ANOVA against afex, and the ordinal models against ordinal::clm, on a
simulated export (R reads the export's CSVs and aggregates them itself).

The ordinal models' cluster-robust SEs are checked by recomputing the CR1 sandwich here
from clm's estimates and covariance: per-observation scores of the cumulative logit summed
by participant, times G/(G - 1) (N - 1)/(N - K).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.special import expit

from cfteach.analysis import SyntheticConfig, compute_results, generate, write_export
from r_reference import read_r, require_r, run_r

R_DESIGN = r"""
keep <- read.csv("ids.csv", stringsAsFactors = FALSE)$participant_id
cfc <- c("counterfactual_only", "proposed"); fsc <- c("feature_only", "proposed")
"""


@pytest.fixture(scope="module")
def study(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict]:
    d = tmp_path_factory.mktemp("rmodels")
    export = generate(SyntheticConfig(n_participants=48, seed=0, feature_effect=0.4))
    write_export(export, d / "export")
    res, _ = compute_results(export)
    return d, res


@pytest.mark.slow
def test_full_anova_matches_afex(study: tuple[Path, dict]) -> None:
    require_r()
    d, res = study
    pd.DataFrame({"participant_id": res["full_anova_participants"]}).to_csv(
        d / "ids.csv", index=False
    )
    run_r(
        R_DESIGN
        + r"""
suppressMessages(library(afex))
t <- read.csv("export/test_responses.csv", stringsAsFactors = FALSE)
t <- t[t$participant_id %in% keep, ]
t$cf <- factor(as.integer(t$condition %in% cfc)); t$fs <- factor(as.integer(t$condition %in% fsc))
cells <- aggregate(optimal ~ participant_id + cf + fs + difficulty, data = t, FUN = mean)
a <- suppressMessages(aov_car(optimal ~ cf * fs + Error(participant_id / difficulty),
  data = cells, type = 3, anova_table = list(correction = "none", es = "pes")))
tab <- a$anova_table
gg <- anova(a, correction = "GG")
s <- summary(a$Anova, multivariate = FALSE)
write.csv(data.frame(term = rownames(tab), F = tab$F, df1 = tab[["num Df"]],
  df2 = tab[["den Df"]], p = tab[["Pr(>F)"]], pes = tab$pes, p_gg = gg[["Pr(>F)"]]),
  "afex.csv", row.names = FALSE)
write.csv(data.frame(W = s$sphericity.tests["difficulty", "Test statistic"],
  p = s$sphericity.tests["difficulty", "p-value"],
  eps = s$pval.adjustments["difficulty", "GG eps"]),
  "sphericity.csv", row.names = FALSE)
""",
        d,
    )
    ref = read_r(d / "afex.csv")
    names = {"cf": "counterfactual", "fs": "feature_scaffolding"}
    ref["term"] = ref["term"].map(lambda n: ":".join(names.get(p, p) for p in n.split(":")))
    ref = ref.set_index("term")
    ours = pd.DataFrame(res["full_anova"]).set_index("term")
    assert set(ours.index) == set(ref.index)
    for term, r in ours.iterrows():
        assert r["F"] == pytest.approx(ref.loc[term, "F"], rel=1e-8, abs=1e-8), term
        assert r["p"] == pytest.approx(ref.loc[term, "p"], rel=1e-8, abs=1e-8), term
        assert (r["df1"], r["df2"]) == (ref.loc[term, "df1"], ref.loc[term, "df2"]), term
        assert r["eta2_partial"] == pytest.approx(ref.loc[term, "pes"], rel=1e-8), term
        if "difficulty" in term:
            assert r["p_gg"] == pytest.approx(ref.loc[term, "p_gg"], rel=1e-8, abs=1e-8), term
    sph = read_r(d / "sphericity.csv").iloc[0]
    ours_sph = res["full_anova_detail"]["sphericity"]
    assert ours_sph["mauchly_W"] == pytest.approx(sph["W"], rel=1e-8)
    assert ours_sph["mauchly_p"] == pytest.approx(sph["p"], rel=1e-8)
    assert ours_sph["eps_gg"] == pytest.approx(sph["eps"], rel=1e-8)


def _cr1_se(y: np.ndarray, x: np.ndarray, groups: np.ndarray, coef: np.ndarray,
            vcov: np.ndarray, n_thresholds: int) -> np.ndarray:
    """CR1 cluster-robust SEs of a cumulative logit P(Y <= j) = F(theta_j - x'beta) at clm's
    estimates (coef = thresholds then beta; vcov its inverse information)."""
    theta, beta = coef[:n_thresholds], coef[n_thresholds:]
    cats = np.sort(np.unique(y))
    k = np.searchsorted(cats, y)  # 0 .. J-1
    eta = x @ beta
    cut = np.r_[-np.inf, theta, np.inf]
    up, lo = cut[k + 1] - eta, cut[k] - eta
    fu = np.where(np.isfinite(up), expit(up) * (1 - expit(up)), 0.0)
    fl = np.where(np.isfinite(lo), expit(lo) * (1 - expit(lo)), 0.0)
    prob = expit(up) - expit(lo)
    scores = np.zeros((len(y), len(coef)))
    for j in range(n_thresholds):
        scores[:, j] = (np.where(k == j, fu, 0.0) - np.where(k == j + 1, fl, 0.0)) / prob
    scores[:, n_thresholds:] = -x * ((fu - fl) / prob)[:, None]
    meat = pd.DataFrame(scores).groupby(groups).sum().to_numpy()
    n, g, p = len(y), len(np.unique(groups)), len(coef)
    v = vcov @ (meat.T @ meat) @ vcov * g / (g - 1) * (n - 1) / (n - p)
    return np.sqrt(np.diag(v))[n_thresholds:]


@pytest.mark.slow
def test_ordinal_models_match_clm(study: tuple[Path, dict]) -> None:
    require_r()
    d, res = study
    kept = sorted({t for t in pd.read_csv(d / "export" / "participants.csv")["participant_id"]}
                  - {e["participant_id"] for e in res["exclusions"]})
    pd.DataFrame({"participant_id": kept}).to_csv(d / "ids.csv", index=False)
    run_r(
        R_DESIGN
        + r"""
suppressMessages(library(ordinal))
code <- function(df) {
  df <- df[df$participant_id %in% keep, ]
  df$cf <- as.numeric(df$condition %in% cfc) - 0.5; df$fs <- as.numeric(df$condition %in% fsc) - 0.5
  df
}
out <- list()
save <- function(name, m, df, y) {
  out[[name]] <<- data.frame(model = name, term = names(coef(m)), b = unname(coef(m)))
  write.csv(as.matrix(vcov(m)), paste0(name, "_vcov.csv"), row.names = FALSE)
  x <- model.matrix(m)$X[, -1, drop = FALSE]
  write.csv(data.frame(y = df[[y]], participant_id = df$participant_id, x),
    paste0(name, "_data.csv"), row.names = FALSE)
}
lk <- code(read.csv("export/likert.csv", stringsAsFactors = FALSE))
for (item in c("informativeness", "mental_effort")) {
  s <- lk[lk$item == item, ]
  save(item, clm(factor(value, ordered = TRUE) ~ cf * fs, data = s), s, "value")
}
t <- code(read.csv("export/test_responses.csv", stringsAsFactors = FALSE))
t <- t[!is.na(t$confidence), ]
t$difficulty <- factor(t$difficulty, levels = c("low", "high", "medium"))
contrasts(t$difficulty) <- contr.sum(3)
m <- clm(factor(confidence, ordered = TRUE) ~ cf * fs + difficulty, data = t)
save("confidence", m, t, "confidence")
write.csv(do.call(rbind, out), "clm.csv", row.names = FALSE)
""",
        d,
    )
    ref = read_r(d / "clm.csv")
    names = {"cf": "counterfactual", "fs": "feature_scaffolding", "cf:fs":
             "counterfactual:feature_scaffolding", "difficulty1": "difficulty[low]",
             "difficulty2": "difficulty[high]"}
    for model in ("informativeness", "mental_effort", "confidence"):
        r = ref[ref["model"] == model].reset_index(drop=True)
        n_thr = int(r["term"].str.contains(r"\|").sum())
        ours = pd.DataFrame(res["ordinal"][model]["terms"]).set_index("term")
        beta_names = [names[t] for t in r["term"][n_thr:]]
        assert sorted(beta_names) == sorted(ours.index)
        b = r["b"].to_numpy()
        assert np.abs(ours.loc[beta_names, "log_odds"].to_numpy() - b[n_thr:]).max() < 1e-4
        data = read_r(d / f"{model}_data.csv")
        vcov = read_r(d / f"{model}_vcov.csv").to_numpy()
        se = _cr1_se(data["y"].to_numpy(), data.iloc[:, 2:].to_numpy(float),
                     data["participant_id"].to_numpy(), b, vcov, n_thr)
        assert ours.loc[beta_names, "se"].to_numpy() == pytest.approx(se, rel=2e-3), model
