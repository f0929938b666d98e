"""The prior work's BEC scaffolding (Lee et al. 2021, the paper's Section V; docs/teaching.md,
"The conditions"): conditions `baseline` and `feature_only`.

No counterfactuals and no human models: every demo is summarised by its one-step minimal
constraint set and that set's area ("BEC area", small = informative).

1. SCOT: for each constraint of the policy-level BEC, the demos whose minimal set contains it;
   over the Cartesian product of these sets, the combination with the lowest (mean pairwise
   dissimilarity, mean complexity, enumeration index) is kept (vectorised; delivery has
   5.66 M combinations). These demos are shown last.
2. The other slots: k-means on the pool's BEC areas, every other cluster from the smallest
   area up, a seeded sample per cluster, largest-area cluster first, a visual pick per
   cluster (`baseline`); with feature scaffolding, the same under one masked feature at a
   time with per-mask quotas (`feature_only`).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from cfteach.bec.constraints import one_action_rows
from cfteach.bec.demos import DemoSet
from cfteach.bec.rows import reduce_and_measure
from cfteach.geometry import Region
from cfteach.geometry.slice import KnownSlice
from cfteach.teaching import known
from cfteach.teaching.common import (
    DemoRecord,
    fit_kmeans,
    masking_order,
    nonzero_counts,
    one_step_sets,
    tightened,
)
from cfteach.teaching.visual_arrays import (
    dissimilarity_matrix,
    dissimilarity_pairs,
    visual_arrays,
)

#: Combinations scored at once; with the per-combination dissimilarity intermediates this
#: bounds SCOT's working memory (tens of MB) whatever the group sizes, so peak memory grows
#: with the domain, not with how many demos share a policy-level constraint.
_SCOT_CHUNK = 1 << 18
#: Pairs whose dissimilarity is computed at once (the reference profile's intermediates are
#: `[pairs, hash length]`).
_PAIR_CHUNK = 1 << 16


def bec_areas(ds: DemoSet) -> np.ndarray:
    """Area of every demo's one-step minimal set, ``[D]`` (cached)."""
    if "bec_areas" not in ds.cache:
        ds.cache["bec_areas"] = reduce_and_measure(one_action_rows(ds))[1]
    return ds.cache["bec_areas"]


def scot(ds: DemoSet, sl: KnownSlice | None = None) -> list[int]:
    """The SCOT demos, in ascending demo index (on the known-weight slice `sl`: its
    policy-level constraints, covered by the one-step sets reduced on the slice)."""
    if sl is None:
        sets = one_step_sets(ds)
        pol = Region(np.unique(one_action_rows(ds, first_step_only=True).rows,
                               axis=0)).reduced()
    else:
        sets, pol = known.one_step_sets(ds, sl), known.policy_rows(ds, sl)
    having: dict[tuple[int, ...], list[int]] = {}
    for d in range(ds.D):
        for r in sets[d].tolist():
            having.setdefault(tuple(r), []).append(d)
    groups = []
    for c in pol.astype(np.int64):
        members = having.get(tuple(c.tolist()), [])
        if not members:
            raise RuntimeError(f"no demonstration's minimal set contains the policy-level "
                               f"constraint {c.tolist()}")
        groups.append(np.array(members, dtype=np.int64))
    return _scot3(ds, groups) if len(groups) == 3 else _scot_generic(ds, groups)


