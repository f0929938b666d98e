"""Visual tie-breaking between equally informative demonstrations. The paper does not describe
it; this follows the authors' code (docs/teaching.md, "The conditions"; the two measures:
docs/profiles.md, difference 7).

Candidates are sorted by (visual complexity of the instance, dissimilarity to the previous
demonstration, a seeded random key) and the first is taken: simple scenes first, then scenes
that look like the last one, so the learner can spot what changed.

Two dissimilarity measures:

* ``reference``: the authors' measure, bug included. D(s, mdp', s') = 2 * sum_{i<L}
  |h(s)[i] - data(s')[i]| + Hamming(env codes), where h(s) are the decimal digits of the
  state's identity hash and data(s') the raw attribute tuple of s' (mis-aligned with h), L the
  shorter hash length. Domains without objects (tiles) compare hash digits with hash digits.
* ``default``: L1 distance between the two state tuples (agent cell, object cell and flags,
  consumables, all aligned by position) + Hamming distance of the env codes. Symmetric.

With no previous demonstration, a candidate's dissimilarity is its average D to every other
state of its own instance ("a typical-looking start state"), in both profiles.

The scalar functions here define the measures (the tests check the batched forms against
them); `tie_break` and SCOT compute them batched with `visual_arrays`.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from cfteach.bec.demos import DemoSet
from cfteach.domains import Instance, State
from cfteach.teaching._views import _data_view, _hash_view
from cfteach.teaching.visual_arrays import (
    dissimilarity_matrix,
    typical_dissimilarities,
    visual_arrays,
)


def reference_dissimilarity(inst: Instance, s: State, inst2: Instance, s2: State) -> float:
    """The reference's D(s, mdp', s') (asymmetric, bug included)."""
    h = _hash_view(inst, s)
    h2 = _hash_view(inst2, s2)
    data = _data_view(inst2, s2)
    n = min(len(h), len(h2))
    total = 2 * sum(abs(h[i] - data[i]) for i in range(n))
    return float(total + sum(abs(a - b) for a, b in zip(inst.env_code, inst2.env_code,
                                                          strict=True)))


def default_dissimilarity(inst: Instance, s: State, inst2: Instance, s2: State) -> float:
    """L1 distance of the aligned state tuples + Hamming distance of the env codes."""
    return float(sum(abs(a - b) for a, b in zip(s, s2, strict=True))
                 + sum(abs(a - b) for a, b in zip(inst.env_code, inst2.env_code, strict=True)))


def dissimilarity(profile: str, inst: Instance, s: State, inst2: Instance, s2: State) -> float:
    fn = reference_dissimilarity if profile == "reference" else default_dissimilarity
    return fn(inst, s, inst2, s2)


def typical_dissimilarity(profile: str, inst: Instance, s: State) -> float:
    """Average D(s, same instance, o) over the instance's other states o."""
    others = [o for o in inst.states() if o != s]
    if not others:
        return 0.0
    return float(np.mean([dissimilarity(profile, inst, s, inst, o) for o in others]))


def tie_break(ds: DemoSet, candidates: Sequence[int], previous: int | None,
              rng: np.random.Generator) -> int:
    """Pick one demo index among `candidates` by (complexity, dissimilarity, random).

    The dissimilarities come from `visual_arrays` (the same measures, batched)."""
    cands = np.array([int(c) for c in candidates], dtype=np.int64)
    if not len(cands):
        raise ValueError("tie_break needs at least one candidate")
    rand = rng.permutation(len(cands))
    if len(cands) == 1:
        return int(cands[0])
    comp = visual_arrays(ds).complexity[cands]
    simplest = np.flatnonzero(comp == comp.min())  # the others cannot win on the first key
    c = cands[simplest]
    if previous is None:  # average D to the other states of the candidate's own instance
        dis = typical_dissimilarities(ds, c)
    else:
        dis = dissimilarity_matrix(ds, c, np.array([previous]))[:, 0]
    return int(c[np.lexsort((rand[simplest], dis))[0]])
