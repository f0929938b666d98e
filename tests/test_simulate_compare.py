"""Closed loop against its controls: exact-zero regret, bootstrap ratios, calibration."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from cfteach.simulate.compare import (
    bootstrap_ratio,
    calibration_table,
    geometric_mean,
    ratio_table,
)
from cfteach.simulate.summary import answer_regret, regret_table


def _answers(rows: list[tuple]) -> pd.DataFrame:
    return pd.DataFrame([{"learner_model": m, "domain": "d", "condition": c, "seed": 0,
                          "learner": i, "test": t, "reward": r, "optimal_reward": o,
                          "finished": True, "correct": ok}
                         for m, c, i, t, r, o, ok in rows])


def test_an_optimal_answer_has_regret_exactly_zero():
    # 0.1 + 0.2 is 0.30000000000000004: the sums differ by 5.6e-17, the answer is optimal
    df = _answers([("m", "c", 0, 0, -(0.1 + 0.2), -0.3, True),
                   ("m", "c", 0, 1, -0.5, -0.3, False)])
    assert (-0.3) - (-(0.1 + 0.2)) != 0
    reg = answer_regret(df)
    assert reg[0] == 0.0 and reg[1] == pytest.approx(0.2)
    table = regret_table(df)["m"]["d"]["c"]
    assert table["mean"] == pytest.approx(0.1) and table["p_optimal"] == 0.5
    assert table["median"] == pytest.approx(0.1)


def test_bootstrap_ratio_point_and_interval():
    num, den = np.array([1.0, 2.0, 3.0]), np.array([2.0, 4.0, 6.0, 8.0])
    r, lo, hi = bootstrap_ratio(num, den)
    assert r == pytest.approx(2.0 / 5.0)
    assert lo <= r <= hi and lo >= 1.0 / 8.0 and hi <= 3.0 / 2.0  # extreme resamples bound it
    assert bootstrap_ratio(np.full(5, 0.2), np.full(4, 0.4)) == pytest.approx((0.5, 0.5, 0.5))
    assert bootstrap_ratio(np.zeros(3), np.zeros(3)) == (1.0, 1.0, 1.0)
    assert bootstrap_ratio(np.ones(3), np.zeros(3))[0] == np.inf


def test_ratio_table_and_geometric_mean_by_hand():
    rows = []
    for cond, regrets in (("closed_loop", [0.1, 0.3]), ("proposed", [0.4, 0.4]),
                          ("proposed_equal_items", [0.2, 0.2])):
        for i, g in enumerate(regrets):
            rows.append(("m", cond, i, 0, -1.0 - g, -1.0, False))
    table = ratio_table(_answers(rows))
    cell = table["cells"]["m"]["d"]
    assert cell["closed_loop/proposed"]["ratio"] == pytest.approx(0.2 / 0.4)
    assert cell["closed_loop/proposed_equal_items"]["ratio"] == pytest.approx(0.2 / 0.2)
    assert "closed_loop/proposed_equal_budget" not in cell
    assert table["geometric_mean"]["closed_loop/proposed"] == pytest.approx(0.5)


def test_geometric_mean_with_zero_and_infinite_ratios():
    assert geometric_mean([0.5, 2.0, 4.0]) == pytest.approx(4.0 ** (1 / 3))
    assert geometric_mean([0.0, 2.0, 4.0]) == 0.0           # a factor 0: the product is 0
    assert geometric_mean([np.inf, 2.0]) == np.inf
    assert geometric_mean([0.0, np.inf]) is None             # 0 x inf has no value
    assert geometric_mean([]) is None and geometric_mean([np.nan, 1.0]) is None


def test_calibration_table_by_hand():
    rows = [("m", "closed_loop", i, t, -1.0 if ok else -2.0, -1.0, ok)
            for i, oks in enumerate([(True, True), (True, False), (False, False)])
            for t, ok in enumerate(oks)]
    beliefs = pd.DataFrame({"learner_model": "m", "domain": "d", "condition": "closed_loop",
                            "seed": 0, "learner": [0, 1, 2], "predicted": [0.9, 0.6, 0.3]})
    cal = calibration_table(_answers(rows), beliefs)["m"]["d"]
    observed = [1.0, 0.5, 0.0]
    assert cal["n"] == 3
    assert cal["predicted"] == pytest.approx(0.6) and cal["observed"] == pytest.approx(0.5)
    assert cal["gap"] == pytest.approx(0.1)
    assert cal["correlation"] == pytest.approx(np.corrcoef([0.9, 0.6, 0.3], observed)[0, 1])
    assert cal["observed_on_probes"] is None  # not measured
    beliefs["probe_observed"] = [1.0, np.nan, 0.5]  # a learner without probes is left out
    cal = calibration_table(_answers(rows), beliefs)["m"]["d"]
    assert cal["observed_on_probes"] == pytest.approx(0.75)
    assert cal["expected"] is None and cal["correlation_ceiling"] is None  # not measured
    # the learners' expected scores: the prediction against them, and the ceiling any
    # per-learner prediction meets (expected against observed); a NaN pair is left out
    beliefs["expected"] = [0.8, 0.7, 0.1]
    cal = calibration_table(_answers(rows), beliefs)["m"]["d"]
    assert cal["expected"] == pytest.approx(1.6 / 3)
    assert cal["correlation_with_expected"] == pytest.approx(
        np.corrcoef([0.9, 0.6, 0.3], [0.8, 0.7, 0.1])[0, 1])
    assert cal["correlation_ceiling"] == pytest.approx(
        np.corrcoef([0.8, 0.7, 0.1], observed)[0, 1])
    beliefs["expected"] = [0.8, np.nan, 0.1]  # two finite pairs: r is undefined
    cal = calibration_table(_answers(rows), beliefs)["m"]["d"]
    assert cal["correlation_ceiling"] is None and cal["expected"] == pytest.approx(0.45)
