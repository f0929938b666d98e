"""Checks a domain must pass before any planning: a wrong domain gives a named error, never a
silent wrong answer (an empty curriculum, demonstrations that bump into walls, a belief that
no longer contains w*) nor a crash minutes later.

* `static_findings(dom)`: instant checks on the file's numbers (features, w* and beliefs).
* `planning_findings(dom, batch, values)`: from the exact values of w* on every instance:
  goals that cannot be reached, states that cannot reach the goal, reward loops w* pays for.
* `goal_findings(dom, batch, values)`: per instance, a warning when no optimal path under w*
  reaches the goal (an `exit` action that ends the episode earlier is worth more).
* `check_domain(dom)`: all of them (compiles the domain; cached per domain object).
* `CHECKS`: what each check verifies, as `cfteach check` prints it.
* `require_sound(dom)`: raise `DomainCheckError` on the first error (teaching calls it).

docs/domains.md ("Checks before planning") lists the rules.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass
from typing import Any

import numpy as np

from cfteach.domains.model import Domain

__all__ = ["CHECKS", "MIN_FEATURES", "DomainCheckError", "Finding", "check_domain",
           "errors_of", "goal_findings", "planning_findings", "require_sound",
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


def _cell(state: tuple[int, ...]) -> list[int]:
    """The agent's cell of a state."""
    return [int(state[0]), int(state[1])]


def planning_findings(dom: Domain, batch: Any, values: Any) -> list[Finding]:
    """Per instance, from `values` = exact value iteration of w* (one weight vector) on
    `batch`: a reward loop w* pays for (unbounded value), a goal the start cannot reach,
    states from which the goal cannot be reached."""
    out: list[Finding] = []
    goal = list(dom.spec.goal)
    cargo = dom.spec.cargo  # set whenever the goal is a delivery (parse_spec checks)
    what = "the agent" if dom.spec.goal_kind == "agent_at" or cargo is None else f"the {cargo.name}"
    for e in range(batch.E):
        inst = batch.instances[e]
        tag = f"{dom.name}: instance {inst.index} (env code {list(inst.env_code)})"
        if not bool(values.bounded[e, 0]):
            out.append(Finding("error", "reward_loop", (
                f"{tag}: w* pays for a loop (a cycle of positive total reward), so the best "
                "value is unbounded and demonstrations are undefined: make the loop cost "
                "something (e.g. a step cost) or a rewarding object consumable")))
            continue
        n = int(batch.n_states[e])
        v = values.V[e, 0, :n]
        dead = np.flatnonzero(~np.isfinite(v))
        if dead.size == 0:
            continue
        if dead[0] == 0:  # the initial state is state 0
            out.append(Finding("error", "unreachable_goal", (
                f"{tag}: the goal ({what} at {goal}) cannot be reached from the start "
                f"{_cell(batch.states[e][0])} (walls or blocked cells cut it off)")))
        else:
            eg = _cell(batch.states[e][int(dead[0])])
            out.append(Finding("error", "dead_end", (
                f"{tag}: from {dead.size} of {n} reachable states (e.g. agent at {eg}) the "
                f"goal ({what} at {goal}) can no longer be reached")))
    return out


def goal_findings(dom: Domain, batch: Any, values: Any) -> list[Finding]:
    """Per instance: a warning when no optimal path from the start reaches the goal. Only an
    action with effect `exit` can end an episode elsewhere; without one, a finite value
    already means that the goal is reached, so nothing is searched."""
    from cfteach.mdp import tied_actions

    exits = [k for k, a in enumerate(dom.action_specs) if a.effect == "exit"]
    if not exits:
        return []
    out: list[Finding] = []
    goal = list(dom.spec.goal)
    for e in range(batch.E):
        if not bool(values.bounded[e, 0]) or not np.isfinite(values.V[e, 0, 0]):
            continue  # named by planning_findings as an error already
        inst = batch.instances[e]
        best = tied_actions(values.Q[e, 0])
        seen, stack, reached = {0}, [0], False
        while stack and not reached:
            i = stack.pop()
            state = batch.states[e][i]
            for a in np.flatnonzero(best[i]):
                nxt, _, term = inst.step(state, int(a))
                if term:
                    reached = inst.is_terminal(nxt)
                    if reached:
                        break
                    continue
                j = batch.state_index[e].get(nxt)
                if j is not None and j not in seen:
                    seen.add(j)
                    stack.append(j)
        if not reached:
            names = ", ".join(dom.action_specs[k].name for k in exits)
            out.append(Finding("warning", "goal_not_optimal", (
                f"{dom.name}: instance {inst.index} (env code {list(inst.env_code)}): no "
                f"optimal path under w* reaches the goal at {goal}; ending the episode with "
                f"{names} is worth more, so demonstrations never show the goal (make "
                f"{names} cost something, or check that the goal is not walled off)")))
    return out


_CACHE: weakref.WeakKeyDictionary[Domain, list[Finding]] = weakref.WeakKeyDictionary()


def check_domain(dom: Domain) -> list[Finding]:
    """Every check (static, then planning on w*); the result is cached per domain object."""
    hit = _CACHE.get(dom)
    if hit is not None:
        return list(hit)
    found = static_findings(dom)
    if not errors_of(found):
        from cfteach.mdp import compile_domain, value_iteration

        batch = compile_domain(dom)
        vals = value_iteration(batch, np.asarray(dom.weights, dtype=float)[None])
        found += planning_findings(dom, batch, vals)
        found += goal_findings(dom, batch, vals)
    _CACHE[dom] = found
    return list(found)


def require_sound(dom: Domain) -> None:
    """Raise `DomainCheckError` if `check_domain` finds an error."""
    found = check_domain(dom)
    if errors_of(found):
        raise DomainCheckError(found)
