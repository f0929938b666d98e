"""The GLMM against lme4 itself: `cfteach analyze --synthetic N` and R's
`glmer(..., nAGQ = 1)` on the exported data (R codes the data with its own contrasts), and
the separation fallback against `blme::bglmer` with the same normal priors.

R runs through Rscript (tests/r_reference.py): missing R fails in CI and skips elsewhere.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from cfteach.analysis import SyntheticConfig, generate, write_export
from cfteach.analysis.io import StudyExport
from cfteach.cli import app
from cli_runner import WideRunner
from r_reference import R_GLMM_DATA, glmm_names, read_r, require_r, run_r

TOL = 2e-3  # log odds and SEs (the target)


def _retained(out: Path) -> list[str]:
    res = json.loads((out / "results.json").read_text(encoding="utf-8"))
    parts = pd.read_csv(out / "export" / "participants.csv", dtype=str)
    gone = {e["participant_id"] for e in res["exclusions"]}
    keep = [p for p in parts["participant_id"] if p not in gone]
    assert len(keep) == res["participants"]["n_retained"]
    return keep


def _glmer(out: Path, fit_call: str) -> tuple[pd.DataFrame, float, list[float]]:
    pd.DataFrame({"participant_id": _retained(out)}).to_csv(out / "retained.csv", index=False)
    run_r(
        R_GLMM_DATA
        + f"m <- {fit_call}\n"
        + "s <- sqrt(diag(as.matrix(vcov(m))))\n"
        + "write.csv(data.frame(term = names(fixef(m)), b = unname(fixef(m)), se = unname(s)),"
        + " 'coef.csv', row.names = FALSE)\n"
        + "write.csv(data.frame(dev = -2 * as.numeric(logLik(m)), th1 = getME(m, 'theta')[1],"
        + " th2 = getME(m, 'theta')[2]), 'fit.csv', row.names = FALSE)\n"
        + "writeLines(levels(t$domain), 'domains.txt')\n",
        out,
    )
    coef = read_r(out / "coef.csv")
    domains = (out / "domains.txt").read_text(encoding="utf-8").split()
    coef["term"] = coef["term"].map(lambda n: glmm_names([n], domains).get(n, n))
    fit = read_r(out / "fit.csv").iloc[0]
    return coef.set_index("term"), float(fit["dev"]), [fit["th1"], fit["th2"]]


def _analyze(out: Path, *args: str) -> dict:
    result = WideRunner().invoke(app, ["analyze", *args, "--out", str(out), "--no-figures"])
    assert result.exit_code == 0, result.output
    return json.loads((out / "results.json").read_text(encoding="utf-8"))


@pytest.mark.slow
@pytest.mark.parametrize("n", [48, 216])
def test_glmm_matches_glmer_laplace(tmp_path: Path, n: int) -> None:
    require_r()
    res = _analyze(tmp_path, "--synthetic", str(n), "--seed", "0")
    g = res["glmm"]
    assert "nAGQ = 1" in g["method"] and g["nAGQ"] == 1
    ref, dev, theta = _glmer(tmp_path, "glmer(form, data = t, family = binomial, nAGQ = 1)")
    ours = pd.DataFrame(g["terms"]).set_index("term")
    assert set(ours.index) == set(ref.index) - {"(Intercept)"}
    assert np.abs(ours["log_odds"] - ref.loc[ours.index, "b"]).max() < TOL
    assert np.abs(ours["se"] - ref.loc[ours.index, "se"]).max() < TOL
    assert abs(g["intercept_log_odds"] - ref.loc["(Intercept)", "b"]) < TOL
    # the same likelihood, optimised at least as well as glmer
    assert g["deviance"] <= dev + 1e-3
    assert g["random_effect_sd"]["participant"] == pytest.approx(theta[0], abs=0.02)


def _force(export: StudyExport, mask, value: int) -> StudyExport:
    t = export.tests.copy()
    m = mask(t)
    t.loc[m, "optimal"] = value
    t.loc[m, "reward"] = t.loc[m, "optimal_reward"] - (0.0 if value else 1.0)
    return StudyExport(export.participants, t, export.likert, export.demo_views)


@pytest.mark.slow
def test_separated_glmm_matches_bglmer(tmp_path: Path) -> None:
    """Every low test right: separation, and the fit is blme's normal-prior posterior mode."""
    require_r()
    e = _force(
        generate(SyntheticConfig(n_participants=48, seed=3)),
        lambda t: t["difficulty"] == "low",
        1,
    )
    write_export(e, tmp_path / "export")
    res = _analyze(tmp_path, str(tmp_path / "export"))
    g = res["glmm"]
    assert g["separation"]["kind"] == "quasi-complete"
    assert "difficulty[low]" in g["separation"]["terms"]
    assert "blme::bglmer" in g["method"]
    ref, dev, _ = _glmer(
        tmp_path,
        # no prior on the SDs (blme's default puts a Wishart one on them), and bobyqa run to
        # convergence: with its default tolerance blme stops 0.02 short on this ridge
        "suppressMessages(blme::bglmer(form, data = t, family = binomial, "
        "fixef.prior = normal(sd = c(10, 2.5)), cov.prior = NULL, "
        "control = glmerControl(optimizer = 'bobyqa', "
        "optCtrl = list(maxfun = 1e5, rhoend = 1e-10))))",
    )
    ours = pd.DataFrame(g["terms"]).set_index("term")
    assert np.abs(ours["log_odds"] - ref.loc[ours.index, "b"]).max() < TOL
    assert np.abs(ours["se"] - ref.loc[ours.index, "se"]).max() < TOL
