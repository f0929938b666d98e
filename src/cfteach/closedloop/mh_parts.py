"""Per-point parts of the noisy belief's posterior, carried through Metropolis-Hastings steps.

`NoisyBelief._move` proposes new points for every particle at once and accepts some: what it
computed for the accepted proposals (their feature values along the answers' steps, their
policy's log-likelihood) replaces the old points' row by row instead of being recomputed.
"""

from __future__ import annotations

from typing import Any

import numpy as np


def select_rows(old: np.ndarray | None, new: np.ndarray | None, take: np.ndarray
                ) -> np.ndarray | None:
    """Rows of `new` where `take`, else of `old` (None stays None: no answers yet)."""
    if old is None or new is None:
        return old
    return np.where(take[:, None], new, old)


def select_parts(old: dict[str, Any], new: dict[str, Any], take: np.ndarray) -> dict[str, Any]:
    """Per-point parts: `new`'s where `take`, else `old`'s (after an MH step on w)."""
    out: dict[str, Any] = {"prior_ok": np.where(take, new["prior_ok"], old["prior_ok"]),
                           "missed": np.where(take, new["missed"], old["missed"])}
    if "steps" in old:
        st = dict(old["steps"])
        if st["x"] is not None:
            st["x"] = np.where(take[:, None, None], new["steps"]["x"], old["steps"]["x"])
        out["steps"] = st
    out["outcomes"] = [(e, np.where(take[:, None, None], xn, xo), np.where(take, okn, oko))
                       for (e, xo, oko), (_, xn, okn) in zip(old["outcomes"], new["outcomes"],
                                                             strict=True)]
    out["after_steps"], out["after_outcomes"] = old["after_steps"], old["after_outcomes"]
    return out
