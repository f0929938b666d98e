"""Checks a domain must pass before any planning: a wrong domain gives a named error, never a
silent wrong answer (an empty curriculum, demonstrations that bump into walls, a belief that
no longer contains w*) nor a crash minutes later.

* `static_findings(dom)`: instant checks on the file's numbers (features, w* and beliefs).
* `CHECKS`: what each check verifies, as `cfteach check` prints it.
* `Finding`, `errors_of`, `DomainCheckError`: the results, shared with the planning checks.

The checks that need planning (`check_domain`, `require_sound`) live one layer up, in
`cfteach.mdp.soundness`: they compile the domain and run value iteration on w*, and the
domain layer stands below the MDP layer.

docs/domains.md ("Checks before planning") lists the rules.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cfteach.domains.model import Domain

__all__ = ["CHECKS", "MIN_FEATURES", "DomainCheckError", "Finding", "errors_of",
           "static_findings"]

#: Beliefs are regions of the unit sphere S^(F-1); the geometry needs F >= 3.
MIN_FEATURES = 3
_TOL = 1e-12

#: Every check, (code, what it verifies, whether it needs planning), in the order they run.
CHECKS: tuple[tuple[str, str, bool], ...] = (
    ("features", f"at least {MIN_FEATURES} features", False),
    ("w_star", "w* inside the file's prior and posterior", False),
    ("reward_loop", "no reward loop that w* pays for", True),
    ("unreachable_goal", "every instance's goal (or an exit) reachable from its start", True),
    ("dead_end", "no state from which the episode can no longer end", True),
    ("goal_not_optimal", "some optimal path under w* reaches the goal (else a warning)", True),
    ("tied_reward", "w* ties no two behaviours with different features", True),
)


@dataclass(frozen=True)
class Finding:
    """One result of a check: ``level`` is "error" (the domain cannot be taught) or
    "warning"; ``code`` a short stable name; ``message`` one line naming the problem."""

    level: str
    code: str
    message: str

    def __str__(self) -> str:
        return f"{self.level}: {self.message}"


class DomainCheckError(ValueError):
    """A domain fails a check; the message is the first error (and how many follow)."""

    def __init__(self, findings: list[Finding]) -> None:
        self.findings = findings
        errors = errors_of(findings)
        more = len(errors) - 1
        text = errors[0].message if errors else "domain check failed"
        if more > 0:
            text += f" (and {more} more error{'s' if more > 1 else ''}; `cfteach check` lists all)"
        super().__init__(text)


def errors_of(findings: list[Finding]) -> list[Finding]:
    """The findings of level "error"."""
    return [f for f in findings if f.level == "error"]


def _fmt(w: np.ndarray) -> str:
    return "[" + ", ".join(f"{x:.3f}" for x in w) + "]"


def static_findings(dom: Domain) -> list[Finding]:
    """Checks on the file's numbers alone: at least 3 features, w* inside the prior and the
    posterior (both are constraints c . w >= 0 that w* must satisfy)."""
    out: list[Finding] = []
    if dom.n_features < MIN_FEATURES:
        out.append(Finding("error", "features", (
            f"{dom.name}: {dom.n_features} feature(s) ({', '.join(dom.feature_names)}); "
            f"teaching needs at least {MIN_FEATURES} (beliefs are regions of a sphere "
            "in feature space): add a feature, e.g. a step cost")))
        return out  # the belief rows below have the same (too small) width
    w = np.asarray(dom.weights, dtype=float)
    for key, rows in (("prior", dom.prior), ("posterior", dom.posterior)):
        if rows.size == 0:
            continue
        dots = rows @ w
        bad = np.flatnonzero(dots < -_TOL * (1 + np.abs(rows).sum(axis=1)))
        for i in bad:
            out.append(Finding("error", f"w_star_{key}", (
                f"{dom.name}: w* {_fmt(w)} lies outside [beliefs] {key}: row {int(i)} "
                f"{rows[i].tolist()} . w* = {dots[i]:.3f} < 0 (every row must hold for w*; "
                "fix the row or the weights)")))
    return out
