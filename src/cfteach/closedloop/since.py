"""How much an old answer still says about what the learner believes now (confusion "since").

A learner's weights change as they are taught, while a particle holds one weight vector: the
weights *now*. An answer given before `k` more demonstrations (lessons or feedback) was
planned under the weights held *then*. With uptake `u` (the chance that a demonstration
changed what they believe, inferred per particle) those equal the weights now with chance
``(1 - u) ** k``; otherwise the attempt is scored as one planned under weights drawn from
the belief of its time (the confusion term's second share, `NoisyBelief`). So the latest
answers are full evidence about the weights now, older ones fade as teaching goes on, and a
prediction (an answer with no demonstration before it) uses the weights now alone.

Why: with a confusion share `c` fixed for the whole session (model ``"grid"``), every
answer, the last ones included, is partly explained away by the belief's width, so passed
tests hardly narrow the belief: learners who had learned everything were predicted up to
0.16 below their score (docs/closed-loop.md, "Answers weighed by what was taught since").
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

#: How the confused share of an attempt is set; the first is the default.
CONFUSION_MODELS = ("since", "grid")


def demos_after(history: Sequence[dict[str, Any]]) -> tuple[np.ndarray, np.ndarray]:
    """The number of demonstrations after each ``"steps"`` entry and after each
    ``"outcome"`` entry of `history`, each in history order."""
    k, steps, outcomes = 0, [], []
    for e in reversed(history):
        if e["kind"] == "demonstration":
            k += 1
        elif e["kind"] == "steps":
            steps.append(k)
        elif e["kind"] == "outcome":
            outcomes.append(k)
    return np.array(steps[::-1], dtype=float), np.array(outcomes[::-1], dtype=float)


def log_shares(model: str, uptake: np.ndarray, confused: np.ndarray, k: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
    """``[P, E]`` logs of ``1 - c`` and of ``c``, the share of an answer followed by `k`
    ``[E]`` demonstrations that was planned under weights of its time rather than the
    particle's own. Model ``"grid"``: each particle's `confused` ``[P]``, whatever `k`;
    model ``"since"``: ``1 - c = (1 - u) ** k`` (`uptake` ``[P]``), computed as
    ``k * log(1 - u)`` so that a long session never rounds the kept share to 0 (``log c``
    is ``-inf`` for ``k = 0``)."""
    k = np.asarray(k, dtype=float)
    with np.errstate(divide="ignore"):
        if model == "since":
            log_keep = k[None, :] * np.log1p(-np.asarray(uptake))[:, None]
            return log_keep, np.log(-np.expm1(log_keep))
        c = np.broadcast_to(np.asarray(confused)[:, None], (len(confused), len(k)))
        return np.log1p(-c), np.log(c)


def share(model: str, uptake: np.ndarray, confused: np.ndarray, k: float) -> np.ndarray:
    """``[P, 1]``: `c` of `log_shares` itself, for one answer followed by `k`
    demonstrations (model ``"grid"``: the grid values exactly, so its results are the
    model's before ``"since"``, bit for bit)."""
    if model == "since":
        return -np.expm1(k * np.log1p(-np.asarray(uptake)))[:, None]
    return np.asarray(confused)[:, None]
