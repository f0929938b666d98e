"""Pilots with perfect (or hopeless) cells still get their analysis: the five cases of the
issue, each one full run. Separation is detected per term before the GLMM, which is then a
posterior mode under normal priors (or is skipped with its reason); no step failing stops
the others, and the ANOVA is there."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest
import statsmodels.api as sm

from cfteach.analysis import SyntheticConfig, compute_results, generate, write_export
from cfteach.analysis.io import StudyExport
from cfteach.analysis.pipeline import guarded, skipped_steps
from cfteach.analysis.separation import separation
from cfteach.cli import app
from cli_runner import WideRunner

CF = ("counterfactual_only", "proposed")
CASES = {
    "pilot: both baseline participants right on every low and medium test": (
        dict(n_participants=8, n_outliers=0),
        lambda t: (t["condition"] == "baseline") & t["difficulty"].isin(["low", "medium"]),
        1,
    ),
    "every test correct": (dict(n_participants=48), lambda t: t["optimal"] >= 0, 1),
    "every proposed test correct": (
        dict(n_participants=48),
        lambda t: t["condition"] == "proposed",
        1,
    ),
    "every low test correct": (dict(n_participants=48), lambda t: t["difficulty"] == "low", 1),
    "every high test wrong in the counterfactual conditions": (
        dict(n_participants=48),
        lambda t: t["condition"].isin(CF) & (t["difficulty"] == "high"),
        0,
    ),
}


def force(export: StudyExport, mask, value: int) -> StudyExport:
    """The export with the answers selected by `mask` all right (1) or all wrong (0)."""
    t = export.tests.copy()
    m = mask(t)
    t.loc[m, "optimal"] = value
    t.loc[m, "reward"] = t.loc[m, "optimal_reward"] - (0.0 if value else 1.0)
    return StudyExport(export.participants, t, export.likert, export.demo_views)


def _case(name: str, seed: int = 1) -> StudyExport:
    kw, mask, value = CASES[name]
    return force(generate(SyntheticConfig(seed=seed, **kw)), mask, value)


@pytest.mark.slow
@pytest.mark.parametrize("name", list(CASES))
def test_every_step_is_computed_or_says_why(name: str) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)  # a failed step warns: fail on it
        warnings.filterwarnings("ignore", message=".*(invalid value|divide|Degrees of freedom)")
        warnings.filterwarnings("ignore", module=r"(pingouin|statsmodels|numpy|scipy)(\..*)?$")
        res, _ = compute_results(_case(name))
    assert skipped_steps(res) == []
    assert len(res["full_anova"]) == 7
    g = res["glmm"]
    if name == "every test correct":
        assert g["skipped"].startswith("all ") and "no variation" in g["skipped"]
        assert all(t["F"] is None for t in res["full_anova"])  # no variance: no F
        assert "no variance" in res["full_anova_detail"]["note"]
        return
    assert "skipped" not in g
    sep = g["separation"]
    assert sep["kind"] == "quasi-complete" and sep["terms"]
    assert g["fixed_effect_prior"]["sd_other"] == 2.5
    assert "blme::bglmer" in g["method"] and "separation" in g["notes"][0].lower()
    for t in g["terms"]:  # finite, shrunk estimates with finite intervals
        assert np.isfinite(t["log_odds"]) and abs(t["log_odds"]) < 15
        assert 0 < t["ci_low"] <= t["odds_ratio"] <= t["ci_high"] < np.inf
    assert all(t["F"] is not None for t in res["full_anova"])


@pytest.mark.slow
@pytest.mark.parametrize("name", ["every test correct", "every low test correct"])
def test_cli_writes_results_and_report(tmp_path: Path, name: str) -> None:
    write_export(_case(name), tmp_path / "export")
    out = tmp_path / "out"
    result = WideRunner().invoke(
        app, ["analyze", str(tmp_path / "export"), "--out", str(out), "--no-figures"]
    )
    assert result.exit_code == 0, result.output
    res = json.loads((out / "results.json").read_text(encoding="utf-8"))
    md = (out / "report.md").read_text(encoding="utf-8")
    assert len(res["full_anova"]) == 7 and "Full factorial model" in md
    if name == "every test correct":
        assert "Not computed: all 864 answers are optimal" in md
    else:
        assert "separation" in md and "posterior modes" in md


def _logit_diverges(y: np.ndarray, x: np.ndarray, j: int) -> bool:
    """Brute force: an unpenalised logistic fit's coefficient j keeps growing with the
    iterations (it has no finite maximum)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        b = [
            sm.Logit(y, x).fit(method="newton", maxiter=it, disp=0, warn_convergence=False)
            .params[j]
            for it in (15, 30)
        ]
    return abs(b[1]) > abs(b[0]) + 1.0


def test_separation_agrees_with_diverging_fits() -> None:
    rng = np.random.default_rng(0)
    x1 = rng.normal(size=200)
    g = rng.integers(0, 2, size=200).astype(float)
    x = np.column_stack([np.ones(200), x1, g])
    y = (rng.random(200) < 1 / (1 + np.exp(-x1))).astype(float)
    assert not separation(y, x, ["a", "b", "c"])["separated"]
    y_q = y.copy()
    y_q[g == 1] = 1.0  # the whole group right: quasi-complete, only its terms diverge
    s = separation(y_q, x, ["a", "b", "c"])
    assert s["kind"] == "quasi-complete" and s["terms"] == {"c": "+inf"}
    assert _logit_diverges(y_q, x, 2)
    assert not _logit_diverges(y_q, x, 0) and not _logit_diverges(y_q, x, 1)
    y_c = (x1 > 0).astype(float)  # a threshold on x1: complete separation
    s = separation(y_c, x, ["a", "b", "c"])
    assert s["kind"] == "complete" and s["terms"]["b"] == "+inf"
    assert _logit_diverges(y_c, x, 1)


def test_a_failing_step_is_recorded_and_named() -> None:
    def broken() -> dict:
        raise RuntimeError("Factor is exactly singular")

    with pytest.warns(RuntimeWarning, match="analysis step glmm failed"):
        r = guarded("glmm", broken)
    assert r == {"skipped": "failed: RuntimeError: Factor is exactly singular"}
    assert skipped_steps({"glmm": r, "h1": {"rm_anova": {"F": 1.0}}}) == ["glmm"]
