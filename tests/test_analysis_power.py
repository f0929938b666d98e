"""`cfteach power`: power vs N by simulation, Wilson intervals, the table and the plot."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from statsmodels.stats.proportion import proportion_confint
from typer.testing import CliRunner

from cfteach.analysis.power import power_curve, rejection_rates, wilson
from cfteach.cli import app


@pytest.mark.parametrize(("hits", "n"), [(0, 20), (7, 20), (190, 200), (200, 200)])
def test_wilson_matches_statsmodels(hits: int, n: int) -> None:
    lo, hi = wilson(hits, n)
    want = proportion_confint(hits, n, alpha=0.05, method="wilson")
    assert (lo, hi) == pytest.approx(want, abs=1e-6)
    assert 0.0 <= lo <= hits / n <= hi <= 1.0  # exactly: the plot's error bars need it


def test_a_test_that_could_not_run_counts_as_not_significant() -> None:
    ps = pd.DataFrame({"a": [0.01, np.nan, 0.2, 0.03]})
    assert rejection_rates(ps)["a"]["power"] == 0.5


def test_planted_effect_has_power_and_absent_one_does_not() -> None:
    table = power_curve([48], 8, {"interaction": 1.5}, seed=0)
    power = table.set_index("hypothesis")["power"]
    assert power["H2"] >= 0.75
    assert power["CFxFS"] <= 0.25 and power["3-way"] <= 0.25
    assert set(table["n_participants"]) == {48}
    assert (table["ci_low"] <= table["power"] + 1e-12).all()
    assert (table["power"] <= table["ci_high"] + 1e-12).all()


def test_cli_power_writes_table_and_plot(tmp_path: Path) -> None:
    res = CliRunner().invoke(
        app, ["power", "--n", "8", "--n", "12", "--sims", "2", "--out", str(tmp_path)]
    )
    assert res.exit_code == 0, res.output
    for name in ("power.md", "power.csv", "power.png", "power.svg"):
        assert (tmp_path / name).stat().st_size > 100
    table = pd.read_csv(tmp_path / "power.csv")
    assert sorted(set(table["n_participants"])) == [8, 12]
    assert "| 8 |" in res.output and "| 12 |" in res.output
    md = (tmp_path / "power.md").read_text(encoding="utf-8")
    for _, r in table.iterrows():  # every rate with the interval power.csv has
        cell = f"{100 * r['power']:.0f}% [{100 * r['ci_low']:.0f}, {100 * r['ci_high']:.0f}]"
        assert cell in md
    assert "Wilson 95% interval over 2 simulated studies" in md
    bad = CliRunner().invoke(app, ["power", "--n", "4", "--out", str(tmp_path)])
    assert bad.exit_code == 2 and "--n must be at least 8" in bad.output
