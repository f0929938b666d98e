"""A reward whose optimal policy ties behaviours that differ in their features cannot be taught.

If two behaviours differ in their feature counts by ``r`` and w* values them equally
(``r . w* = 0``), w* lies on the boundary of the region of weights under which the robot's
policy is optimal (its BEC). When such ties come in opposite directions (``r`` and ``-r``
both constrain w*), that region has no interior: every curriculum narrows the learner to a
set of measure zero, so areas, overlaps and test difficulties are all zero, and the
baseline's SCOT finds no demonstration for its constraints. This module names the problem
before teaching, instead of a curriculum that silently means nothing.
"""

from __future__ import annotations

import numpy as np

from cfteach.bec.constraints import one_action_rows
from cfteach.bec.demos import DemoSet
from cfteach.domains.check import DomainCheckError, Finding
from cfteach.geometry import Region

__all__ = ["require_untied", "tie_findings"]

_TOL = 1e-9


def _describe(row: np.ndarray, names: list[str]) -> str:
    """``2*carry + 1*step = 0`` for the row (2, 0, 1)."""
    if row[np.flatnonzero(row)[0]] < 0:
        row = -row
    terms = [f"{int(v)}*{n}" for v, n in zip(row.tolist(), names, strict=True) if v]
    return " + ".join(terms).replace("+ -", "- ") + " = 0"


def tie_findings(ds: DemoSet) -> list[Finding]:
    """An error when the policy-level BEC (every demonstration's first-step one-action rows)
    has no interior, naming one tie of w*; otherwise nothing."""
    rows = np.unique(one_action_rows(ds, first_step_only=True).rows, axis=0)
    if len(rows) == 0 or not Region(rows).is_empty():
        return []
    dom = ds.domain
    w = np.asarray(dom.weights, dtype=float)
    tied = rows[(np.abs(rows @ w) <= _TOL) & rows.any(axis=1)]
    example = (f" (e.g. {_describe(tied[0], list(dom.feature_names))} under w*)"
               if len(tied) else "")
    return [Finding("error", "tied_reward", (
        f"{dom.name}: w* values two behaviours with different features equally{example}, "
        "so the weights under which the robot's policy is optimal form a set with no "
        "interior and no curriculum can teach them: change a weight so that nothing ties"))]


def require_untied(ds: DemoSet) -> None:
    """Raise `DomainCheckError` (a `ValueError`) when `tie_findings` finds the problem."""
    found = tie_findings(ds)
    if found:
        raise DomainCheckError(found)
