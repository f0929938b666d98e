"""Constraints on the reward weights that demonstrations convey (the paper's Sections III-IV;
docs/teaching.md, "Constraints of single demonstrations").

A constraint ``c`` means ``c . w >= 0``. Two kinds:

* one-action deviations (standard IRL, the paper's Eq. (2)): the demo beats every rollout
  that deviates from it by one action at one step;
* counterfactuals (the paper's Eq. (3)): the demo beats what a human with weights ``w_h``
  would have done from each of its states (their tied-optimal trajectory with the best true reward).

Single demonstrations::

    from cfteach.bec import one_action_constraints, counterfactual_constraints
    rows = one_action_constraints("delivery", env_index=0, start_state=state)

Every candidate demonstration of a domain at once (what teaching uses): `demo_set`,
`one_action_rows`, `counterfactual_rows`, `knowledge_gains`. See docs/teaching.md.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from cfteach.bec.constraints import (
    DEFAULT_UNBOUNDED,
    UNBOUNDED_RULES,
    check_unbounded,
    counterfactual_rows,
    human_mu,
    human_mu_batch,
    human_values,
    loop_rows,
    one_action_rows,
)
from cfteach.bec.demos import PROFILES, VI_METHOD, DemoSet, check_profile, demo_set
from cfteach.bec.gain import cone_generators, intersected_areas, knowledge_gains
from cfteach.bec.known_slice import reduce_on_known_slice
from cfteach.bec.rows import RowSet, group_rows, primitive, reduce_and_measure, reduce_sets
from cfteach.domains import Domain, State, load
from cfteach.geometry import Region

__all__ = [
    "DEFAULT_UNBOUNDED", "PROFILES", "UNBOUNDED_RULES", "DemoSet", "RowSet", "VI_METHOD",
    "check_profile", "check_unbounded", "cone_generators", "loop_rows",
    "counterfactual_constraints", "counterfactual_rows", "demo_set", "group_rows",
    "human_mu", "human_mu_batch", "human_values", "intersected_areas", "knowledge_gains",
    "one_action_constraints", "one_action_rows", "policy_bec", "primitive",
    "reduce_and_measure", "reduce_on_known_slice", "reduce_sets", "resolve_domain",
]


def resolve_domain(domain: Domain | str) -> Domain:
    """A Domain object, or a built-in name / domain-file path loaded with `domains.load`."""
    if isinstance(domain, Domain):
        return domain
    if isinstance(domain, str | bytes) or hasattr(domain, "__fspath__"):
        return load(domain)
    raise TypeError(f"domain must be a Domain, a built-in name or a path, got {domain!r}")


def _demo_index(ds: DemoSet, env_index: int, start_state: State | dict[str, Any]) -> int:
    # env_index is the instance's own index; on a domain restricted to some environments
    # (cfteach.domains.subset) it differs from the instance's position in the batch.
    position = {inst.index: e for e, inst in enumerate(ds.batch.instances)}
    if int(env_index) not in position:
        raise ValueError(f"{ds.domain.name}: env_index must be one of the domain's "
                         f"environments ({_ranges(sorted(position))}), got {env_index}")
    e = position[int(env_index)]
    inst = ds.batch.instances[e]
    state = inst.state_from_json(start_state) if isinstance(start_state, dict) \
        else tuple(start_state)
    try:
        return ds.index(e, state)
    except KeyError:
        raise ValueError(f"{ds.domain.name}: {start_state} is not a reachable non-terminal "
                         f"state of instance {env_index}") from None


def _ranges(xs: list[int]) -> str:
    """`0..63` for a full range, else the first few indices."""
    if xs == list(range(len(xs))):
        return f"0..{len(xs) - 1}"
    return ", ".join(map(str, xs[:8])) + (", ..." if len(xs) > 8 else "")


def one_action_constraints(domain: Domain | str, env_index: int,
                           start_state: State | dict[str, Any], *,
                           profile: str = "default") -> np.ndarray:
    """The demo's one-step minimal constraint set (reduced, primitive int rows ``[k, F]``).

    The demonstration is the greedy rollout under the true weights from `start_state` (a
    State tuple or its JSON form) in instance `env_index`.
    """
    ds = demo_set(resolve_domain(domain), profile)
    d = _demo_index(ds, env_index, start_state)
    return reduce_sets(one_action_rows(ds), np.array([d]))[d]


def counterfactual_constraints(domain: Domain | str, env_index: int,
                               start_state: State | dict[str, Any], human_weights: Any, *,
                               method: str = "exact", profile: str = "default",
                               reference_ties: bool | None = None,
                               unbounded: str | None = None) -> np.ndarray:
    """Joint counterfactual constraints of one demo under human models ``[M, F]`` (reduced).

    Only the demo's instance is planned, so this is cheap enough per learner. Human models
    whose values are unbounded in this instance contribute nothing (``unbounded="skip"``,
    the authors' rule) or the constraints that their positive loops do not pay (``"loops"``,
    `loop_rows`); default: the profile's rule (skip for reference, loops for default;
    docs/profiles.md, difference 6).
    """
    ds = demo_set(resolve_domain(domain), profile)
    d = _demo_index(ds, env_index, start_state)
    W = np.atleast_2d(np.asarray(human_weights, dtype=float))
    if W.shape[1] != ds.F:
        raise ValueError(f"human_weights must have {ds.F} columns (one per feature), "
                         f"got shape {W.shape}")
    e = int(ds.env[d])
    ties = ds.profile == "reference" if reference_ties is None else reference_ties
    mu_h, bounded = human_mu_batch(ds.batch.subset([e]), ds.weights, W, method=method,
                                   reference_ties=ties)
    t = np.arange(ds.length[d])
    s = ds.states[d, t]
    rows = ds.suffix_mu[d, t][:, None, :] - mu_h[0][:, s].transpose(1, 0, 2)  # [T, M, F]
    rows = rows[:, bounded[0]].reshape(-1, ds.F)
    rule = check_unbounded(DEFAULT_UNBOUNDED[ds.profile] if unbounded is None else unbounded)
    if rule == "loops" and not bounded[0].all():
        um = np.flatnonzero(~bounded[0])
        rows = np.vstack([rows, *loop_rows(ds.batch, W, np.full(len(um), e), um)])
    grouped = group_rows(rows, np.zeros(len(rows), dtype=np.int64), 1)
    if not len(grouped.rows):
        return np.zeros((0, ds.F), dtype=np.int64)
    return Region(grouped.rows).reduced().astype(np.int64)


def policy_bec(domain: Domain | str, *, profile: str = "default",
               known: Sequence[str] = ()) -> np.ndarray:
    """The domain's policy-level BEC: reduce(union of every demo's first-step rows).

    `known` names features whose weight is treated as known (the step cost, in the 2021
    machine-teaching work's published BECs): redundancy is then decided on that slice of the
    L1 ball (`known_slice.reduce_on_known_slice`).
    """
    dom = resolve_domain(domain)
    unknown = [k for k in known if k not in dom.feature_names]
    if unknown:
        raise ValueError(f"{dom.name}: unknown feature(s) {', '.join(map(repr, unknown))} in "
                         f"known (features: {', '.join(dom.feature_names)})")
    ds = demo_set(dom, profile)
    rows = np.unique(one_action_rows(ds, first_step_only=True).rows, axis=0)
    if known:
        idx = [dom.feature_names.index(k) for k in known]
        return reduce_on_known_slice(primitive(rows), dom.weights_raw, idx)
    return Region(rows).reduced().astype(np.int64)