def _scot_generic(ds: DemoSet, groups: list[np.ndarray]) -> list[int]:
    """SCOT for any number of constraints: the product in chunks, indices sorted per combo,
    the dissimilarities of each chunk's pairs computed for that chunk only (a matrix over
    the groups' union would take |union|^2 memory: 313 MiB for 16 instances of a 256-instance
    taxi domain whose step constraint sits in most demos' sets)."""
    union = np.unique(np.concatenate(groups))
    pos = {int(d): i for i, d in enumerate(union.tolist())}
    comp = visual_arrays(ds).complexity[union].astype(float)
    local = [np.array([pos[int(d)] for d in g], dtype=np.int64) for g in groups]
    shape = tuple(len(g) for g in local)
    total = int(np.prod(shape))

    def pair_d(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return dissimilarity_pairs(ds, union[a], union[b])

    best_key: tuple[float, float, int] | None = None
    for start in range(0, total, _SCOT_CHUNK):
        flat = np.arange(start, min(total, start + _SCOT_CHUNK))
        idx = np.stack([g[i] for g, i in zip(local, np.unravel_index(flat, shape),
                                             strict=True)], axis=1)
        key = _score(np.sort(idx, axis=1), pair_d, comp)
        vis, cmx = key
        o = np.lexsort((flat, cmx, vis))[0]
        cand = (float(vis[o]), float(cmx[o]), int(flat[o]))
        if best_key is None or cand < best_key:
            best_key = cand
    assert best_key is not None
    combo = np.unravel_index(best_key[2], shape)
    chosen = {int(union[g[i]]) for g, i in zip(local, combo, strict=True)}
    return sorted(chosen)


def _sorted_pair_d(ds: DemoSet, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """D(min, max) for every (a[i], b[j]): the pair in ascending demo index order (computed
    in row blocks, so the intermediates stay within `_PAIR_CHUNK` pairs)."""
    out = np.empty((len(a), len(b)))
    rows = max(1, _PAIR_CHUNK // max(1, len(b)))
    for r in range(0, len(a), rows):
        ar = a[r:r + rows]
        dab = dissimilarity_matrix(ds, ar, b)
        dba = dissimilarity_matrix(ds, b, ar).T
        out[r:r + rows] = np.where(ar[:, None] <= b[None, :], dab, dba)
    return out


def _scot3(ds: DemoSet, groups: list[np.ndarray]) -> list[int]:
    """SCOT for three policy-level constraints, scored by broadcasting over blocks of the
    first group (all dissimilarities and complexities are integers, so the sums are exact;
    the blocks keep the first best in enumeration order, as one broadcast over the whole
    product would, without holding that product: 5.66 M combinations in delivery)."""
    g1, g2, g3 = groups
    comp = visual_arrays(ds).complexity.astype(float)
    t23 = _sorted_pair_d(ds, g2, g3)
    e23 = g2[:, None] == g3[None, :]
    c23 = comp[g2][:, None] + comp[g3][None, :]
    rows = max(1, _SCOT_CHUNK // max(1, len(g2) * len(g3)))
    best: tuple[float, float, int] | None = None
    for r in range(0, len(g1), rows):
        h1 = g1[r:r + rows]
        vis, cmx = _scot3_block(ds, h1, g2, g3, comp, t23, e23, c23)
        low = vis.min()
        cm = np.where(vis == low, cmx, np.inf)
        o = int(np.flatnonzero((vis == low).ravel() & (cm.ravel() == cm.min()))[0])
        cand = (float(low), float(cm.min()), r * len(g2) * len(g3) + o)
        if best is None or cand[:2] < best[:2]:
            best = cand
    assert best is not None
    i, j, k = np.unravel_index(best[2], (len(g1), len(g2), len(g3)))
    return sorted({int(g1[i]), int(g2[j]), int(g3[k])})


def _scot3_block(ds: DemoSet, g1: np.ndarray, g2: np.ndarray, g3: np.ndarray,
                 comp: np.ndarray, t23: np.ndarray, e23: np.ndarray,
                 c23: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(mean pairwise D, mean complexity) of every combination with its first demo in `g1`."""
    t12, t13 = _sorted_pair_d(ds, g1, g2), _sorted_pair_d(ds, g1, g3)
    e12 = g1[:, None] == g2[None, :]
    e13 = g1[:, None] == g3[None, :]
    tot = t12[:, :, None] + t13[:, None, :] + t23[None, :, :]
    csum = comp[g1][:, None, None] + c23[None, :, :]
    vis = tot / 3
    cmx = csum / 3
    dup = e12[:, :, None] | e13[:, None, :] | e23[None, :, :]
    if dup.any():
        i, j, k = np.nonzero(dup)
        a, b, c = g1[i], g2[j], g3[k]
        trip = np.sort(np.stack([a, b, c], axis=1), axis=1)
        single = (trip[:, 0] == trip[:, 2])
        x = trip[:, 0]
        y = np.where(trip[:, 0] == trip[:, 1], trip[:, 2], trip[:, 1])
        dxy = dissimilarity_pairs(ds, x, y)
        vis[i, j, k] = np.where(single, np.inf, dxy)
        cmx[i, j, k] = np.where(single, comp[x], (comp[x] + comp[y]) / 2)
    return vis, cmx


def _score(s: np.ndarray, pair_d, comp: np.ndarray) -> tuple[np.ndarray, np.ndarray]:  # noqa: ANN001
    """(mean pairwise D over the unique sorted indices, mean complexity) per combination;
    `pair_d(a, b)` gives D for index arrays (element-wise).

    A combination that is a single demo has no pairs; it scores +inf on the first key (the
    reference would take the mean of an empty list, which is NaN)."""
    n, k = s.shape
    uniq = np.ones((n, k), dtype=bool)
    uniq[:, 1:] = s[:, 1:] != s[:, :-1]
    n_u = uniq.sum(axis=1)
    tot = np.zeros(n)
    for i in range(k):
        for j in range(i + 1, k):
            tot += np.where(uniq[:, i] & uniq[:, j], pair_d(s[:, i], s[:, j]), 0.0)
    pairs = n_u * (n_u - 1) / 2
    with np.errstate(invalid="ignore", divide="ignore"):
        vis = np.where(pairs > 0, tot / np.where(pairs > 0, pairs, 1), np.inf)
    cmx = (np.where(uniq, comp[s], 0.0)).sum(axis=1) / n_u
    return vis, cmx


def _kmeans_pick(ds: DemoSet, pool: np.ndarray, n_pick: int, pool_size: int,
                 chosen: list[int], rng: np.random.Generator, seed: int,
                 all_areas: np.ndarray | None = None) -> list[int]:
    """k-means on the pool's BEC areas (`all_areas`, default `bec_areas`), clusters 0, 2,
    ..., sample each, largest first, visual pick per cluster. Returns the picks (appends
    nothing to `chosen`)."""
    areas = (bec_areas(ds) if all_areas is None else all_areas)[pool]
    n_clusters = min(2 * n_pick - 1, len(np.unique(areas)))
    if n_clusters < 1 or not len(pool):
        return []
    km = fit_kmeans(areas[:, None], n_clusters, seed)
    order = np.argsort(km.cluster_centers_[:, 0])
    samples = []
    for c in order[::2][:n_pick]:
        members = pool[km.labels_ == c]
        size = min(pool_size // 4, len(members))
        samples.append(rng.choice(members, size=size, replace=False) if size else members[:0])
    picks: list[int] = []
    comp = visual_arrays(ds).complexity
    for sample in samples[::-1]:
        taken = set(chosen) | set(picks)
        cands = np.array([d for d in sample.tolist() if d not in taken], dtype=np.int64)
        if not len(cands):
            continue
        before = picks or chosen
        last = before[-1] if before else None
        dis = (dissimilarity_matrix(ds, cands, np.array([last]))[:, 0] if last is not None
               else np.zeros(len(cands)))
        o = np.lexsort((np.arange(len(cands)), comp[cands], dis))[0]
        picks.append(int(cands[o]))
    return picks


def baseline_curriculum(ds: DemoSet, *, feature_scaffolding: bool, max_demos: int,
                        seed: int, sl: KnownSlice | None = None,
                        ) -> tuple[list[DemoRecord], Region, list[dict]]:
    """`baseline` / `feature_only`. Returns (demos, final belief, log).

    With a known-weight slice `sl`, sets, areas and beliefs are those of the slice
    (`cfteach.teaching.known`) and the known features are never masked."""
    F = ds.F
    names = ds.domain.feature_names
    sets = one_step_sets(ds) if sl is None else known.one_step_sets(ds, sl)
    areas = bec_areas(ds) if sl is None else known.measures(ds, sl)

    def belief(rows: np.ndarray) -> Any:
        return Region(rows, dim=F) if sl is None else sl.region(rows)

    rng = np.random.default_rng([seed, 5])
    scot_demos = scot(ds, sl)
    k = max(0, max_demos - len(scot_demos))
    pool = np.setdiff1d(np.arange(ds.D), scot_demos)
    chosen: list[int] = []
    masks_of: dict[int, str | None] = {}
    log: list[dict] = [{"scot": scot_demos, "slots": k}]
    if not feature_scaffolding:
        chosen = _kmeans_pick(ds, pool, k, len(pool), chosen, rng, seed, areas)
    else:
        counts = nonzero_counts([sets[int(d)] for d in pool], F)
        masks: list[int | None] = [*[m for m in masking_order(counts)
                                     if sl is None or m not in sl.known], None]
        c = math.ceil(k / len(masks)) if k else 0
        quotas, left = [], k
        for _ in masks:
            q = min(c, left)
            quotas.append(q)
            left -= q
        carry = 0
        phase_rows = np.zeros((0, F), dtype=np.int64)
        for mask, q in zip(masks, quotas, strict=True):
            want = q + carry
            if want <= 0:
                continue
            limit = belief(phase_rows).area()
            ok = [d for d in pool.tolist() if d not in chosen and areas[d] < limit
                  and (mask is None or not (len(sets[d]) and np.any(sets[d][:, mask] != 0)))]
            eligible = np.array(ok, dtype=np.int64)
            picks = _kmeans_pick(ds, eligible, min(want, len(eligible)), len(pool), chosen,
                                 rng, seed, areas) if len(eligible) else []
            for d in picks:
                masks_of[d] = None if mask is None else names[mask]
                phase_rows = np.vstack([phase_rows, sets[d]])
            log.append({"masked_feature": None if mask is None else names[mask],
                        "quota": want, "eligible": len(eligible), "picked": picks})
            chosen += picks
            carry = want - len(picks)
    order = chosen + scot_demos
    records = []
    running = belief(np.asarray(ds.domain.prior, dtype=np.int64))
    for d in order:
        before = running.area()
        running = tightened(running, sets[d])
        after = running.area()
        records.append(DemoRecord(demo=d, constraints=sets[d],
                                  knowledge_gain=before / after if after > 0 else 0.0,
                                  belief_area_after=after, masked_feature=masks_of.get(d),
                                  extra={"scot": d in scot_demos}))
    return records, running, log
