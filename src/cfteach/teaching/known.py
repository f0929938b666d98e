"""Teaching with some weights known: every belief lives on the known-weight slice.

A domain file's ``[beliefs] known = ["step"]`` or ``--known step`` fixes those weights at
their true values (``w*`` scaled to L1 norm 1, the 2021 machine-teaching work's setting). Each
demonstration's one-step set, the policy-level constraints SCOT covers, the BEC measures, the
human models, the knowledge gains and the test overlaps are then computed on the slice
(`cfteach.geometry.slice`) instead of the sphere. The measure follows the profile
(`MEASURE`): ``reference`` measures on the edge of the L1 ball, as the 2021 work did;
``default`` on the whole ball. These computations run in the main process (no workers).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from cfteach.bec.constraints import one_action_rows
from cfteach.bec.demos import DemoSet
from cfteach.bec.rows import RowSet
from cfteach.domains import Domain
from cfteach.geometry.slice import KnownSlice, SliceRegion

#: Which part of the L1 ball each profile measures a sliced belief on.
MEASURE = {"reference": "edge", "default": "ball"}


def known_names(dom: Domain, known: Sequence[str] | str | None) -> tuple[str, ...]:
    """The known features' names: `known` (a list, or a comma-separated string; ``""`` or
    ``"none"`` for none) or, when None, the domain file's ``[beliefs] known``."""
    if known is None:
        return tuple(getattr(dom.spec, "known", ()))
    if isinstance(known, str):
        known = [] if known.strip().lower() in ("", "none") else \
            [k.strip() for k in known.split(",")]
    names = tuple(known)
    bad = [k for k in names if k not in dom.feature_names]
    if bad:
        raise ValueError(f"{dom.name}: unknown feature(s) {', '.join(map(repr, bad))} in "
                         f"known (features: {', '.join(dom.feature_names)})")
    if len(set(names)) != len(names):
        raise ValueError(f"known: a feature is listed twice in {list(names)}")
    if names and dom.n_features - len(names) < 2:
        raise ValueError(f"known: {dom.name} has {dom.n_features} features; at least two "
                         "must stay unknown")
    return names


def make_slice(dom: Domain, names: Sequence[str], profile: str) -> KnownSlice | None:
    """The slice of these known features under the profile's measure (None: nothing known)."""
    if not names:
        return None
    idx = [dom.feature_names.index(k) for k in names]
    return KnownSlice.make(dom.weights_raw, idx, MEASURE[profile])


def settings_entry(sl: KnownSlice, dom: Domain) -> dict[str, Any]:
    """``settings.known`` of the JSON: the features, their fixed values and the measure."""
    return {"features": [dom.feature_names[i] for i in sl.known],
            "weights": [float(sl.w_true[i]) for i in sl.known], "measure": sl.measure}


def reduce_on(sl: KnownSlice, rows: np.ndarray) -> np.ndarray:
    """Rows (int) that still cut the slice."""
    if not len(rows):
        return np.zeros((0, sl.dim), dtype=np.int64)
    return np.rint(SliceRegion(sl, rows).reduced()).astype(np.int64)


def reduce_rowset(sl: KnownSlice, rowset: RowSet, demos: np.ndarray | None = None
                  ) -> dict[int, np.ndarray]:
    """Every demo's rows reduced on the slice, one reduction per distinct set."""
    ids = np.arange(rowset.n_demos) if demos is None else np.asarray(demos, dtype=np.int64)
    sets, slot = rowset.distinct(ids)
    red = [reduce_on(sl, s) for s in sets]
    return {d: red[i] for d, i in zip(ids.tolist(), slot.tolist(), strict=True)}


def one_step_sets(ds: DemoSet, sl: KnownSlice) -> dict[int, np.ndarray]:
    """Every demo's one-step minimal set on the slice (cached per slice)."""
    key = ("one_step_sets", sl.known, sl.measure)
    if key not in ds.cache:
        from cfteach.teaching.common import one_step_sets as on_sphere

        sphere = on_sphere(ds)  # what the cone keeps, the slice keeps at most
        groups: dict[bytes, np.ndarray] = {}
        out = {}
        for d, rows in sphere.items():
            k = rows.tobytes()
            if k not in groups:
                groups[k] = reduce_on(sl, rows)
            out[d] = groups[k]
        ds.cache[key] = out
    return ds.cache[key]


def measures(ds: DemoSet, sl: KnownSlice) -> np.ndarray:
    """The slice measure of every demo's one-step set ``[D]`` (cached)."""
    key = ("bec_measures", sl.known, sl.measure)
    if key not in ds.cache:
        sets = one_step_sets(ds, sl)
        memo: dict[bytes, float] = {}
        out = np.empty(ds.D)
        for d in range(ds.D):
            k = sets[d].tobytes()
            if k not in memo:
                memo[k] = SliceRegion(sl, sets[d]).area()
            out[d] = memo[k]
        ds.cache[key] = out
    return ds.cache[key]


def policy_rows(ds: DemoSet, sl: KnownSlice) -> np.ndarray:
    """The policy-level constraints on the slice (the rows SCOT must cover)."""
    from cfteach.bec.rows import primitive

    rows = np.unique(primitive(one_action_rows(ds, first_step_only=True).rows), axis=0)
    return reduce_on(sl, rows)


def overlaps(belief: SliceRegion, rowset: RowSet) -> np.ndarray:
    """measure(belief & rows of d) for every demo, one measure per distinct set."""
    sets, slot = rowset.distinct(np.arange(rowset.n_demos))
    vals = np.array([belief.with_rows(s).area() for s in sets])
    return vals[slot] if len(slot) else np.zeros(0)


def gains(belief: SliceRegion, rowset: RowSet) -> tuple[np.ndarray, np.ndarray]:
    """Knowledge gain measure(B) / measure(B & rows of d) per demo (0 where nothing is
    left), and zero errors (the measures share one sample beyond two free weights, so the
    ratios are common-random-number estimates)."""
    whole = belief.area()
    inter = overlaps(belief, rowset)
    with np.errstate(divide="ignore", invalid="ignore"):
        g = np.where(inter > 0, whole / np.where(inter > 0, inter, 1.0), 0.0)
    return g, np.zeros(len(g))


def touches(sl: KnownSlice, joint: RowSet, demos: np.ndarray, feature: int) -> np.ndarray:
    """bool per demo: its rows reduced on the slice involve `feature`."""
    red = reduce_rowset(sl, joint, demos)
    return np.array([bool(len(red[int(d)]) and np.any(red[int(d)][:, feature] != 0))
                     for d in demos], dtype=bool)
