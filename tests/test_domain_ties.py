"""A reward that ties behaviours with different features is refused with a named error.

The refusal is checked against a second method: a linear program that looks for an interior
point of the policy-level BEC (the largest margin t with r . w >= t for every row, |w| <= 1).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import linprog
from typer.testing import CliRunner

from cfteach import teaching
from cfteach.bec.constraints import one_action_rows
from cfteach.bec.demos import demo_set
from cfteach.bec.ties import tie_findings
from cfteach.cli import app
from cfteach.domains import load
from cfteach.domains.check import DomainCheckError

DOCS = Path(__file__).resolve().parents[1] / "docs" / "domains.md"


def _doc_example(carry_weight: str | None = None) -> str:
    text = re.search(r"<!-- example-domain -->\s*```toml\n(.*?)```", DOCS.read_text(),
                     re.S)
    assert text, "docs/domains.md lost its marked example"
    toml = text.group(1)
    if carry_weight is not None:
        toml, n = re.subn(r'(label = "Carrying the key"\nweight = )[-0-9.]+',
                          rf"\g<1>{carry_weight}", toml)
        assert n == 1
    return toml


def _interior_margin(rows: np.ndarray) -> float:
    """max t such that r . w >= t for every row, with -1 <= w_i <= 1 (0 iff no interior)."""
    F = rows.shape[1]
    c = np.zeros(F + 1)
    c[-1] = -1.0
    a_ub = np.hstack([-rows.astype(float), np.ones((len(rows), 1))])
    res = linprog(c, A_ub=a_ub, b_ub=np.zeros(len(rows)),
                  bounds=[(-1, 1)] * F + [(None, 1)], method="highs")
    assert res.status == 0
    return float(-res.fun)


@pytest.fixture()
def tied(tmp_path: Path) -> Path:
    path = tmp_path / "tied.toml"
    path.write_text(_doc_example("0.5"))  # two carried steps (+2 x 0.5) = one step (-1)
    return path


def test_a_tied_reward_is_named_and_agrees_with_a_linear_program(tied: Path) -> None:
    dom = load(tied)
    ds = demo_set(dom)
    rows = np.unique(one_action_rows(ds, first_step_only=True).rows, axis=0)
    assert _interior_margin(rows) == pytest.approx(0.0, abs=1e-9)
    (finding,) = tie_findings(ds)
    assert finding.level == "error" and finding.code == "tied_reward"
    named = re.search(r"e\.g\. (.*) = 0 under w\*", finding.message)
    assert named, finding.message
    coef = {n: 0 for n in dom.feature_names}
    for term in re.findall(r"([+-]? ?-?\d+)\*(\w+)", named.group(1)):
        coef[term[1]] = int(term[0].replace(" ", ""))
    raw = dict(zip(dom.feature_names, dom.weights_raw, strict=True))
    assert any(coef.values())
    assert sum(coef[n] * raw[n] for n in coef) == pytest.approx(0.0, abs=1e-12)


def test_teaching_and_tests_refuse_a_tied_reward(tied: Path) -> None:
    for call in (lambda: teaching.teach(load(tied), "baseline"),
                 lambda: teaching.teach(load(tied), "proposed"),
                 lambda: teaching.select_tests(load(tied), per_level=1)):
        with pytest.raises(DomainCheckError, match="tied_reward|ties|equally"):
            call()


def test_check_cli_fails_the_tie_rule(tied: Path) -> None:
    res = CliRunner().invoke(app, ["check", str(tied)])
    assert res.exit_code == 1
    assert "FAILED: w* ties no two behaviours with different features" in res.stdout
    assert "Traceback" not in res.output


@pytest.mark.parametrize("name", ["delivery", "skateboard", "tiles", "docs-example"])
def test_untied_domains_have_an_interior_and_pass(name: str, tmp_path: Path) -> None:
    if name == "docs-example":
        path = tmp_path / "corridor.toml"
        path.write_text(_doc_example())
        dom = load(path)
    else:
        dom = load(name)
    ds = demo_set(dom)
    rows = np.unique(one_action_rows(ds, first_step_only=True).rows, axis=0)
    assert _interior_margin(rows) > 1e-6
    assert tie_findings(ds) == []
    if name == "docs-example":
        assert len(teaching.teach(dom, "baseline").records) >= 1
