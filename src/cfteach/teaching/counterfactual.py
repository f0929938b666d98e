"""Algorithm 1: counterfactual scaffolding (`counterfactual_only`) and, with feature
scaffolding, the `proposed` condition (the paper's Section IV and Algorithm 1).

Each round samples human models from the learner's current belief, computes every candidate's
counterfactual constraints against them, and shows the demonstration whose constraints shrink
the belief most (or closest to a proportion of the most). Feature scaffolding masks one
feature at a time: demonstrations whose constraints involve the masked feature are held back
until the mask moves on.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from cfteach.bec.constraints import counterfactual_rowset
from cfteach.bec.demos import DemoSet
from cfteach.bec.gain import REFINE_Z, refine_top
from cfteach.bec.rows import RowSet, reduce_sets
from cfteach.geometry import Region
from cfteach.geometry.slice import KnownSlice, SliceRegion
from cfteach.parallel import Executor
from cfteach.teaching import distribute, known
from cfteach.teaching.common import (
    DemoRecord,
    masking_order,
    nonzero_counts,
    one_step_sets,
    tightened,
)
from cfteach.teaching.sampling import sample_models
from cfteach.teaching.visual import tie_break

_DEFAULT_GAIN_EPS = 1e-12  # default profile: a gain must exceed 1 by this to count
_DEFAULT_TIE_TOL = 1e-9  # default profile: gains this close (relative) are tied


def _isclose(a: float, b: float) -> bool:
    """``np.isclose(a, b)`` for scalars (rtol 1e-5, atol 1e-8, relative to b)."""
    if not (math.isfinite(a) and math.isfinite(b)):
        return a == b
    return abs(a - b) <= 1e-8 + 1e-5 * abs(b)


def _candidates_reference_list(gains: np.ndarray, proportion: float) -> list[int]:
    """The reference's list branch: gains > 1 scanned in demo order with isclose grouping."""
    ids = np.flatnonzero(gains > 1)
    if not len(ids):
        return []
    if proportion == 1:
        best, out = -np.inf, []
        for d, g in zip(ids.tolist(), gains[ids].tolist(), strict=True):
            if _isclose(g, best):
                out.append(d)
            elif g > best:
                best, out = g, [d]
        return out
    target = proportion * gains[ids].max()
    closest, out = np.inf, []
    for d, g in zip(ids.tolist(), gains[ids].tolist(), strict=True):
        dist = abs(g - target)
        if _isclose(dist, closest):
            out.append(d)
        elif dist < closest:
            closest, out = dist, [d]
    return out


def _candidates_reference_array(gains: np.ndarray) -> list[int]:
    """The reference's array branch (consistent state counts, tiles): exact maximum."""
    g = np.where(gains == 1, 0.0, gains)
    top = g.max() if len(g) else 0.0
    if top <= 1:
        return []
    return np.flatnonzero(g == top).tolist()


def _candidates_default(gains: np.ndarray, proportion: float) -> list[int]:
    """One rule for every domain: gains > 1, closest to proportion * max (ties within a
    relative 1e-9, so float noise in the areas cannot split a tie)."""
    ids = np.flatnonzero(gains > 1 + _DEFAULT_GAIN_EPS)
    if not len(ids):
        return []
    target = proportion * gains[ids].max()
    dist = np.abs(gains[ids] - target)
    return ids[dist <= dist.min() + _DEFAULT_TIE_TOL * max(1.0, target)].tolist()


def candidate_set(profile: str, gains: np.ndarray, proportion: float,
                  consistent_states: bool) -> list[int]:
    """The demos tied for selection this round ([] = no information left)."""
    if profile == "reference":
        if consistent_states and proportion == 1:
            return _candidates_reference_array(gains)
        return _candidates_reference_list(gains, proportion)
    return _candidates_default(gains, proportion)


def blocked(joint: RowSet, demos: np.ndarray, feature: int,
            executor: Executor | None = None, sl: KnownSlice | None = None) -> np.ndarray:
    """bool per demo in `demos`: some *reduced* joint constraint involves `feature` (reduced
    on the known-weight slice `sl` when given)."""
    out = np.zeros(len(demos), dtype=bool)
    touch = np.zeros(joint.n_demos, dtype=bool)
    touch[joint.demo[joint.rows[:, feature] != 0]] = True
    need = touch[demos]
    if need.any():
        out[need] = distribute.touches(joint, demos[need], feature, executor) if sl is None \
            else known.touches(sl, joint, demos[need], feature)
    return out


#: Demos whose gain lies this close (relative) below the best unmasked one are checked
#: against the mask too: 10x the widest tie rule (the reference's isclose, rtol 1e-5).
_MASK_MARGIN = 1e-4
_MASK_FIRST = 64  # demos checked first (then 4x as many each time, while all are held back)


