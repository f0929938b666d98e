"""Closed loop against its controls, and how well the teacher predicted its learners.

* `ratio_table`: per learner model and domain, closed-loop mean regret over each control's
  (``proposed``, ``proposed_equal_budget``, ``proposed_equal_items``) with a percentile
  bootstrap 95% CI (learners resampled within each condition, independently), and the
  geometric mean of each ratio over the cells.
* `calibration_table`: the teacher's predicted P(optimal) at its stop (on its own probe
  tests) against the learners' observed P(optimal) on the post-teaching tests.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from cfteach.simulate.summary import per_learner

CLOSED = "closed_loop"
CONTROLS = ("proposed", "proposed_equal_budget", "proposed_equal_items")
N_BOOT = 2000


def bootstrap_ratio(num: np.ndarray, den: np.ndarray, *, seed: int = 0,
                    n_boot: int = N_BOOT) -> tuple[float, float, float]:
    """``mean(num) / mean(den)`` and its percentile bootstrap 95% CI (each sample resampled
    on its own). Resamples whose denominator is 0 give an infinite ratio (kept, so a CI
    can be infinite); a ratio 0/0 counts as 1 (both perfect)."""
    num, den = np.asarray(num, float), np.asarray(den, float)
    rng = np.random.default_rng([seed, 17])
    bn = num[rng.integers(len(num), size=(n_boot, len(num)))].mean(axis=1)
    bd = den[rng.integers(len(den), size=(n_boot, len(den)))].mean(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.where(bd > 0, bn / np.where(bd > 0, bd, 1), np.where(bn > 0, np.inf, 1.0))
    m_num, m_den = float(num.mean()), float(den.mean())
    point = m_num / m_den if m_den > 0 else (np.inf if m_num > 0 else 1.0)
    lo = np.percentile(r, 2.5, method="lower")  # no interpolation: r may hold inf
    hi = np.percentile(r, 97.5, method="higher")
    return float(point), float(lo), float(hi)


def ratio_table(answers: pd.DataFrame, *, seed: int = 0) -> dict[str, Any]:
    """``{"cells": {learner: {domain: {"closed_loop/<control>": {ratio, ci_low, ci_high}}}},
    "geometric_mean": {"closed_loop/<control>": value}, "n_cells": {...}}``."""
    if answers.empty or CLOSED not in set(answers["condition"]):
        return {}
    per = per_learner(answers)
    cells: dict[str, dict[str, dict[str, Any]]] = {}
    logs: dict[str, list[float]] = {}
    for (model, dom), g in per.groupby(["learner_model", "domain"], observed=True):
        closed = g.loc[g["condition"] == CLOSED, "regret"].to_numpy(float)
        if not len(closed):
            continue
        for ctl in CONTROLS:
            other = g.loc[g["condition"] == ctl, "regret"].to_numpy(float)
            if not len(other):
                continue
            r, lo, hi = bootstrap_ratio(closed, other, seed=seed)
            key = f"{CLOSED}/{ctl}"
            cells.setdefault(str(model), {}).setdefault(str(dom), {})[key] = {
                "ratio": r, "ci_low": lo, "ci_high": hi}
            logs.setdefault(key, []).append(r)
    geo = {key: geometric_mean(rs) for key, rs in logs.items()}
    return {"cells": cells, "geometric_mean": geo,
            "n_cells": {k: len(v) for k, v in logs.items()}}


def geometric_mean(ratios: list[float]) -> float | None:
    """The geometric mean of non-negative ratios: 0 when one of them is 0 (closed loop
    without regret in a cell), infinite when one is infinite (a control without any), and
    None when both happen (0 x inf has no value)."""
    r = np.asarray(ratios, float)
    if not len(r) or np.any(r < 0) or np.any(np.isnan(r)):
        return None
    zero, inf = bool(np.any(r == 0)), bool(np.any(np.isinf(r)))
    if zero and inf:
        return None
    if zero or inf:
        return 0.0 if zero else float("inf")
    return float(np.exp(np.mean(np.log(r))))


def calibration_table(answers: pd.DataFrame, beliefs: pd.DataFrame
                      ) -> dict[str, dict[str, dict[str, Any]]]:
    """``calibration[learner][domain] = {predicted, observed, n, gap, correlation,
    observed_on_probes, expected, correlation_with_expected, correlation_ceiling}``: the
    closed-loop teacher's mean predicted P(optimal) at its stop (on its own probes, never
    the post-tests), the learners' mean observed P(optimal) on the post-tests, their
    difference, the per-learner Pearson correlation (None when either does not vary) and
    the learners' mean P(optimal) on the teacher's probes themselves (None when not
    measured): `predicted` against it is the model's error alone.

    A simulated learner's observed score is a sample of its expected score (`expected`,
    the mean over many plays of each post-test): `correlation_with_expected` is the
    prediction's correlation with that, free of the post-tests' sampling noise, and
    `correlation_ceiling` the expected score's own correlation with the observed one, the
    best any per-learner prediction can reach on average."""
    if answers.empty or "predicted" not in beliefs.columns:
        return {}
    per = per_learner(answers[answers["condition"] == CLOSED])
    b = beliefs[beliefs["condition"] == CLOSED]
    cols = ["learner_model", "domain", "seed", "learner", "predicted"]
    cols += [c for c in ("probe_observed", "expected") if c in b.columns]
    m = per.merge(b[cols],
                  on=["learner_model", "domain", "seed", "learner"])
    out: dict[str, dict[str, dict[str, Any]]] = {}
    for (model, dom), g in m.groupby(["learner_model", "domain"], observed=True):
        g = g[np.isfinite(g["predicted"].to_numpy(float))]
        if not len(g):
            continue
        pred, obs = g["predicted"].to_numpy(float), g["p_optimal"].to_numpy(float)
        exp = g["expected"].to_numpy(float) if "expected" in g else np.full(len(g), np.nan)
        out.setdefault(str(model), {})[str(dom)] = {
            "predicted": float(pred.mean()), "observed": float(obs.mean()), "n": int(len(g)),
            "gap": float(pred.mean() - obs.mean()), "correlation": _pearson(pred, obs),
            "observed_on_probes": _mean_finite(g.get("probe_observed")),
            "expected": _mean_finite(g.get("expected")),
            "correlation_with_expected": _pearson(pred, exp),
            "correlation_ceiling": _pearson(exp, obs)}
    return out


def _pearson(x: np.ndarray, y: np.ndarray) -> float | None:
    """Pearson's r over the pairs where both are finite; None with fewer than 3 pairs or
    when either side does not vary (r has no value then)."""
    ok = np.isfinite(x) & np.isfinite(y)
    x, y = x[ok], y[ok]
    if len(x) < 3 or np.ptp(x) == 0 or np.ptp(y) == 0:
        return None
    return float(np.corrcoef(x, y)[0, 1])


def _mean_finite(col: pd.Series | None) -> float | None:
    """Mean of the finite values (None when there are none)."""
    if col is None:
        return None
    v = col.to_numpy(float)
    v = v[np.isfinite(v)]
    return float(v.mean()) if len(v) else None
