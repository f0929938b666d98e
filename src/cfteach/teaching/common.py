"""Shared pieces of the curricula: per-domain defaults, the masking order, demo records."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, overload

import numpy as np

from cfteach.bec.constraints import one_action_rows
from cfteach.bec.demos import DemoSet
from cfteach.bec.rows import reduce_sets
from cfteach.geometry import Region
from cfteach.geometry.slice import SliceRegion

CONDITIONS = ("baseline", "feature_only", "counterfactual_only", "proposed")

#: The paper's footnote: counterfactual_only used 70% of the best gain in these domains.
REFERENCE_PROPORTION = {("counterfactual_only", "delivery"): 0.7,
                        ("counterfactual_only", "skateboard"): 0.7}


def check_condition(condition: str) -> str:
    if condition == "closed_loop":
        raise ValueError("closed_loop adapts to the learner's answers, so it has no fixed "
                         "curriculum: run it with `cfteach simulate --conditions closed_loop` "
                         "or cfteach.closedloop.ClosedLoopTeacher (docs/closed-loop.md)")
    if condition not in CONDITIONS:
        raise ValueError(f"unknown condition {condition!r} (allowed: {', '.join(CONDITIONS)})")
    return condition


def default_proportion(profile: str, condition: str, domain_name: str) -> float:
    if profile == "reference":
        return REFERENCE_PROPORTION.get((condition, domain_name), 1.0)
    return 1.0


def check_proportion(p: float) -> float:
    if not (isinstance(p, int | float) and 0 < p <= 1):
        raise ValueError(f"proportion must lie in (0, 1], got {p!r}")
    return float(p)


def one_step_sets(ds: DemoSet) -> dict[int, np.ndarray]:
    """Every demo's one-step minimal constraint set (the paper's Eq. (2), reduced), cached on
    the DemoSet."""
    if "one_step_sets" not in ds.cache:
        ds.cache["one_step_sets"] = reduce_sets(one_action_rows(ds))
    return ds.cache["one_step_sets"]


def nonzero_counts(sets: list[np.ndarray], n_features: int) -> np.ndarray:
    """Nonzero entries per feature over a list of constraint sets: what feature scaffolding
    orders its masks by (the paper's Section IV, "Feature Scaffolding")."""
    out = np.zeros(n_features, dtype=np.int64)
    for s in sets:
        if len(s):
            out += (s != 0).sum(axis=0)
    return out


def masking_order(counts: np.ndarray) -> list[int]:
    """Features in ascending count order, first index on ties (one mask at a time)."""
    return np.argsort(np.asarray(counts), kind="stable").tolist()


@dataclass
class DemoRecord:
    """One chosen demonstration and what the learner's belief looked like after it."""

    demo: int
    constraints: np.ndarray
    knowledge_gain: float
    belief_area_after: float
    masked_feature: str | None
    extra: dict = field(default_factory=dict)


@overload
def tightened(belief: Region, rows: np.ndarray) -> Region: ...


@overload
def tightened(belief: SliceRegion, rows: np.ndarray) -> SliceRegion: ...


def tightened(belief: Region | SliceRegion, rows: np.ndarray) -> Region | SliceRegion:
    """The belief after also learning `rows` (``c . w >= 0``), kept irredundant so that its
    constraints can be reported as they are (on a known-weight slice: irredundant there)."""
    if not isinstance(belief, Region):  # a geometry.slice.SliceRegion
        on_slice = belief.with_rows(rows)
        return type(belief)(belief.slice, on_slice.reduced())
    both = Region(np.vstack([belief.reduced(), rows]), dim=belief.dim)
    return Region(both.reduced(), dim=belief.dim)


def fit_kmeans(x: np.ndarray, n_clusters: int, seed: int) -> Any:  # a fitted KMeans
    """scikit-learn's k-means (4 seeded starts) on one OpenMP thread.

    Why one thread: its centres differ in the last digits with the number of OpenMP threads,
    so a machine with another core count, or a worker process started with one thread,
    would write different tests JSON. The data are a few thousand scalars; one thread is
    as fast.
    """
    import warnings

    from sklearn.cluster import KMeans
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1, user_api="openmp"), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return KMeans(n_clusters=n_clusters, random_state=seed, n_init=4).fit(x)