def masked_gains(joint: RowSet, gains_all: np.ndarray, feature: int, proportion: float,
                 executor: Executor | None = None, *, errors: np.ndarray | None = None,
                 z: float = REFINE_Z, sl: KnownSlice | None = None) -> np.ndarray:
    """`gains_all` with the demos held back by the mask on `feature` set to 0, as far as the
    selection can tell.

    With ``proportion == 1`` only the best gains matter: demos are checked against the mask
    in descending order of gain until the best unmasked one is found, then down to
    `_MASK_MARGIN` below it; the lower ones keep their gains but can be neither the maximum
    nor tied with it under any profile's rule, so the chosen demos and the log are those of
    checking every demo (which is done for other proportions, whose target depends on the
    maximum). Checking means reducing a demo's joint constraints, the costly part.
    With estimated gains (`errors`, more than 3 features) the floor widens to what
    `refine_top` may still re-rank: every demo whose upper bound ``gain + z error`` reaches the
    best unmasked demo's lower bound is checked.
    """
    live = np.flatnonzero(gains_all > 1)
    gains = gains_all.copy()
    on_slice = {} if sl is None else {"sl": sl}
    if proportion != 1:
        gains[live[blocked(joint, live, feature, executor, **on_slice)]] = 0.0
        return gains
    order = live[np.argsort(-gains_all[live], kind="stable")]
    done, step, top = 0, _MASK_FIRST, None
    err = np.zeros(len(gains_all)) if errors is None else np.asarray(errors, dtype=float)
    upper = gains_all + z * err
    while done < len(order):
        if top is None:
            block = order[done:min(len(order), done + step)]
            step *= 4
        else:  # everything left that could still be (or tie with) the best
            floor = top - _MASK_MARGIN * max(1.0, abs(top))
            rest = order[done:]
            block = rest[upper[rest] >= floor]
        held = blocked(joint, block, feature, executor, **on_slice)
        gains[block[held]] = 0.0
        if top is not None:
            break
        done += len(block)
        if not held.all():
            free = block[~held]
            best = free[np.argmax(gains_all[free])]
            top = float(gains_all[best] - z * err[best])
    return gains


def counterfactual_curriculum(
    ds: DemoSet,
    *,
    feature_scaffolding: bool,
    human_models: int,
    max_demos: int,
    proportion: float,
    seed: int,
    unbounded: str | None = None,
    tick: Callable[[str], None] | None = None,
    executor: Executor | None = None,
    sl: KnownSlice | None = None,
) -> tuple[list[DemoRecord], Region | SliceRegion, list[dict]]:
    """Run Algorithm 1. Returns (chosen demos, final belief, per-round log).

    With an `executor` (more than one worker), each round's planning and geometry run on
    its workers; the curriculum is the same bit for bit (`cfteach.teaching.distribute`).
    With a known-weight slice `sl`, beliefs, human models, gains and reductions are the
    slice's (`cfteach.teaching.known`; the counterfactual planning still uses the workers).
    """
    F = ds.F
    names = ds.domain.feature_names
    prior = np.asarray(ds.domain.prior, dtype=np.int64)
    running = Region(prior, dim=F) if sl is None else sl.region(prior)
    if feature_scaffolding:
        distribute.one_step_cache(ds, executor)
        sets = one_step_sets(ds) if sl is None else known.one_step_sets(ds, sl)
        counts = nonzero_counts(list(sets.values()), F)
        masks: list[int | None] = [*[m for m in masking_order(counts)
                                     if sl is None or m not in sl.known], None]
    else:
        masks = [None]
    mask_i = 0
    consistent = bool(np.all(ds.batch.n_states == ds.batch.n_states[0]))
    tie_rng = np.random.default_rng([seed, 2])
    chosen: list[DemoRecord] = []
    log: list[dict] = []
    while len(chosen) < max_demos:
        # one stream per round index: the conditions share round 1's models for one seed
        model_rng = np.random.default_rng([seed, 1, len(chosen)])
        W = sample_models(ds.profile, running.reduced(), human_models, model_rng, F) \
            if sl is None else running.sample(human_models, model_rng)
        if not len(W):
            log.append({"round": len(chosen), "stop": "no human model inside the belief"})
            break
        joint, bounded = counterfactual_rowset(ds, W, unbounded=unbounded, executor=executor)
        if isinstance(running, Region):  # sl is None
            gains_all, errors_all = distribute.gains(running, joint, executor)
        else:
            gains_all, errors_all = known.gains(running, joint)  # errors 0 if F=3 or on a slice
        cands: list[int] = []
        while True:
            mask = masks[mask_i]
            gains = gains_all
            if mask is not None and sl is None:
                gains = masked_gains(joint, gains_all, mask, proportion, executor,
                                     errors=errors_all)
            elif mask is not None:
                gains = masked_gains(joint, gains_all, mask, proportion, executor,
                                     errors=errors_all, sl=sl)
            if isinstance(running, Region):  # sl is None
                gains = refine_top(running, joint, gains, errors_all)  # > 3 features only
            cands = candidate_set(ds.profile, gains, proportion, consistent)
            if cands or mask is None:
                break
            mask_i += 1
        entry = {"round": len(chosen), "human_models": W.tolist(),
                 "bounded_pairs": int(bounded.sum()),
                 "masked_feature": None if mask is None else names[mask],
                 "max_gain": float(gains.max()) if len(gains) else 0.0,
                 "n_candidates": len(cands)}
        if tick:
            tick(f"round {len(chosen) + 1}")
        if not cands:
            entry["stop"] = "no demonstration adds knowledge"
            log.append(entry)
            break
        prev = chosen[-1].demo if chosen else None
        d = tie_break(ds, cands, prev, tie_rng)
        C = reduce_sets(joint, np.array([d]))[d] if sl is None \
            else known.reduce_rowset(sl, joint, np.array([d]))[d]
        running = tightened(running, C)
        chosen.append(DemoRecord(demo=d, constraints=C, knowledge_gain=float(gains[d]),
                                 belief_area_after=running.area(),
                                 masked_feature=None if mask is None else names[mask]))
        entry["chosen"] = d
        log.append(entry)
    return chosen, running, log
