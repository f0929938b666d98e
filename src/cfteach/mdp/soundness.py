"""Checks on a domain that need planning: from the exact values of w* on every instance, a
wrong domain gives a named error before any teaching, never a silent wrong answer (an empty
curriculum, demonstrations that bump into walls) nor a crash minutes later.

* `planning_findings(dom, batch, values)`: goals that cannot be reached, states that cannot
  reach the goal, reward loops w* pays for.
* `goal_findings(dom, batch, values)`: per instance, a warning when no optimal path under w*
  reaches the goal (an `exit` action that ends the episode earlier is worth more).
* `check_domain(dom)`: the static checks of `cfteach.domains.check`, then these (compiles the
  domain; cached per domain object).
* `require_sound(dom)`: raise `DomainCheckError` on the first error (teaching calls it).

docs/domains.md ("Checks before planning") lists the rules.
"""

from __future__ import annotations

import weakref
from typing import Any

import numpy as np

from cfteach.domains.check import DomainCheckError, Finding, errors_of, static_findings
from cfteach.domains.model import Domain
from cfteach.mdp.arrays import compile_domain
from cfteach.mdp.vi import tied_actions, value_iteration

__all__ = ["check_domain", "goal_findings", "planning_findings", "require_sound"]


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
