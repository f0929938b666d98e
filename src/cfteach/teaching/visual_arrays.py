"""The dissimilarity measures of `visual` for many demonstrations at once.

Per demo we keep the views the measures compare (hash digits, attribute tuple, state tuple,
env code) as padded integer arrays, built once per DemoSet, so SCOT can score millions of
combinations and the baselines thousands of candidates without Python loops.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cfteach.bec.demos import DemoSet
from cfteach.teaching._views import _data_view, _hash_view


@dataclass(frozen=True)
class VisualArrays:
    hash: np.ndarray  # [D, L] digits (0-padded)
    hash_len: np.ndarray  # [D]
    data: np.ndarray  # [D, L2]
    state: np.ndarray  # [D, n] state tuple
    env_code: np.ndarray  # [D, bits]
    complexity: np.ndarray  # [D]


def visual_arrays(ds: DemoSet) -> VisualArrays:
    if "visual" in ds.cache:
        return ds.cache["visual"]
    hs, ds_, st = [], [], []
    for d in range(ds.D):
        inst, s = ds.instance(d), ds.start_state(d)
        hs.append(_hash_view(inst, s))
        ds_.append(_data_view(inst, s))
        st.append(s)
    L = max(len(h) for h in hs)
    L2 = max(max(len(x) for x in ds_), L)
    H = np.zeros((ds.D, L), dtype=np.int64)
    hl = np.array([len(h) for h in hs], dtype=np.int64)
    DA = np.zeros((ds.D, L2), dtype=np.int64)
    for i, (h, x) in enumerate(zip(hs, ds_, strict=True)):
        H[i, : len(h)] = h
        DA[i, : len(x)] = x
    insts = ds.batch.instances
    env = np.array([insts[e].env_code for e in range(ds.batch.E)], dtype=np.int64)[ds.env]
    comp = np.array([insts[e].complexity for e in range(ds.batch.E)], dtype=np.int64)[ds.env]
    out = VisualArrays(hash=H, hash_len=hl, data=DA, state=np.array(st, dtype=np.int64),
                       env_code=env, complexity=comp)
    ds.cache["visual"] = out
    return out


def dissimilarity_matrix(ds: DemoSet, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``D[i, j]`` = dissimilarity(demo a[i], demo b[j]) in the DemoSet's profile."""
    a = np.asarray(a, dtype=np.int64)
    b = np.asarray(b, dtype=np.int64)
    return _dissimilarity(ds, a[:, None], b[None, :])


def dissimilarity_pairs(ds: DemoSet, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``D[i]`` = dissimilarity(demo a[i], demo b[i]) (element-wise, same length)."""
    return _dissimilarity(ds, np.asarray(a, dtype=np.int64), np.asarray(b, dtype=np.int64))


def typical_dissimilarities(ds: DemoSet, demos: np.ndarray) -> np.ndarray:
    """`visual.typical_dissimilarity` of each demo: its average D to every other start
    state of its own instance (0 if it has none)."""
    out = np.zeros(len(demos))
    for i, d in enumerate(np.asarray(demos, dtype=np.int64).tolist()):
        same = np.flatnonzero(ds.env == ds.env[d])  # the instance's states, in state order
        others = same[same != d]
        if len(others):
            out[i] = float(np.mean(dissimilarity_matrix(ds, np.array([d]), others)[0]))
    return out


def _dissimilarity(ds: DemoSet, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """D(a, b) for broadcastable demo index arrays `a`, `b` (result has their shape)."""
    va = visual_arrays(ds)
    ham = np.abs(va.env_code[a] - va.env_code[b]).sum(-1)
    if ds.profile == "reference":
        L = va.hash.shape[1]
        n = np.minimum(va.hash_len[a], va.hash_len[b])
        diff = np.abs(va.hash[a] - va.data[b][..., :L])  # [..., L]
        diff = np.where(np.arange(L) < n[..., None], diff, 0)
        return (2 * diff.sum(-1) + ham).astype(float)
    return (np.abs(va.state[a] - va.state[b]).sum(-1) + ham).astype(float)
